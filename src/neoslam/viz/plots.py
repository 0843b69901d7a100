"""The paper's figures as PNG files: the maps of ground truth, odometry and the corrected map in 3-D (Fig. 3b; the
top view, Fig. 3d, is neoslam.viz.map_plot's), the error of the maps along the route (Fig. 4b), the OVCN's training
loss (Fig. 4a) and the matching scores of a keyframe against the stored ones (Fig. 4c)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from neoslam.evaluation.loops import PrecisionRecall  # noqa: E402
from neoslam.types import Trajectory  # noqa: E402

__all__ = [
    "plot_map_3d",
    "plot_keyframe_labels",
    "plot_error_along_route",
    "plot_ovcn_loss",
    "plot_matching_scores",
    "plot_precision_recall",
]

DPI = 120
STYLES = {
    "ground truth": {"color": "black", "linewidth": 1.6},
    "odometry": {"color": "tab:red", "linewidth": 1.0, "linestyle": "--", "zorder": 3},  # visible on top
    "corrected": {"color": "tab:blue", "linewidth": 1.2},
}
LABEL_COLOURS = {"car": "tab:blue", "truck": "tab:purple", "bicycle": "tab:green", "person": "tab:orange"}


def _save(figure, path: Path) -> None:
    figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def _title(title: str, note: str | None) -> str:
    return title if note is None else f"{title}\n({note})"


def plot_keyframe_labels(path: Path, trajectory: Trajectory, labels: np.ndarray, points: np.ndarray) -> None:
    """The trajectory with the labels of the objects of its keyframes (Fig. 3c)."""
    figure, axes = plt.subplots(figsize=(8, 7))
    axes.plot(*trajectory.positions[:, :2].T, color="0.6", linewidth=1.0, label="trajectory")
    for label in sorted(set(labels.tolist())):
        chosen = labels == label
        axes.plot(*points[chosen, :2].T, ".", markersize=4, color=LABEL_COLOURS.get(label, "grey"), label=label)
    axes.set(xlabel="x [m]", ylabel="y [m]", title="Objects of the keyframes by label")
    axes.set_aspect("equal", adjustable="datalim")
    axes.grid(alpha=0.3)
    axes.legend(loc="best", fontsize=8, markerscale=3)
    _save(figure, path)


def plot_map_3d(path: Path, trajectories: dict[str, Trajectory], note: str | None = None) -> None:
    """The trajectories in 3-D, height exaggerated so that slopes show (Fig. 3b)."""
    figure = plt.figure(figsize=(8, 6))
    axes = figure.add_subplot(projection="3d")
    for name, trajectory in trajectories.items():
        axes.plot(*trajectory.positions.T, label=name, **STYLES.get(name, {}))
    axes.set(xlabel="x [m]", ylabel="y [m]", zlabel="z [m]", title=_title("Object experience map in 3-D", note))
    axes.legend(loc="best", fontsize=8)
    _save(figure, path)


def plot_error_along_route(
    path: Path, truth: Trajectory, estimates: dict[str, Trajectory], note: str | None = None
) -> None:
    """Position error of each (aligned) estimate against the distance travelled (Fig. 4b); `note`: how they were
    aligned, under the title."""
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(truth.positions, axis=0), axis=1))])
    figure, axes = plt.subplots(figsize=(8, 4))
    for name, estimate in estimates.items():
        error = np.linalg.norm(estimate.positions - truth.positions, axis=1)
        axes.plot(travelled, error, label=f"{name} (RMSE {np.sqrt(np.mean(error**2)):.2f} m)", **STYLES.get(name, {}))
    axes.set(
        xlabel="distance travelled [m]",
        ylabel="position error [m]",
        title=_title("Error of the maps along the route", note),
    )
    axes.grid(alpha=0.3)
    axes.legend(loc="best", fontsize=8)
    _save(figure, path)


def plot_ovcn_loss(path: Path, losses: list[float]) -> None:
    """Mean L2 loss (eq. 13) of the object-vector cells network per epoch (Fig. 4a)."""
    figure, axes = plt.subplots(figsize=(6, 4))
    axes.plot(np.arange(1, len(losses) + 1), losses, "o-", color="tab:blue")
    axes.set(xlabel="epoch", ylabel="loss ½(y − O)²", title="Training of the object-vector cells network")
    axes.set_yscale("log")
    axes.grid(alpha=0.3, which="both")
    _save(figure, path)


def plot_matching_scores(
    path: Path,
    keyframe: int,
    ids: np.ndarray,
    scores: np.ndarray,
    verified: np.ndarray,
    threshold: float,
    recognised: list[int],
) -> None:
    """Scores of matching one keyframe against every stored keyframe (ids, increasing; Fig. 4c): the spectral score
    XᵀMX / e_max of every comparison, and the score of the matches that pass verification (zero elsewhere). The
    `recognised` keyframes that closed a loop onto it are marked where they are stored (a keyframe recognised as a
    stored one is not stored again)."""
    figure, axes = plt.subplots(figsize=(8, 4))
    axes.plot(ids, scores, color="tab:gray", linewidth=0.7, label="spectral score")
    axes.plot(ids, verified, color="tab:blue", linewidth=1.2, label="verified score")
    axes.axhline(
        threshold, color="tab:red", linestyle="--", linewidth=0.8, label=f"candidate threshold ({threshold:g})"
    )
    shown = np.isin(ids, recognised)
    if shown.any():
        axes.plot(ids[shown], verified[shown], "o", color="tab:green", label="accepted closure")
    axes.set(xlabel="keyframe", ylabel="matching score", title=f"Matching keyframe {keyframe} against the map")
    axes.set_yscale("symlog", linthresh=1.0)
    axes.grid(alpha=0.3)
    axes.legend(loc="best", fontsize=8)
    _save(figure, path)


def plot_precision_recall(path: Path, curve: PrecisionRecall, note: str | None = None) -> None:
    """Precision against recall of the run's accepted closures as their score threshold rises (each point: accept
    the closures scored at least one closure's score); the lowest threshold, every closure the run accepted, is
    marked. `note`: what recall is counted over, under the title."""
    figure, axes = plt.subplots(figsize=(5.5, 4.5))
    axes.step(curve.recall, curve.precision, where="post", color="tab:blue", linewidth=1.2)
    axes.plot(curve.recall, curve.precision, "o", color="tab:blue", markersize=3, label="a score threshold")
    axes.plot(curve.recall[:1], curve.precision[:1], "*", color="tab:red", markersize=12, label="as the run accepted")
    axes.set(xlabel="recall", ylabel="precision", xlim=(-0.02, 1.02), ylim=(-0.02, 1.05))
    axes.set_title(_title("Loop closures: precision and recall", note))
    axes.grid(alpha=0.3)
    axes.legend(loc="lower left", fontsize=8)
    _save(figure, path)
