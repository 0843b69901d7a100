"""What a frame given to `NeoSLAM.step` must be beside the one before (its fields are checked when it is made:
neoslam.record_checks): indices increasing, time not going back, objects in front of the camera with patches, and
the motion limits the CLI applies to files (`motion_limits`: speed, rotation rate and the odometry's step between
frames; not the time step, which files have checked and a live camera may pause for as long as it likes).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from neoslam.config import MotionLimitsConfig
from neoslam.record_checks import refuse

__all__ = ["FrameOrder", "velocity_problem"]


def velocity_problem(linear: Any, angular: Any, limits: MotionLimitsConfig) -> tuple[str, str] | None:
    """The velocity beyond `motion_limits` (its field and what is wrong), or None: the speed |v| over max_speed or the
    rotation rate |w| over max_turn_rate, a value that is not finite included."""
    speed, turn = float(np.linalg.norm(linear)), float(np.linalg.norm(angular))
    if not speed <= limits.max_speed:
        return "linear_velocity", f"speed {speed:.6g} m/s exceeds motion_limits.max_speed ({limits.max_speed:g} m/s)"
    if not turn <= limits.max_turn_rate:
        return (
            "angular_velocity",
            f"rotation rate {turn:.6g} rad/s exceeds motion_limits.max_turn_rate ({limits.max_turn_rate:g} rad/s)",
        )
    return None


class FrameOrder:
    """Each frame given to `NeoSLAM.step`: its objects in front of the camera, with patches; against the frame
    before, a larger index, a timestamp not earlier, speeds and an odometry step inside `motion_limits` (as the CLI
    checks files)."""

    def __init__(self, limits: MotionLimitsConfig, frame_type: type) -> None:
        self.limits = limits
        self._frame_type = frame_type
        self._previous: tuple[int, float, np.ndarray] | None = None

    def check(self, frame: Any) -> None:
        if not isinstance(frame, self._frame_type):
            raise TypeError(f"step: expected a Frame, got {type(frame).__name__}")
        for k, observation in enumerate(frame.observations):
            depth = float(observation.center_camera[2])
            if depth <= 0.0:
                refuse(
                    "Frame",
                    f"observations[{k}].center_camera",
                    f"depth (z, optical frame) {depth:g} m is not in front of the camera",
                )
            if observation.patch is None:
                refuse("Frame", f"observations[{k}].patch", "None: keyframes match objects by their patches")
        limits = self.limits
        problem = velocity_problem(frame.linear_velocity, frame.angular_velocity, limits)
        if problem is not None:
            refuse("Frame", *problem)
        if self._previous is not None:
            index, stamp, position = self._previous
            if frame.index <= index:
                refuse("Frame", "index", f"{frame.index} after frame {index}: frame indices must increase")
            step = frame.timestamp - stamp
            if step < 0.0:
                refuse("Frame", "timestamp", f"{frame.timestamp:.9g} s is before the previous frame's {stamp:.9g} s")
            moved = float(np.linalg.norm(np.asarray(frame.odometry_pose)[:3, 3] - position))
            if step > 0.0 and moved / step > limits.max_speed:
                refuse(
                    "Frame",
                    "odometry_pose",
                    f"{moved:.6g} m from the previous frame's in {step:.6g} s ({moved / step:.6g} m/s) exceeds "
                    f"motion_limits.max_speed ({limits.max_speed:g} m/s)",
                )
        self._previous = (int(frame.index), float(frame.timestamp), np.asarray(frame.odometry_pose)[:3, 3].copy())
