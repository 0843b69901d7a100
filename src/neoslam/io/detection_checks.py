"""What makes a detection valid, in one place for every reader of detections: a simulated dataset's
detections.csv and the JSON-lines detections file of `--detections` accept and refuse the same values.

Each check returns None for a valid value or the problem as a phrase (without file or line, which the reader adds).
"""

from __future__ import annotations

import math
from typing import Any

__all__ = [
    "SCORE_RANGE",
    "MAX_PIXEL",
    "MAX_CENTRE_M",
    "is_number",
    "label_problem",
    "score_problem",
    "box_problem",
    "centre_problem",
]

SCORE_RANGE = (0.0, 1.0)
# Box corners may lie outside the image (a detector's box of a cut-off object; clipped on use), but not absurdly far:
# a million pixels is a corrupt value or a unit slip.
MAX_PIXEL = 1e6
# A stereo centre farther than 10 km cannot be measured (KITTI's rig at 0.1 px of disparity: 3.8 km).
MAX_CENTRE_M = 1e4


def is_number(value: Any) -> bool:
    """A finite int or float; JSON's true/false are not numbers, nor are NaN and Infinity (json.loads reads them)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer literal beyond any float (JSON allows 400 digits)
        return False


def label_problem(label: Any) -> str | None:
    if not isinstance(label, str) or not label.strip():
        return f'"label" must be a non-empty string, got {label!r}'
    return None


def score_problem(score: Any) -> str | None:
    if not is_number(score) or not SCORE_RANGE[0] <= score <= SCORE_RANGE[1]:
        return f'"score" must be a number in [0, 1], got {score!r}'
    return None


def box_problem(box: Any, name: str = "box") -> str | None:
    """[x1, y1, x2, y2] in pixels: four finite numbers within MAX_PIXEL, x1 < x2 and y1 < y2."""
    if not isinstance(box, list | tuple) or len(box) != 4 or not all(is_number(v) for v in box):
        return f'"{name}" must be 4 finite numbers [x1, y1, x2, y2], got {box!r}'
    if any(abs(v) > MAX_PIXEL for v in box):
        return f'"{name}" has a corner beyond {MAX_PIXEL:g} px, got {box!r}'
    x1, y1, x2, y2 = box
    if x2 <= x1 or y2 <= y1:
        return f'"{name}" must have x1 < x2 and y1 < y2, got {box!r}'
    return None


def centre_problem(centre: Any) -> str | None:
    """A stereo centre (x, y, z) in the camera frame, metres: finite, in front of the camera, within MAX_CENTRE_M."""
    if len(centre) != 3 or not all(is_number(v) for v in centre):
        return f"object centre must be 3 finite numbers, got {tuple(centre)!r}"
    if centre[2] <= 0:
        return f"object centre has depth {centre[2]} m (must be in front of the camera)"
    if max(abs(v) for v in centre) > MAX_CENTRE_M:
        return f"object centre {tuple(float(v) for v in centre)} is beyond {MAX_CENTRE_M:g} m (stereo cannot see there)"
    return None
