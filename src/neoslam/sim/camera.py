"""A rectified stereo camera: projection, disparity, boxes of 3-D objects and back-projection."""

from __future__ import annotations

import numpy as np

from neoslam.config import CameraConfig

__all__ = ["StereoCamera"]

MIN_CORNER_DEPTH = 0.1  # m: box corners behind this are left out of the projected box


class StereoCamera:
    """Pinhole model of the left camera plus the baseline to the right one; points in the optical frame."""

    def __init__(self, config: CameraConfig) -> None:
        self.config = config

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 2) left-image pixels and (n,) disparities of (n, 3) points with z > 0."""
        c = self.config
        z = points[:, 2]
        pixels = np.column_stack([c.fx * points[:, 0] / z + c.cx, c.fy * points[:, 1] / z + c.cy])
        return pixels, c.fx * c.baseline / z

    def back_project(self, pixels: np.ndarray, disparity: np.ndarray) -> np.ndarray:
        """(n, 3) points from left-image pixels and disparities (stereo triangulation)."""
        c = self.config
        z = c.fx * c.baseline / disparity
        return np.column_stack([(pixels[:, 0] - c.cx) * z / c.fx, (pixels[:, 1] - c.cy) * z / c.fy, z])

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        c = self.config
        return (pixels[:, 0] >= 0) & (pixels[:, 0] < c.width) & (pixels[:, 1] >= 0) & (pixels[:, 1] < c.height)

    def extent(self, corners: np.ndarray) -> np.ndarray:
        """Left-image box (x1, y1, x2, y2), not clipped, around the (8, 3) corners in front of the camera."""
        pixels, _ = self.project(corners[corners[:, 2] > MIN_CORNER_DEPTH])
        return np.concatenate([pixels.min(axis=0), pixels.max(axis=0)])

    def box(self, corners: np.ndarray) -> np.ndarray:
        """Left-image box (x1, y1, x2, y2), clipped to the image, around (8, 3) corners in the optical frame."""
        c = self.config
        return np.clip(self.extent(corners), 0, [c.width - 1, c.height - 1, c.width - 1, c.height - 1])
