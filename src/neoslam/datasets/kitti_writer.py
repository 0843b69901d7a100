"""A stereo sequence written in the KITTI odometry layout, so that anything that reads a KITTI root reads it.

Any sequence `neoslam.datasets.kitti.read_kitti_sequence` could have made (a `KittiSequence`, or a
`neoslam.datasets.replay.ReplayedSequence` of one: its frames in another order, seen through photometric changes)
becomes sequence NN of a KITTI root:

```
ROOT/
  sequences/NN/image_0/000000.png ...   left grey images, lossless PNG
  sequences/NN/image_1/000000.png ...   right grey images
  sequences/NN/calib.txt                P0, P1 (the stereo pair, from the sequence's camera), P2, P3 (see below)
  sequences/NN/times.txt                the sequence's timestamps, s
  poses/NN.txt                          its ground truth (camera-0 poses), when it has one
```

calib.txt: P0 = K [I | 0] and P1 = K [I | -fx b e_x] with K and the baseline b of the sequence's camera, the two
lines the reader takes. A grey sequence knows no colour cameras, so P2 and P3 repeat P0 and P1, only so that tools
that expect KITTI's four lines (pykitti) read the file; nothing in NeoSLAM reads them. No Tr line is written.
The poses are written as the sequence gives them (a replay's are its base's poses at the replayed frames).
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from neoslam.config import CameraConfig
from neoslam.errors import OutputError
from neoslam.io.trajectory_files import write_kitti, write_times
from neoslam.types import Trajectory

__all__ = ["StereoSequence", "write_kitti_sequence", "projection_matrices"]


class StereoSequence(Protocol):
    """What the writer reads: a KittiSequence or a ReplayedSequence."""

    camera: CameraConfig
    timestamps: np.ndarray
    ground_truth: Trajectory | None

    def __len__(self) -> int: ...

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]: ...


def projection_matrices(camera: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """The left and right (3, 4) projection matrices of a rectified stereo camera, as KITTI's P0 and P1."""
    intrinsics = np.array([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])
    left = np.hstack([intrinsics, np.zeros((3, 1))])
    right = left.copy()
    right[0, 3] = -camera.fx * camera.baseline
    return left, right


def _calibration_lines(camera: CameraConfig) -> list[str]:
    left, right = projection_matrices(camera)
    rows = {"P0": left, "P1": right, "P2": left, "P3": right}
    return [f"{key}: " + " ".join(f"{v:.12e}" for v in matrix.reshape(-1)) for key, matrix in rows.items()]


def _write_image(path: Path, image: np.ndarray) -> None:
    if image.dtype != np.uint8 or image.ndim != 2:
        raise ValueError(f"{path.name}: expected an 8-bit grey image, got {image.dtype} of shape {image.shape}")
    if not cv2.imwrite(str(path), image):
        raise OutputError(f"{path}: cannot be written")


def write_kitti_sequence(root: Path, name: str, sequence: StereoSequence) -> Path:
    """Write `sequence` as sequence `name` (e.g. "06") of the KITTI odometry root `root` (created if missing; a
    sequence or pose file of that name already there is refused, FileExistsError). Returns the sequence folder."""
    root = Path(root)
    folder = root / "sequences" / name
    poses = root / "poses" / f"{name}.txt"
    for existing in (folder, poses):
        if existing.exists():
            raise FileExistsError(f"{existing}: already exists")
    if len(sequence) == 0:
        raise ValueError("the sequence has no frames")
    left_folder, right_folder = folder / "image_0", folder / "image_1"
    left_folder.mkdir(parents=True)
    right_folder.mkdir()
    for index in range(len(sequence)):
        left, right = sequence.stereo_pair(index)
        _write_image(left_folder / f"{index:06d}.png", left)
        _write_image(right_folder / f"{index:06d}.png", right)
    (folder / "calib.txt").write_text("".join(line + "\n" for line in _calibration_lines(sequence.camera)))
    write_times(folder / "times.txt", sequence.timestamps)
    if sequence.ground_truth is not None:
        poses.parent.mkdir(exist_ok=True)
        write_kitti(poses, sequence.ground_truth)
    return folder
