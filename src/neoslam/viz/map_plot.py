"""The top view of a run's map (plots/map_2d.png, the paper's Fig. 3d and more): the trajectories, the loop closures
the map accepted (judged true or false against the ground truth where there is one), the experiences of each session
of a map kept over sessions, where this session relocalised in it, and the objects by class with their ids.

`map_figure` builds the figure (tests read its legend, links and labels); `plot_map_2d` writes it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from neoslam.mapping.object_map import MapObject  # noqa: E402
from neoslam.types import Trajectory  # noqa: E402
from neoslam.viz.plots import DPI, LABEL_COLOURS, STYLES  # noqa: E402

__all__ = ["MapLayers", "map_figure", "plot_map_2d", "CLOSURE_LABELS"]

OTHER_COLOURS = ("tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")  # classes beyond the four
CLOSURE_COLOURS = {True: "tab:green", False: "tab:red", None: "tab:cyan"}
CLOSURE_LABELS = {True: "loop closure, true", False: "loop closure, false", None: "loop closure (not judged)"}
SESSION_COLOURS = ("0.55", "tab:olive", "tab:pink", "tab:brown", "tab:cyan", "tab:gray")
MAX_LABELLED_OBJECTS = 80  # more object ids than this would hide the map: the ids are left out (objects.csv has them)


@dataclass(frozen=True)
class MapLayers:
    """What the top view draws besides the trajectories, in the frame they are shown in (ground plane)."""

    objects: list[MapObject] = field(default_factory=list)
    closures: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))  # (k, query/match, x/y)
    closure_truth: np.ndarray | None = None  # (k,) bool, judged by the ground truth; None: not judged
    experiences: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (m, 2) the map's experiences
    sessions: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (m,) each one's session
    relocalised: np.ndarray | None = None  # (2,) where this session relocalised in a stored map
    note: str | None = None  # how the trajectories were placed, under the title


def _class_colours(labels: list[str]) -> dict[str, str]:
    others = iter(OTHER_COLOURS * (1 + len(labels) // len(OTHER_COLOURS)))
    return {label: LABEL_COLOURS.get(label) or next(others) for label in labels}


def _draw_sessions(axes, layers: MapLayers) -> None:
    """The experiences by session, when the map holds more than one (one session: the trajectory says it all)."""
    sessions = sorted(set(layers.sessions.tolist()))
    if len(sessions) < 2:
        return
    for k, session in enumerate(sessions):
        mine = layers.sessions == session
        colour = SESSION_COLOURS[k % len(SESSION_COLOURS)]
        points = layers.experiences[mine]
        axes.plot(*points.T, "o", markersize=2.5, color=colour, alpha=0.7, label=f"session {session} experiences")


def _draw_closures(axes, layers: MapLayers) -> None:
    """Each accepted closure as a link from the query to the match, coloured by its judgement."""
    if not len(layers.closures):
        return
    k = len(layers.closures)
    verdicts = [None] * k if layers.closure_truth is None else [bool(t) for t in layers.closure_truth]
    for verdict in (True, False, None):
        chosen = np.array([v is verdict for v in verdicts], dtype=bool)
        if not chosen.any():
            continue
        colour = CLOSURE_COLOURS[verdict]
        links = layers.closures[chosen]
        axes.add_collection(LineCollection(links, colors=colour, linewidths=1.2, zorder=4))
        axes.plot(*links[:, 0].T, "o", color=colour, markersize=3, zorder=4)  # the query end: a short link shows too
        axes.plot([], [], "o-", color=colour, markersize=3, label=f"{CLOSURE_LABELS[verdict]} ({int(chosen.sum())})")


def _draw_objects(axes, objects: list[MapObject]) -> list[Line2D]:
    """The objects by class (a legend entry each, with its count) and, when few enough to read, their ids."""
    labels = sorted({o.label for o in objects})
    colours = _class_colours(labels)
    handles = []
    for label in labels:
        points = np.array([o.position[:2] for o in objects if o.label == label])
        axes.plot(*points.T, "s", markersize=3.5, color=colours[label], alpha=0.8, zorder=5)
        handles.append(Line2D([], [], marker="s", linestyle="", color=colours[label], label=f"{label} ({len(points)})"))
    if len(objects) <= MAX_LABELLED_OBJECTS:
        for o in objects:
            axes.annotate(str(o.id), o.position[:2], fontsize=6, xytext=(2, 2), textcoords="offset points", zorder=6)
    return handles


def map_figure(trajectories: dict[str, Trajectory], layers: MapLayers | None = None) -> Figure:
    """The top view (see the module); the first trajectory's start is marked."""
    layers = layers or MapLayers()
    figure, axes = plt.subplots(figsize=(9, 7.5))
    _draw_sessions(axes, layers)
    for name, trajectory in trajectories.items():
        axes.plot(*trajectory.positions[:, :2].T, label=name, **STYLES.get(name, {}))
    axes.plot(*next(iter(trajectories.values())).positions[0, :2], "k^", markersize=8, label="start")
    if layers.relocalised is not None:
        axes.plot(*layers.relocalised, "*", color="gold", markeredgecolor="black", markersize=14, zorder=7,
                  label="relocalised in the map")  # fmt: skip
    _draw_closures(axes, layers)
    class_handles = _draw_objects(axes, layers.objects)
    title = "Object experience map, top view"
    axes.set(xlabel="x [m]", ylabel="y [m]", title=title if layers.note is None else f"{title}\n({layers.note})")
    axes.set_aspect("equal", adjustable="datalim")
    axes.autoscale_view()
    axes.grid(alpha=0.3)
    paths = axes.legend(loc="upper left", fontsize=7, framealpha=0.8)
    if class_handles:
        axes.add_artist(paths)
        axes.legend(handles=class_handles, loc="lower right", fontsize=7, title="objects", title_fontsize=7)
    figure.tight_layout()
    return figure


def plot_map_2d(path: Path, trajectories: dict[str, Trajectory], layers: MapLayers | None = None) -> None:
    """Write the top view to `path` (PNG)."""
    figure = map_figure(trajectories, layers)
    figure.savefig(path, dpi=DPI)
    plt.close(figure)
