"""One route driven several times in a row: the drive of a robot that goes along its streets every day.

A trajectory (a KITTI ground truth, a built-in route) is cut into one pass where it first comes back to a place it
started from: the earliest frame j that a later frame k, at least `min_loop_m` of travel on, passes within
`return_radius` (horizontally) heading the same way (within `max_turn_deg`). The pass is frames j .. k-1, and the
next pass starts again at frame j, so the drive never jumps: the step from the last frame of a pass to the first of
the next is the step k-1 -> k with frame k moved onto frame j. That last gap (up to `return_radius` and a few
degrees of heading) is spread over the last `blend_m` metres of every pass, turned and shifted a little more at
each frame (about frame k's position), so that the poses and their steps stay continuous. Timestamps run on: each
pass lasts t_k - t_j.

Ground truth only: the simulator drives it (`neoslam.sim.simulator.simulate`), SLAM never reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation, Slerp

from neoslam.geometry import yaw_of
from neoslam.types import Trajectory

__all__ = ["MultiPassDrive", "find_pass", "join_passes"]

RETURN_RADIUS_M = 1.2  # a route comes back to its start when it passes this close to it (horizontally)
MIN_LOOP_M = 50.0  # travel before a return counts (the frames just after the start are near it too)
MAX_TURN_DEG = 45.0  # and the heading at the return within this of the start's: not the street driven back
BLEND_M = 20.0  # the gap at the join is spread over this much travel before it


@dataclass(frozen=True)
class MultiPassDrive:
    """The joined drive and where each pass begins."""

    trajectory: Trajectory
    pass_starts: np.ndarray  # (passes,) index of each pass's first frame in `trajectory`
    source_frames: tuple[int, int]  # (j, k): one pass is frames j .. k-1 of the source trajectory

    @property
    def passes(self) -> int:
        return len(self.pass_starts)

    @property
    def frames_per_pass(self) -> int:
        return self.source_frames[1] - self.source_frames[0]

    def pass_of(self) -> np.ndarray:
        """(n,) the pass (0-based) each frame belongs to."""
        return np.repeat(np.arange(self.passes), self.frames_per_pass)


def _arc_length(positions: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


def _heading_difference(a: np.ndarray, b: float) -> np.ndarray:
    return np.abs(np.angle(np.exp(1j * (a - b))))


def find_pass(
    trajectory: Trajectory,
    return_radius: float = RETURN_RADIUS_M,
    min_loop_m: float = MIN_LOOP_M,
    max_turn_deg: float = MAX_TURN_DEG,
) -> tuple[int, int]:
    """(j, k): the earliest frame j the route comes back to, and the frame k of that return nearest to frame j
    (within `return_radius` horizontally, heading within `max_turn_deg`, after at least `min_loop_m` of travel)."""
    if len(trajectory) < 2:
        raise ValueError("a trajectory of fewer than two poses has no pass to repeat")
    xy = trajectory.positions[:, :2]
    arc = _arc_length(trajectory.positions)
    yaw = yaw_of(trajectory.poses)
    tree = cKDTree(xy)
    for j in range(len(xy)):
        if arc[-1] - arc[j] < min_loop_m:
            break
        near = np.asarray(tree.query_ball_point(xy[j], return_radius), dtype=int)
        same_way = _heading_difference(yaw[near], yaw[j]) <= np.radians(max_turn_deg)
        near = np.sort(near[(arc[near] - arc[j] >= min_loop_m) & same_way])
        if len(near):
            breaks = np.flatnonzero(np.diff(near) != 1)
            first_return = near[: breaks[0] + 1] if len(breaks) else near  # the first time it comes back
            k = int(first_return[np.argmin(np.linalg.norm(xy[first_return] - xy[j], axis=1))])
            return j, k
    raise ValueError(
        f"the route never comes back within {return_radius} m of a place it passed, heading the same way "
        f"(within {max_turn_deg}°) after {min_loop_m} m: its passes cannot be joined without a jump"
    )


def _blended(poses: np.ndarray, arc: np.ndarray, j: int, k: int, blend_m: float) -> np.ndarray:
    """Frames j .. k-1, the last `blend_m` metres turned and shifted by a growing share of the transform that
    takes frame k onto frame j (turned about frame k's position), so that the step into the next pass is a step."""
    pass_poses = poses[j:k].copy()
    start, end = poses[k], poses[j]
    turn = Rotation.from_matrix(end[:3, :3] @ start[:3, :3].T)
    shift = end[:3, 3] - start[:3, 3]
    share = np.clip(1.0 - (arc[k] - arc[j:k]) / blend_m, 0.0, 1.0) if blend_m > 0 else np.zeros(k - j)
    moved = share > 0
    if moved.any():
        rotations = Slerp([0.0, 1.0], Rotation.concatenate([Rotation.identity(), turn]))(share[moved]).as_matrix()
        offsets = pass_poses[moved, :3, 3] - start[:3, 3]
        turned = np.einsum("nij,nj->ni", rotations, offsets)
        pass_poses[moved, :3, 3] = start[:3, 3] + turned + share[moved, None] * shift
        pass_poses[moved, :3, :3] = rotations @ pass_poses[moved, :3, :3]
    return pass_poses


def join_passes(
    trajectory: Trajectory,
    passes: int,
    return_radius: float = RETURN_RADIUS_M,
    blend_m: float = BLEND_M,
    min_loop_m: float = MIN_LOOP_M,
    max_turn_deg: float = MAX_TURN_DEG,
) -> MultiPassDrive:
    """`passes` copies of the trajectory's first pass (see `find_pass`), one after another, continuous in pose and
    time; every pass is the same poses (the last `blend_m` metres of each lead into the next, or, for the last,
    into where the next would start)."""
    if passes < 1:
        raise ValueError(f"passes must be at least 1, got {passes}")
    j, k = find_pass(trajectory, return_radius, min_loop_m, max_turn_deg)
    arc = _arc_length(trajectory.positions)
    one = _blended(trajectory.poses, arc, j, k, blend_m)
    stamps = trajectory.timestamps
    duration = float(stamps[k] - stamps[j])
    offsets = stamps[j:k] - stamps[j]
    timestamps = np.concatenate([stamps[j] + p * duration + offsets for p in range(passes)])
    poses = np.concatenate([one] * passes)
    starts = np.arange(passes) * (k - j)
    return MultiPassDrive(Trajectory(timestamps, poses), starts, (j, k))
