"""Sessions part 8: later sessions on real images that start part way into the mapped street.

A = the 51 frames of kitti_06_51 through the real front end makes a map (its first pose is the map's frame, the
identity as 06's ground truth); each later session B drives the same street forward from frame 10, 20 or 30, its
images unchanged, or changed photometrically (real_streets.py's third pass; or darker, noisier and more blurred, as
a camera with another exposure), written as a KITTI root whose ground truth starts at the identity (B knows nothing
of where it starts), and is run into A's map with `--localise-only` (so that every B meets the same map). Reported
per session: the B frame it relocalised at, how far it had driven by then, and its position error in A's frame at
that frame and at its last frame (target: within 3 m), from the ground truth, which the run never reads; and the
keyframes it stored (a session relocalises by its keyframes; one recognised as a stored keyframe once relocalised
is not stored again).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.harness import data_root
from benchmarks.real_streets import THIRD_PASS
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.kitti_writer import write_kitti_sequence
from neoslam.datasets.replay import PhotometricChange, ReplayedSequence
from neoslam.evaluation.trajectory_metrics import associate
from neoslam.geometry import invert_pose
from neoslam.io.trajectory_files import read_tum
from neoslam.types import Trajectory

STARTS = (10, 20, 30)  # kitti_06_51 frames a later session starts from
CHANGES = {
    "unchanged": PhotometricChange(),
    "third pass": THIRD_PASS,
    "darker, noisier": PhotometricChange(
        gain=0.6, offset=-12.0, noise_sigma=6.0, blur_sigma=1.0, shift_x=-1.1, shift_y=0.7, seed=8
    ),
}
WITHIN_M = 3.0  # target: a relocalised session's position error in the map's frame

Run = Callable[[Path, Path, Path | None, list[str]], tuple[dict[str, Any], float]]


@dataclass(frozen=True)
class Rebased:
    """A replay whose ground truth starts at the identity (as KITTI's does): its poses relative to its first."""

    replay: ReplayedSequence

    @property
    def camera(self):
        return self.replay.camera

    @property
    def timestamps(self) -> np.ndarray:
        return self.replay.timestamps

    @property
    def ground_truth(self) -> Trajectory:
        truth = self.replay.ground_truth
        return Trajectory(truth.timestamps, invert_pose(truth.poses[0]) @ truth.poses)

    def __len__(self) -> int:
        return len(self.replay)

    def stereo_pair(self, index: int):
        return self.replay.stereo_pair(index)


def _error_at(estimate: Trajectory, truth: Trajectory, frame: int) -> float | None:
    """Horizontal position error (m) of the estimate at a frame of the truth (associated by timestamp)."""
    matched_estimate, matched_truth = associate(estimate, truth, 0.01)
    at = np.flatnonzero(np.isclose(matched_truth.timestamps, truth.timestamps[frame]))
    if not len(at):
        return None
    offset = matched_estimate.positions[at[0], :2] - matched_truth.positions[at[0], :2]
    return float(np.linalg.norm(offset))


def _session(folder: Path, map_path: Path, base, start: int, name: str, change: PhotometricChange, run: Run) -> dict:
    order = tuple(range(start, len(base)))
    replay = ReplayedSequence(base, order, (change,) * len(order), label=f"from {start}")
    slug = f"{name.split(',')[0].replace(' ', '_')}_{start}"
    root = folder / f"kitti_{slug}"
    if not root.exists():
        write_kitti_sequence(root, "06", Rebased(replay))
    metrics, _ = run(root, folder / f"R_{slug}", map_path, ["--sequence", "06", "--localise-only"])
    relocalised = metrics.get("session", {}).get("relocalised_frame")
    truth = replay.ground_truth  # in A's frame
    estimate = read_tum(folder / f"R_{slug}" / "trajectory_tum.txt")
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(truth.positions[:, :2], axis=0), axis=1))])
    found = relocalised is not None
    return {
        "images": name,
        "start (06 frame)": start,
        "frames": len(order),
        "relocalised at (B frame)": relocalised,
        "driven to it m": round(float(travelled[int(relocalised)]), 1) if found else None,
        "error there m": _error_at(estimate, truth, int(relocalised)) if found else None,
        "error at the end m": _error_at(estimate, truth, len(order) - 1) if found else None,
        "closures with the map": metrics.get("session", {}).get("map_closures"),
        "keyframes stored": metrics.get("keyframes"),
    }


def run_part(folder: Path, run: Run) -> dict[str, Any]:
    """The sessions of part 8 into A's map (made here); `run(data, out, map, extra)` runs `neoslam run`."""
    folder.mkdir(exist_ok=True)
    root = data_root() / "kitti_06_51"
    base = read_kitti_sequence(root, "06")
    map_path = folder / "map.neoslam"
    if not map_path.exists():
        run(root, folder / "RA", map_path, ["--sequence", "06"])
    rows = [
        _session(folder, map_path, base, start, name, change, run)
        for name, change in CHANGES.items()
        for start in STARTS
    ]
    relocalised = [r for r in rows if r["relocalised at (B frame)"] is not None]
    within = [r for r in relocalised if r["error there m"] is not None and r["error there m"] <= WITHIN_M]
    values = {
        "sessions": len(rows),
        "relocalised": len(relocalised),
        f"relocalised within {WITHIN_M:g} m": len(within),
    }
    targets = {"relocalised": f"{len(rows)}", f"relocalised within {WITHIN_M:g} m": f"{len(rows)}"}
    return {"values": values, "targets": targets, "sessions": rows}
