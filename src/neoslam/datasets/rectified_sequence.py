"""A sequence of raw stereo image files, rectified as each frame is read: what the EuRoC reader and the folder of a
camera's own images give the front end (a `perception.frontend.StereoSequence`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neoslam.config import CameraConfig
from neoslam.datasets.kitti import read_grey_image
from neoslam.errors import InputError
from neoslam.perception.rectification import StereoRectifier
from neoslam.types import Trajectory

__all__ = ["RectifiedSequence", "check_image_size"]


def check_image_size(path: Path, image: np.ndarray, size: tuple[int, int]) -> None:
    """An image of another size than the calibration's is refused, naming the image and both sizes."""
    height, width = image.shape
    if (width, height) != size:
        raise InputError(path, f"image is {width}x{height}, the calibration's is {size[0]}x{size[1]}")


@dataclass(frozen=True)
class RectifiedSequence:
    """Stereo frames from image files, each pair rectified by `rectifier` when read. `timestamps` in seconds;
    `ground_truth` (T_world_robot at each frame) is for evaluation only."""

    name: str
    rectifier: StereoRectifier
    timestamps: np.ndarray
    left_images: tuple[Path, ...]
    right_images: tuple[Path, ...]
    ground_truth: Trajectory | None = None

    @property
    def camera(self) -> CameraConfig:
        """The rectified pair's calibration (what the front end triangulates with)."""
        return self.rectifier.camera

    def __len__(self) -> int:
        return len(self.timestamps)

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """The rectified left and right grey images of a frame."""
        return self.rectifier.rectify(self._read(self.left_images[index]), self._read(self.right_images[index]))

    def left_image(self, index: int) -> np.ndarray:
        """The rectified left grey image of a frame (what the detector sees)."""
        return self.rectifier.rectify_left(self._read(self.left_images[index]))

    def _read(self, path: Path) -> np.ndarray:
        image = read_grey_image(path)
        check_image_size(path, image, self.rectifier.size)
        return image
