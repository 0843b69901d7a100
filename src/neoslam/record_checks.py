"""Checks of what the Python API is given, so that a wrong value is refused where it enters, naming the field and the
value, rather than failing nine calls deep or being taken silently.

`check_observation` and `check_frame` run when an ObjectObservation or a Frame is made (neoslam.types); a
`FrameOrder` checks each frame `NeoSLAM.step` is given against the one before: indices increasing, time not going
back, and the motion limits the CLI applies to files (`motion_limits`: speed, rotation rate and the odometry's step
between frames; not the time step, which files have checked and a live camera may pause for as long as it likes).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from neoslam.config import MotionLimitsConfig

__all__ = ["FrameOrder", "check_frame", "check_observation"]

ROTATION_TOLERANCE = 1e-4  # |RᵀR - I| and |det R - 1| a pose's rotation may be off by (float32 round trips)
_SHOWN = 80  # characters of a value shown in a message


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN else f"{text[: _SHOWN - 3]}..."


def _fail(record: str, name: str, problem: str) -> None:
    raise ValueError(f"{record}.{name}: {problem}")


def _array(record: str, name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """The value as a finite float array of the shape, or ValueError naming the field."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        _fail(record, name, f"expected numbers of shape {shape}, got {_shown(value)}")
    if array.shape != shape:
        _fail(record, name, f"expected shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        _fail(record, name, f"not finite: {_shown(array.tolist())}")
    return array


def _number(record: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        _fail(record, name, f"expected a number, got {_shown(value)}")
    if not np.isfinite(value):
        _fail(record, name, f"not finite: {value}")
    return float(value)


def check_observation(observation: Any) -> None:
    """An ObjectObservation's fields: a non-empty label, a score in [0, 1], boxes of 4 finite numbers, a finite
    centre, a 2-D uint8 patch (None: no appearance, as the components' own tests give), a depth sigma >= 0 or None.
    That the centre is in front of the camera is the frame's check (`FrameOrder`): a component may be given any
    point."""
    record = "ObjectObservation"
    if not isinstance(observation.label, str) or not observation.label.strip():
        _fail(record, "label", f"expected a non-empty class name, got {_shown(observation.label)}")
    score = _number(record, "score", observation.score)
    if not 0.0 <= score <= 1.0:
        _fail(record, "score", f"{score:g} is not in [0, 1]")
    _array(record, "box_left", observation.box_left, (4,))
    _array(record, "box_right", observation.box_right, (4,))
    _array(record, "center_camera", observation.center_camera, (3,))
    patch = observation.patch
    if patch is not None and (not isinstance(patch, np.ndarray) or patch.ndim != 2 or patch.dtype != np.uint8):
        got = f"{patch.dtype} array of shape {patch.shape}" if isinstance(patch, np.ndarray) else _shown(patch)
        _fail(record, "patch", f"expected a 2-D uint8 grey patch, got {got}")
    if observation.depth_sigma is not None and _number(record, "depth_sigma", observation.depth_sigma) < 0.0:
        _fail(record, "depth_sigma", f"{observation.depth_sigma:g} m is negative")


def check_frame(frame: Any, observation_type: type) -> None:
    """A Frame's fields: an index >= 0, a finite timestamp, a finite 4x4 rigid odometry pose (orthonormal
    rotation, last row 0 0 0 1), velocities of 3 finite numbers and a tuple of ObjectObservations."""
    record = "Frame"
    if isinstance(frame.index, bool) or not isinstance(frame.index, int | np.integer) or frame.index < 0:
        _fail(record, "index", f"expected an integer >= 0, got {_shown(frame.index)}")
    _number(record, "timestamp", frame.timestamp)
    pose = _array(record, "odometry_pose", frame.odometry_pose, (4, 4))
    rotation = pose[:3, :3]
    off = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if off > ROTATION_TOLERANCE or abs(np.linalg.det(rotation) - 1.0) > ROTATION_TOLERANCE:
        _fail(
            record,
            "odometry_pose",
            f"its rotation is not a rotation (|RᵀR - I| = {off:.3g}, det {np.linalg.det(rotation):.3g})",
        )
    if not np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0)):
        _fail(record, "odometry_pose", f"its last row is {pose[3].tolist()}, not [0, 0, 0, 1]")
    _array(record, "linear_velocity", frame.linear_velocity, (3,))
    _array(record, "angular_velocity", frame.angular_velocity, (3,))
    if not isinstance(frame.observations, tuple):
        _fail(record, "observations", f"expected a tuple of ObjectObservation, got {type(frame.observations).__name__}")
    for k, observation in enumerate(frame.observations):
        if not isinstance(observation, observation_type):
            _fail(record, f"observations[{k}]", f"expected an ObjectObservation, got {type(observation).__name__}")


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
                _fail(
                    "Frame",
                    f"observations[{k}].center_camera",
                    f"depth (z, optical frame) {depth:g} m is not in front of the camera",
                )
            if observation.patch is None:
                _fail("Frame", f"observations[{k}].patch", "None: keyframes match objects by their patches")
        limits = self.limits
        speed = float(np.linalg.norm(frame.linear_velocity))
        if speed > limits.max_speed:
            _fail(
                "Frame",
                "linear_velocity",
                f"speed {speed:.6g} m/s exceeds motion_limits.max_speed ({limits.max_speed:g} m/s)",
            )
        turn = float(np.linalg.norm(frame.angular_velocity))
        if turn > limits.max_turn_rate:
            _fail(
                "Frame",
                "angular_velocity",
                f"rotation rate {turn:.6g} rad/s exceeds motion_limits.max_turn_rate ({limits.max_turn_rate:g} rad/s)",
            )
        if self._previous is not None:
            index, stamp, position = self._previous
            if frame.index <= index:
                _fail("Frame", "index", f"{frame.index} after frame {index}: frame indices must increase")
            step = frame.timestamp - stamp
            if step < 0.0:
                _fail("Frame", "timestamp", f"{frame.timestamp:.9g} s is before the previous frame's {stamp:.9g} s")
            moved = float(np.linalg.norm(np.asarray(frame.odometry_pose)[:3, 3] - position))
            if step > 0.0 and moved / step > limits.max_speed:
                _fail(
                    "Frame",
                    "odometry_pose",
                    f"{moved:.6g} m from the previous frame's in {step:.6g} s ({moved / step:.6g} m/s) exceeds "
                    f"motion_limits.max_speed ({limits.max_speed:g} m/s)",
                )
        self._previous = (int(frame.index), float(frame.timestamp), np.asarray(frame.odometry_pose)[:3, 3].copy())
