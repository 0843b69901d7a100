"""Trajectory accuracy: timestamp association, alignment, ATE and RPE (defined as evo defines them) and the KITTI
odometry devkit's drift. Pure maths on `Trajectory` objects already in one world frame convention.

Conventions shared with evo (so our numbers agree with evo_ape / evo_rpe):
- ATE is evo_ape's `translation_part`: |p_est - p_ref| per pose after the alignment.
- RPE uses consecutive pairs (evo's `all_pairs=False`); E = (ref_i^-1 ref_j)^-1 (est_i^-1 est_j); translation error
  |t(E)| in metres and rotation error = angle of log(R(E)) in degrees. Metre deltas pick the pairs on the *reference*
  path (evo's `pairs_from_reference=True`; evo's own default picks them on the estimate).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.geometry import SimilarityTransform, relative_pose, rotation_angle, umeyama_alignment
from neoslam.types import Trajectory

__all__ = [
    "AlignMode",
    "DeltaUnit",
    "ErrorStats",
    "RPEStats",
    "DriftStats",
    "associate",
    "align",
    "absolute_trajectory_error",
    "relative_pose_error",
    "kitti_drift",
    "DEFAULT_MAX_TIME_DIFF_S",
    "KITTI_SEGMENT_LENGTHS_M",
    "KITTI_STEP_FRAMES",
]

AlignMode = Literal["se3", "sim3", "none"]
DeltaUnit = Literal["frames", "m"]

DEFAULT_MAX_TIME_DIFF_S = 0.01  # evo's --t_max_diff default
KITTI_SEGMENT_LENGTHS_M = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
KITTI_STEP_FRAMES = 10  # the devkit's step_size between first frames of segments
PERCENT = 100.0
DRIFT_PATH_M = 100.0  # rotational drift is reported per 100 m
SEGMENT_CHUNK = 65_536  # drift segments evaluated at once: about 25 MB of pose stacks


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Summary of a non-negative error array (evo's statistics; std is the population std)."""

    errors: np.ndarray
    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float

    @classmethod
    def from_errors(cls, errors: np.ndarray) -> ErrorStats:
        errors = np.asarray(errors, dtype=float)
        if errors.size == 0:
            nan = float("nan")
            return cls(errors, nan, nan, nan, nan, nan, nan)
        return cls(
            errors=errors,
            rmse=float(np.sqrt(np.mean(errors**2))),
            mean=float(np.mean(errors)),
            median=float(np.median(errors)),
            std=float(np.std(errors)),
            min=float(np.min(errors)),
            max=float(np.max(errors)),
        )

    def summary(self) -> dict[str, float]:
        """The scalar statistics (without the per-pose array)."""
        return {name: getattr(self, name) for name in ("rmse", "mean", "median", "std", "min", "max")}


@dataclass(frozen=True, slots=True)
class RPEStats:
    translation: ErrorStats  # metres
    rotation: ErrorStats  # degrees
    pairs: np.ndarray  # (k, 2) index pairs (i, j) into the associated trajectories


@dataclass(frozen=True, slots=True)
class DriftStats:
    """KITTI devkit drift: averages over all segments and per segment length (only lengths with segments)."""

    translation_percent: float
    rotation_deg_per_100m: float
    per_length: dict[float, tuple[float, float]]  # length -> (translation %, rotation deg/100 m)
    first_frames: np.ndarray  # (k,) first frame of each segment
    lengths: np.ndarray  # (k,) segment length, metres
    translation_errors_percent: np.ndarray  # (k,)
    rotation_errors_deg_per_100m: np.ndarray  # (k,)


def _nearest_stamps(query: np.ndarray, stamps: np.ndarray, max_diff: float) -> tuple[np.ndarray, ...]:
    """(query index, index of the nearest sorted stamp, |difference|) for queries matched within max_diff.

    Ties go to the earlier stamp, as in evo's matching_time_indices."""
    upper = np.clip(np.searchsorted(stamps, query, side="right"), 0, len(stamps) - 1)
    lower = np.maximum(upper - 1, 0)
    diff_upper, diff_lower = np.abs(stamps[upper] - query), np.abs(query - stamps[lower])
    nearest = np.where(diff_upper < diff_lower, upper, lower)
    diff = np.minimum(diff_upper, diff_lower)
    ok = diff <= max_diff
    return np.flatnonzero(ok), nearest[ok], diff[ok]


def _keep_unique_targets(
    query_idx: np.ndarray, target_idx: np.ndarray, diffs: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """When several query stamps chose one target stamp keep only the closest (ties: the earlier query)."""
    order = np.lexsort((query_idx, diffs, target_idx))
    first = np.ones(len(order), dtype=bool)
    first[1:] = target_idx[order][1:] != target_idx[order][:-1]
    keep = np.sort(order[first])
    return query_idx[keep], target_idx[keep]


def associate(
    est: Trajectory, ref: Trajectory, max_time_diff: float = DEFAULT_MAX_TIME_DIFF_S, offset: float = 0.0
) -> tuple[Trajectory, Trajectory]:
    """Matched copies (est, ref) of equal length, paired by nearest timestamp as evo's associate_trajectories.

    `offset` is added to the estimate's stamps for matching only (evo's --t_offset); each returned trajectory keeps
    its own stamps. As in evo, every stamp of the trajectory with fewer poses looks for its nearest stamp in the
    other one. Unlike evo, a stamp is never used twice: if two stamps pick the same partner only the closer one
    keeps it (with max_time_diff below half the frame period this never happens and the result equals evo's).
    """
    if len(est) == 0 or len(ref) == 0:
        raise ValueError("cannot associate an empty trajectory")
    est_is_longer = len(est) > len(ref)
    short, long = (ref, est) if est_is_longer else (est, ref)
    long_stamps = long.timestamps + (offset if est_is_longer else -offset)
    short_idx, long_idx, diffs = _nearest_stamps(short.timestamps, long_stamps, max_time_diff)
    short_idx, long_idx = _keep_unique_targets(short_idx, long_idx, diffs)
    if len(short_idx) == 0:
        raise ValueError(
            f"no matching timestamps between the estimate and the reference with max. time difference "
            f"{max_time_diff} s and time offset {offset} s"
        )
    est_idx, ref_idx = (long_idx, short_idx) if est_is_longer else (short_idx, long_idx)
    return _subset(est, est_idx), _subset(ref, ref_idx)


def _subset(trajectory: Trajectory, indices: np.ndarray) -> Trajectory:
    """The poses at `indices`; the trajectory itself when they are all of it (a long one is not copied)."""
    if len(indices) == len(trajectory) and np.array_equal(indices, np.arange(len(trajectory))):
        return trajectory
    return trajectory.subset(indices)


def _check_same_length(est: Trajectory, ref: Trajectory) -> None:
    if len(est) != len(ref):
        raise ValueError(f"trajectories must be associated first: {len(est)} estimated vs {len(ref)} reference poses")


def align(est: Trajectory, ref: Trajectory, mode: AlignMode = "se3") -> tuple[Trajectory, SimilarityTransform]:
    """Move `est` onto `ref` with the Umeyama fit of the positions (rigid for se3, with scale for sim3)."""
    return _aligned(est, ref, mode)


def _aligned(est: Trajectory, ref: Trajectory, mode: AlignMode) -> tuple[Trajectory, SimilarityTransform]:
    transform = _alignment(est, ref, mode)
    if mode == "none":
        return est, transform
    return Trajectory(est.timestamps, transform.apply_to_poses(est.poses)), transform


def _alignment(est: Trajectory, ref: Trajectory, mode: AlignMode) -> SimilarityTransform:
    """The transform that moves `est` onto `ref` (the identity for "none")."""
    _check_same_length(est, ref)
    if mode == "none":
        return SimilarityTransform(np.eye(3), np.zeros(3), 1.0)
    if mode not in ("se3", "sim3"):
        raise ValueError(f"unknown alignment mode {mode!r}; expected 'se3', 'sim3' or 'none'")
    return umeyama_alignment(est.positions, ref.positions, with_scale=mode == "sim3")


def absolute_trajectory_error(est: Trajectory, ref: Trajectory, align: AlignMode = "se3") -> ErrorStats:
    """ATE: per-pose position error in metres after aligning est onto ref (evo_ape, translation part); only the
    positions are moved (a long trajectory's aligned poses would be another copy of it)."""
    transform = _alignment(est, ref, align)
    return ErrorStats.from_errors(np.linalg.norm(transform.apply_to_points(est.positions) - ref.positions, axis=1))


def _pairs_by_frames(n_poses: int, delta: int) -> np.ndarray:
    ids = np.arange(0, n_poses, delta)
    return np.stack([ids[:-1], ids[1:]], axis=1)


def _pairs_by_path(positions: np.ndarray, delta_m: float) -> np.ndarray:
    """Consecutive pairs whose path length (summed step by step, reset at each pair) first reaches delta_m."""
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    ids = [0]
    travelled = 0.0
    for index, step in enumerate(steps, start=1):
        travelled += float(step)
        if travelled >= delta_m:
            ids.append(index)
            travelled = 0.0
    return np.stack([ids[:-1], ids[1:]], axis=1).astype(int)


def _rpe_pairs(ref: Trajectory, delta: float, unit: DeltaUnit) -> np.ndarray:
    if unit == "frames":
        if delta < 1 or float(delta) != int(delta):
            raise ValueError(f"RPE delta in frames must be a positive integer, got {delta}")
        return _pairs_by_frames(len(ref), int(delta))
    if unit == "m":
        if delta <= 0:
            raise ValueError(f"RPE delta in metres must be positive, got {delta}")
        return _pairs_by_path(ref.positions, float(delta))
    raise ValueError(f"unknown RPE delta unit {unit!r}; expected 'frames' or 'm'")


def relative_pose_error(est: Trajectory, ref: Trajectory, delta: float = 1, unit: DeltaUnit = "frames") -> RPEStats:
    """RPE over consecutive pairs `delta` frames or metres (along ref) apart; no alignment is needed."""
    _check_same_length(est, ref)
    pairs = _rpe_pairs(ref, delta, unit)
    if len(pairs) == 0:
        raise ValueError(f"RPE delta = {delta} {unit} gives no pose pairs for {len(ref)} poses")
    i, j = pairs[:, 0], pairs[:, 1]
    ref_rel = relative_pose(ref.poses[i], ref.poses[j])
    est_rel = relative_pose(est.poses[i], est.poses[j])
    error = relative_pose(ref_rel, est_rel)
    translation = np.linalg.norm(error[:, :3, 3], axis=1)
    rotation = np.degrees(Rotation.from_matrix(error[:, :3, :3]).magnitude())
    return RPEStats(ErrorStats.from_errors(translation), ErrorStats.from_errors(rotation), pairs)


def _segments(distances: np.ndarray, step: int, lengths: tuple[float, ...]) -> tuple[np.ndarray, ...]:
    """(first, last, length) of the devkit's segments, in its order (by first frame, then length): a segment
    ends at the first frame whose path distance exceeds the first frame's by the length (lastFrameFromSegmentLength)."""
    starts = np.arange(0, len(distances), step)
    grid = np.meshgrid(starts, np.asarray(lengths, dtype=float), indexing="ij")
    first, length = (axis.ravel() for axis in grid)
    last = np.searchsorted(distances, distances[first] + length, side="right")
    valid = last < len(distances)
    return first[valid], last[valid], length[valid]


def _devkit_relative(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """inv(a) @ b with a general matrix inverse, as the devkit: ground-truth rotations are only orthonormal to
    ~3e-7, and a transpose-inverse would leave ~0.004 deg/100 m of rotational drift between identical inputs."""
    return np.linalg.inv(pose_a) @ pose_b


def kitti_drift(
    est: Trajectory,
    ref: Trajectory,
    lengths: tuple[float, ...] = KITTI_SEGMENT_LENGTHS_M,
    step: int = KITTI_STEP_FRAMES,
) -> DriftStats:
    """KITTI odometry devkit drift: mean translational error (%) and rotational error (deg/100 m) of segments.

    Segments start every `step` frames; for each length the segment ends at the first frame whose distance
    travelled along ref exceeds the length. Trajectories too short for any segment give NaN averages.
    """
    _check_same_length(est, ref)
    if not lengths or step < 1:
        raise ValueError(f"kitti_drift needs segment lengths and a positive step, got {lengths} and {step}")
    steps = np.linalg.norm(np.diff(ref.positions, axis=0), axis=1)
    distances = np.concatenate([[0.0], np.cumsum(steps)])
    first, last, seg_len = _segments(distances, step, lengths)
    t_err, r_err = np.empty(len(first)), np.empty(len(first))
    for chunk in range(0, len(first), SEGMENT_CHUNK):  # a few (k, 4, 4) stacks at a time, however long the drive
        part = slice(chunk, chunk + SEGMENT_CHUNK)
        ref_rel = _devkit_relative(ref.poses[first[part]], ref.poses[last[part]])
        est_rel = _devkit_relative(est.poses[first[part]], est.poses[last[part]])
        error = _devkit_relative(ref_rel, est_rel)
        t_err[part] = np.linalg.norm(error[:, :3, 3], axis=1) / seg_len[part] * PERCENT
        r_err[part] = np.degrees(rotation_angle(error[:, :3, :3])) / seg_len[part] * DRIFT_PATH_M
    return _drift_stats(first, seg_len, t_err, r_err)


def _drift_stats(first: np.ndarray, seg_len: np.ndarray, t_err: np.ndarray, r_err: np.ndarray) -> DriftStats:
    per_length = {
        float(length): (float(t_err[seg_len == length].mean()), float(r_err[seg_len == length].mean()))
        for length in np.unique(seg_len)
    }
    nan = float("nan")
    return DriftStats(
        translation_percent=float(t_err.mean()) if len(t_err) else nan,
        rotation_deg_per_100m=float(r_err.mean()) if len(r_err) else nan,
        per_length=per_length,
        first_frames=first,
        lengths=seg_len,
        translation_errors_percent=t_err,
        rotation_errors_deg_per_100m=r_err,
    )
