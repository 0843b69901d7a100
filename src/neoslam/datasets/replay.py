"""A stereo sequence replayed: its frames in another order (forward, back, forward again), each optionally seen
through a photometric change (gain, offset, noise, blur, a small shift of both images).

This builds a revisit from real images where no second drive of a street is available: the camera comes back to
places it has seen, and the changes make the images of the return differ from the first pass as a later drive's
would, a little. It is the same street's images, not an independent second drive: the parked cars stand exactly
where they stood, and the stereo geometry is the first pass's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from neoslam.config import CameraConfig
from neoslam.datasets.kitti import KittiSequence
from neoslam.types import Trajectory

__all__ = ["PhotometricChange", "ReplayedSequence", "forward_back_forward"]

GREY_MAX = 255


@dataclass(frozen=True, slots=True)
class PhotometricChange:
    """grey' = gain x grey + offset + N(0, noise_sigma), blurred by a Gaussian of blur_sigma px, shifted by
    (shift_x, shift_y) px (both images alike, so that the rectification holds); seeded per frame."""

    gain: float = 1.0
    offset: float = 0.0
    noise_sigma: float = 0.0
    blur_sigma: float = 0.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    seed: int = 0

    def apply(self, image: np.ndarray, frame: int, camera: int) -> np.ndarray:
        """The changed image of one camera (0 left, 1 right) of a frame; deterministic."""
        changed = image.astype(np.float32) * self.gain + self.offset
        if self.noise_sigma > 0:
            rng = np.random.default_rng([self.seed, frame, camera])
            changed += rng.normal(0.0, self.noise_sigma, image.shape).astype(np.float32)
        if self.blur_sigma > 0:
            changed = cv2.GaussianBlur(changed, (0, 0), self.blur_sigma)
        if self.shift_x or self.shift_y:
            shift = np.array([[1.0, 0.0, self.shift_x], [0.0, 1.0, self.shift_y]], dtype=np.float32)
            changed = cv2.warpAffine(changed, shift, image.shape[::-1], borderMode=cv2.BORDER_REPLICATE)
        return np.clip(np.rint(changed), 0, GREY_MAX).astype(np.uint8)


@dataclass(frozen=True)
class ReplayedSequence:
    """The frames `order` of a base sequence, frame k seen through `changes[k]` (None: unchanged), at the base's
    median frame period. Its ground truth is the base's at the replayed frames (evaluation only)."""

    base: KittiSequence
    order: tuple[int, ...]
    changes: tuple[PhotometricChange | None, ...]
    label: str = "replay"

    def __post_init__(self) -> None:
        if len(self.order) != len(self.changes):
            raise ValueError(f"{len(self.order)} frames but {len(self.changes)} changes")
        if not self.order or min(self.order) < 0 or max(self.order) >= len(self.base):
            raise ValueError(f"replayed frames must lie in 0..{len(self.base) - 1}")

    @property
    def name(self) -> str:
        return f"{self.base.name}-{self.label}"

    @property
    def camera(self) -> CameraConfig:
        return self.base.camera

    @property
    def timestamps(self) -> np.ndarray:
        period = float(np.median(np.diff(self.base.timestamps))) if len(self.base) > 1 else 0.1
        return np.arange(len(self.order)) * period

    @property
    def ground_truth(self) -> Trajectory | None:
        truth = self.base.ground_truth
        return None if truth is None else Trajectory(self.timestamps, truth.poses[list(self.order)])

    def __len__(self) -> int:
        return len(self.order)

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        left, right = self.base.stereo_pair(self.order[index])
        change = self.changes[index]
        if change is None:
            return left, right
        return change.apply(left, index, 0), change.apply(right, index, 1)


def forward_back_forward(
    base: KittiSequence, third_pass: PhotometricChange, frames: Sequence[int] | None = None
) -> ReplayedSequence:
    """The frames forward, back to the start, and forward again through `third_pass`'s change."""
    forward = list(frames if frames is not None else range(len(base)))
    back = forward[-2::-1]
    again = forward[1:]
    return ReplayedSequence(
        base,
        tuple(forward + back + again),
        (None,) * (len(forward) + len(back)) + (third_pass,) * len(again),
        label="forward-back-forward",
    )
