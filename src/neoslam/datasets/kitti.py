"""The KITTI odometry layout, read: one stereo sequence with its calibration, times and (optional) poses.

```
ROOT/
  sequences/NN/image_0/000000.png ...   left grey camera (rectified)
  sequences/NN/image_1/000000.png ...   right grey camera
  sequences/NN/calib.txt                "P0: 12 numbers", "P1: 12 numbers" (3x4 projection matrices, row-major)
  sequences/NN/times.txt                seconds, one line per frame
  poses/NN.txt                          optional ground truth (camera-0 poses), read for evaluation only
```
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from pydantic import ValidationError

from neoslam.config import CameraConfig, describe_validation_error
from neoslam.errors import InputError
from neoslam.inputs import MAX_IMAGE_BYTES, read_input_bytes
from neoslam.io.image_header import oversized
from neoslam.io.trajectory_files import read_kitti, read_times
from neoslam.text import read_text
from neoslam.types import Trajectory

__all__ = ["KittiSequence", "read_kitti_sequence", "read_calibration", "is_kitti_root", "sequences_in"]

IMAGE_SUFFIX = ".png"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"  # the IEND chunk's type and CRC, which close every complete PNG
PROJECTION_VALUES = 12
# KITTI's principal points sit within a few per cent of the image centre; an image whose centre is farther from the
# calibrated principal point than this share of its size belongs to another camera or was resized.
PRINCIPAL_POINT_TOLERANCE = 0.1


def is_kitti_root(folder: Path) -> bool:
    return (folder / "sequences").is_dir()


def sequences_in(root: Path) -> list[str]:
    """The sequence folders under a KITTI odometry root, sorted."""
    return sorted(p.name for p in (root / "sequences").glob("*") if p.is_dir())


def read_calibration(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The left and right projection matrices P0 and P1 (3x4) of a KITTI calib.txt."""
    matrices: dict[str, np.ndarray] = {}
    seen_at: dict[str, int] = {}
    for number, line in enumerate(read_text(path, missing="calibration file not found").splitlines(), start=1):
        key, _, rest = line.partition(":")
        if key.strip() not in ("P0", "P1"):
            continue
        if key.strip() in seen_at:
            # Which of two differing matrices is the camera's cannot be told: refuse rather than take the last.
            raise InputError(path, f"a second {key.strip()} line (the first is line {seen_at[key.strip()]})", number)
        seen_at[key.strip()] = number
        tokens = rest.split()
        if len(tokens) != PROJECTION_VALUES:
            raise InputError(path, f"{key.strip()} has {len(tokens)} numbers, {PROJECTION_VALUES} expected", number)
        try:
            values = np.array([float(t) for t in tokens])
        except ValueError:
            raise InputError(path, f"{key.strip()} holds a value that is not a number", number) from None
        if not np.isfinite(values).all():
            raise InputError(path, f"{key.strip()} holds a value that is not finite", number)
        matrices[key.strip()] = values.reshape(3, 4)
    for key in ("P0", "P1"):
        if key not in matrices:
            raise InputError(path, f"no {key} line (left P0 and right P1 projection matrices are needed)")
    return matrices["P0"], matrices["P1"]


def _camera_from_projections(path: Path, left: np.ndarray, right: np.ndarray, size: tuple[int, int]) -> CameraConfig:
    fx, fy, cx, cy = left[0, 0], left[1, 1], left[0, 2], left[1, 2]
    if fx <= 0 or fy <= 0:
        raise InputError(path, f"P0 has a non-positive focal length ({fx}, {fy})")
    # A rectified pair: P1 = K [I | -b e_x], so its fourth column holds -fx * baseline (relative to P0's).
    baseline = -(right[0, 3] - left[0, 3]) / fx
    if baseline <= 0:
        raise InputError(path, f"P1 gives a non-positive stereo baseline ({baseline:.4f} m); is P1 the right camera?")
    width, height = size
    try:
        return CameraConfig(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height, baseline=baseline)
    except ValidationError as error:  # e.g. a focal length of 1e300 px
        raise InputError(path, f"P0/P1 give camera.{describe_validation_error(error)}") from None


def _check_principal_point(image: Path, camera: CameraConfig) -> None:
    off_x = abs(camera.cx - camera.width / 2) / camera.width
    off_y = abs(camera.cy - camera.height / 2) / camera.height
    if max(off_x, off_y) > PRINCIPAL_POINT_TOLERANCE:
        raise InputError(
            image,
            f"image size {camera.width}x{camera.height} does not match the calibration (principal point "
            f"{camera.cx:.1f}, {camera.cy:.1f} is far from the image centre)",
        )


@contextmanager
def _native_stderr_silenced() -> Iterator[None]:
    """Nothing written to file descriptor 2 inside gets out: libpng and OpenCV print their own complaints about a
    broken image there ("libpng error: Read Error"), before and apart from NeoSLAM's one line about it."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def read_grey_image(path: Path) -> np.ndarray:
    """An 8-bit grey image; one clear error when it is missing, truncated or not an image."""
    data = read_input_bytes(path, "image not found", MAX_IMAGE_BYTES)
    if data.startswith(PNG_SIGNATURE) and PNG_END not in data:
        raise InputError(path, "truncated PNG (its closing IEND chunk is missing)")
    too_large = oversized(data)
    if too_large is not None:
        raise InputError(path, too_large)
    with _native_stderr_silenced():
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE) if data else None
    if image is None:
        raise InputError(path, "not a readable image")
    return image


def _image_paths(folder: Path, count: int) -> tuple[Path, ...]:
    if not folder.is_dir():
        raise InputError(folder, "image folder not found")
    paths = tuple(folder / f"{i:06d}{IMAGE_SUFFIX}" for i in range(count))
    missing = next((p for p in paths if not p.is_file()), None)
    if missing is not None:
        raise InputError(missing, f"frame missing ({count} frames in times.txt)")
    extra = len(list(folder.glob(f"*{IMAGE_SUFFIX}"))) - count
    if extra > 0:
        raise InputError(folder, f"{extra} more images than the {count} lines of times.txt")
    return paths


@dataclass(frozen=True)
class KittiSequence:
    """A KITTI odometry sequence, read lazily frame by frame. `ground_truth` is for evaluation only."""

    root: Path
    sequence: str
    camera: CameraConfig
    timestamps: np.ndarray
    left_images: tuple[Path, ...]
    right_images: tuple[Path, ...]
    ground_truth: Trajectory | None

    @property
    def name(self) -> str:
        return f"kitti-{self.sequence}"

    def __len__(self) -> int:
        return len(self.timestamps)

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Left and right grey images of a frame, checked against the calibrated size."""
        return self._checked(self.left_images[index]), self._checked(self.right_images[index])

    def left_image(self, index: int) -> np.ndarray:
        """The left grey image of a frame (what the detector sees), checked against the calibrated size."""
        return self._checked(self.left_images[index])

    def _checked(self, path: Path) -> np.ndarray:
        image = read_grey_image(path)
        expected = (self.camera.height, self.camera.width)
        if image.shape != expected:
            problem = f"image is {image.shape[1]}x{image.shape[0]}, the sequence's are {expected[1]}x{expected[0]}"
            raise InputError(path, problem)
        return image


def _ground_truth(path: Path, timestamps: np.ndarray) -> Trajectory:
    """poses/NN.txt at the sequence's times; a pose count that differs from times.txt is the pose file's fault
    (times.txt matched the images already)."""
    poses = read_kitti(path).poses
    if len(poses) != len(timestamps):
        raise InputError(path, f"{len(poses)} poses for the {len(timestamps)} frames of times.txt")
    return Trajectory(timestamps, poses)


def read_kitti_sequence(root: Path, sequence: str) -> KittiSequence:
    """Check the layout of sequence NN under a KITTI odometry root and read its calibration, times and poses."""
    folder = root / "sequences" / sequence
    if not folder.is_dir():
        raise InputError(folder, f"sequence not found (sequences here: {', '.join(sequences_in(root)) or 'none'})")
    left_projection, right_projection = read_calibration(folder / "calib.txt")
    times_path = folder / "times.txt"
    if not times_path.is_file():
        raise InputError(times_path, "times file not found")
    timestamps = read_times(times_path)
    left = _image_paths(folder / "image_0", len(timestamps))
    right = _image_paths(folder / "image_1", len(timestamps))
    first = read_grey_image(left[0])
    size = (first.shape[1], first.shape[0])
    camera = _camera_from_projections(folder / "calib.txt", left_projection, right_projection, size)
    _check_principal_point(left[0], camera)
    poses_path = root / "poses" / f"{sequence}.txt"
    truth = _ground_truth(poses_path, timestamps) if poses_path.is_file() else None
    return KittiSequence(root, sequence, camera, timestamps, left, right, truth)
