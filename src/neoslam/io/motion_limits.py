"""Motion an input claims, checked against `motion_limits` before anything integrates it.

Every motion source goes through here: the velocities of a simulated dataset's frames.csv, the poses of an
`--odometry` file (steps between consecutive poses over the time between their frames) and the true trajectory
of `neoslam simulate --trajectory`. A speed of 1e9 m/s or a gap of 1e7 s is a corrupt value or a unit slip, not a
drive: integrating it would put the robot anywhere, so the first offending line is refused, named with its value.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neoslam.config import MotionLimitsConfig
from neoslam.errors import InputError
from neoslam.geometry import body_velocities
from neoslam.io.trajectory_files import data_line_numbers
from neoslam.types import Trajectory

__all__ = ["check_time_steps", "check_velocities", "check_pose_steps", "check_trajectory_file"]


def _lengths(vectors: np.ndarray) -> np.ndarray:
    """Row norms that do not overflow for huge entries (1e300 is reported as 1e300, not inf)."""
    vectors = np.asarray(vectors, dtype=float)
    scale = np.abs(vectors).max(axis=1, initial=0.0)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        unit = vectors / np.where(scale > 0, scale, 1.0)[:, None]
        return scale * np.sqrt((unit**2).sum(axis=1))


def _first_above(values: np.ndarray, limit: float) -> int | None:
    """Index of the first value above the limit or not a number (inf - inf from huge inputs), else None."""
    bad = np.flatnonzero(~(values <= limit))
    return int(bad[0]) if bad.size else None


def check_time_steps(path: Path, timestamps: np.ndarray, limits: MotionLimitsConfig, lines: np.ndarray) -> None:
    """Refuse a gap between consecutive timestamps longer than max_time_step; `lines[i]` is the line of stamp i."""
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.diff(np.asarray(timestamps, dtype=float))
    index = _first_above(steps, limits.max_time_step)
    if index is not None:
        problem = (
            f"time step of {steps[index]:.6g} s from the previous frame exceeds "
            f"motion_limits.max_time_step ({limits.max_time_step:g} s)"
        )
        raise InputError(path, problem, line=int(lines[index + 1]))


def check_velocities(
    path: Path, linear: np.ndarray, angular: np.ndarray, limits: MotionLimitsConfig, lines: np.ndarray
) -> None:
    """Refuse a row whose speed |v| or rotation rate |w| is over the limits; `lines[i]` is the line of row i."""
    speed, turn = _lengths(linear), _lengths(angular)
    index = _first_above(speed, limits.max_speed)
    if index is not None:
        problem = f"speed {speed[index]:.6g} m/s exceeds motion_limits.max_speed ({limits.max_speed:g} m/s)"
        raise InputError(path, problem, line=int(lines[index]))
    index = _first_above(turn, limits.max_turn_rate)
    if index is not None:
        problem = (
            f"rotation rate {turn[index]:.6g} rad/s exceeds motion_limits.max_turn_rate "
            f"({limits.max_turn_rate:g} rad/s)"
        )
        raise InputError(path, problem, line=int(lines[index]))


def check_pose_steps(path: Path, trajectory: Trajectory, limits: MotionLimitsConfig, lines: np.ndarray) -> None:
    """Refuse a step between consecutive poses faster than the limits allow over the time between them (the
    trajectory's timestamps: its own, a times file's or the image sequence's); `lines[i]` is the line of pose i."""
    if len(trajectory) < 2:
        return
    dt = np.diff(trajectory.timestamps)
    with np.errstate(over="ignore", invalid="ignore"):
        steps = _lengths(np.diff(trajectory.positions, axis=0))
        speed = steps / dt  # the body-frame speed: a rotation does not change a step's length
        _, angular = body_velocities(trajectory.poses, trajectory.timestamps)
    index = _first_above(speed, limits.max_speed)
    if index is not None:
        problem = (
            f"{steps[index]:.6g} m from the previous pose in {dt[index]:.6g} s ({speed[index]:.6g} m/s) exceeds "
            f"motion_limits.max_speed ({limits.max_speed:g} m/s)"
        )
        raise InputError(path, problem, line=int(lines[index + 1]))
    check_velocities(path, np.zeros_like(angular[1:]), angular[1:], limits, lines[1:])


def check_trajectory_file(
    path: Path, trajectory: Trajectory, limits: MotionLimitsConfig, times_path: Path | None = None
) -> None:
    """A trajectory read from `path` (its timestamps from `times_path` when given): time steps, then the steps
    between poses, each refused with the line of the file that holds it."""
    lines = data_line_numbers(path)
    if times_path is None:
        check_time_steps(path, trajectory.timestamps, limits, lines)
    else:
        check_time_steps(times_path, trajectory.timestamps, limits, data_line_numbers(times_path))
    check_pose_steps(path, trajectory, limits, lines)
