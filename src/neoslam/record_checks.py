"""Checks of what the Python API is given, so that a wrong value is refused where it enters, naming the field and the
value, rather than failing nine calls deep or being taken silently.

`check_observation` and `check_frame` run when an ObjectObservation or a Frame is made (neoslam.types); what a frame
given to `NeoSLAM.step` must be beside the one before is neoslam.step_inputs'.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["check_frame", "check_observation", "refuse"]

ROTATION_TOLERANCE = 1e-4  # |RᵀR - I| and |det R - 1| a pose's rotation may be off by (float32 round trips)
_SHOWN = 80  # characters of a value shown in a message


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN else f"{text[: _SHOWN - 3]}..."


def refuse(record: str, name: str, problem: str) -> None:
    """ValueError naming the record's field and what is wrong with it."""
    raise ValueError(f"{record}.{name}: {problem}")


def _array(record: str, name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """The value as a finite float array of the shape, or ValueError naming the field."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        refuse(record, name, f"expected numbers of shape {shape}, got {_shown(value)}")
    if array.shape != shape:
        refuse(record, name, f"expected shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        refuse(record, name, f"not finite: {_shown(array.tolist())}")
    return array


def _number(record: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        refuse(record, name, f"expected a number, got {_shown(value)}")
    if not np.isfinite(value):
        refuse(record, name, f"not finite: {value}")
    return float(value)


def check_observation(observation: Any) -> None:
    """An ObjectObservation's fields: a non-empty label, a score in [0, 1], boxes of 4 finite numbers, a finite
    centre, a 2-D uint8 patch (None: no appearance, as the components' own tests give), a depth sigma >= 0 or None.
    That the centre is in front of the camera is the frame's check (`FrameOrder`): a component may be given any
    point."""
    record = "ObjectObservation"
    if not isinstance(observation.label, str) or not observation.label.strip():
        refuse(record, "label", f"expected a non-empty class name, got {_shown(observation.label)}")
    score = _number(record, "score", observation.score)
    if not 0.0 <= score <= 1.0:
        refuse(record, "score", f"{score:g} is not in [0, 1]")
    _array(record, "box_left", observation.box_left, (4,))
    _array(record, "box_right", observation.box_right, (4,))
    _array(record, "center_camera", observation.center_camera, (3,))
    patch = observation.patch
    if patch is not None and (not isinstance(patch, np.ndarray) or patch.ndim != 2 or patch.dtype != np.uint8):
        got = f"{patch.dtype} array of shape {patch.shape}" if isinstance(patch, np.ndarray) else _shown(patch)
        refuse(record, "patch", f"expected a 2-D uint8 grey patch, got {got}")
    if observation.depth_sigma is not None and _number(record, "depth_sigma", observation.depth_sigma) < 0.0:
        refuse(record, "depth_sigma", f"{observation.depth_sigma:g} m is negative")


def check_frame(frame: Any, observation_type: type) -> None:
    """A Frame's fields: an index >= 0, a finite timestamp, a finite 4x4 rigid odometry pose (orthonormal
    rotation, last row 0 0 0 1), velocities of 3 finite numbers and a tuple of ObjectObservations."""
    record = "Frame"
    if isinstance(frame.index, bool) or not isinstance(frame.index, int | np.integer) or frame.index < 0:
        refuse(record, "index", f"expected an integer >= 0, got {_shown(frame.index)}")
    _number(record, "timestamp", frame.timestamp)
    pose = _array(record, "odometry_pose", frame.odometry_pose, (4, 4))
    rotation = pose[:3, :3]
    off = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if off > ROTATION_TOLERANCE or abs(np.linalg.det(rotation) - 1.0) > ROTATION_TOLERANCE:
        refuse(
            record,
            "odometry_pose",
            f"its rotation is not a rotation (|RᵀR - I| = {off:.3g}, det {np.linalg.det(rotation):.3g})",
        )
    if not np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0)):
        refuse(record, "odometry_pose", f"its last row is {pose[3].tolist()}, not [0, 0, 0, 1]")
    _array(record, "linear_velocity", frame.linear_velocity, (3,))
    _array(record, "angular_velocity", frame.angular_velocity, (3,))
    if not isinstance(frame.observations, tuple):
        refuse(
            record, "observations", f"expected a tuple of ObjectObservation, got {type(frame.observations).__name__}"
        )
    for k, observation in enumerate(frame.observations):
        if not isinstance(observation, observation_type):
            refuse(record, f"observations[{k}]", f"expected an ObjectObservation, got {type(observation).__name__}")
