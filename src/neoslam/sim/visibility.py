"""What of an object the camera can see: cut off by the image border, hidden behind nearer objects."""

from __future__ import annotations

import numpy as np

from neoslam.boxes import covered_share
from neoslam.config import CameraConfig

__all__ = ["cut_off", "hidden", "column_offset"]

COVER_SAMPLES = 8  # a box's cover is measured on this many x this many points spread over it


def cut_off(extent: np.ndarray, behind: bool, camera: CameraConfig, margin: float) -> bool:
    """An object whose unclipped box (x1, y1, x2, y2) comes within `margin` px of the left, right or top image
    border, or that reaches behind the camera, is only partly in the image (the real stereo step does not place such
    boxes). The bottom border is left out: a box's lower near corner leaves the image well before a car's wheels do."""
    x1, y1, x2, _ = extent
    inside = x1 >= margin and y1 >= margin and x2 <= camera.width - 1 - margin
    return behind or not inside


def hidden(boxes: np.ndarray, depths: np.ndarray, cover: float) -> np.ndarray:
    """(n,) True for each box of (n, 4) whose share covered by the boxes of nearer objects reaches `cover`."""
    return np.array(
        [
            covered_share(box, boxes[depths < depth], COVER_SAMPLES) >= cover
            for box, depth in zip(boxes, depths, strict=True)
        ],
        dtype=bool,
    )


def column_offset(u: float, camera: CameraConfig) -> float:
    """Distance of image column u from the principal point as a share of the half image width (0 axis, 1 edge)."""
    return abs(u - camera.cx) / max(camera.cx, camera.width - camera.cx)
