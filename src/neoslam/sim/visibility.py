"""What of an object the camera can see: cut off by the image border, hidden behind nearer objects."""

from __future__ import annotations

import numpy as np

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


def _samples(box: np.ndarray) -> np.ndarray:
    """(COVER_SAMPLES², 2) points at the centres of a regular grid over the box."""
    steps = (np.arange(COVER_SAMPLES) + 0.5) / COVER_SAMPLES
    xs = box[0] + steps * (box[2] - box[0])
    ys = box[1] + steps * (box[3] - box[1])
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def hidden(boxes: np.ndarray, depths: np.ndarray, cover: float) -> np.ndarray:
    """(n,) True for each box of (n, 4) whose share covered by the boxes of nearer objects reaches `cover`."""
    result = np.zeros(len(boxes), dtype=bool)
    for i, box in enumerate(boxes):
        nearer = boxes[depths < depths[i]]
        if len(nearer) == 0:
            continue
        points = _samples(box)[:, None, :]
        inside = (points[..., 0] >= nearer[:, 0]) & (points[..., 0] <= nearer[:, 2])
        inside &= (points[..., 1] >= nearer[:, 1]) & (points[..., 1] <= nearer[:, 3])
        result[i] = inside.any(axis=1).mean() >= cover
    return result


def column_offset(u: float, camera: CameraConfig) -> float:
    """Distance of image column u from the principal point as a share of the half image width (0 axis, 1 edge)."""
    return abs(u - camera.cx) / max(camera.cx, camera.width - camera.cx)
