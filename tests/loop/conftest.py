"""Builders shared by the loop-closure tests: keyframes, streets of objects and planar motions, made by hand."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from neoslam.geometry import make_pose
from neoslam.types import Keyframe

PATCH = 16
LABELS = ("car", "car", "car", "truck", "bicycle", "person")


def yaw_pose(yaw: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return make_pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.asarray(translation, dtype=float))


def keyframe(
    centers,
    labels,
    patches: np.ndarray | None = None,
    pose: np.ndarray | None = None,
    id: int = 0,
    frame_index: int = 0,
    views: np.ndarray | None = None,
) -> Keyframe:
    centers = np.asarray(centers, dtype=float).reshape(-1, 3)
    if patches is None:  # one plain grey level per object: all alike in appearance
        patches = np.full((len(centers), PATCH, PATCH), 128, np.uint8)
    return Keyframe(
        id=id,
        frame_index=frame_index,
        pose=np.eye(4) if pose is None else pose,
        centers=centers,
        labels=tuple(labels),
        patches=patches,
        views=views,
    )


class Street:
    """Objects parked along both sides of a street on the x axis, each class with its own look: objects of a class
    look alike (patch RMSE well under the paper's 80), so appearance alone cannot tell them apart."""

    def __init__(self, rng: np.random.Generator, count: int, length: float, individuality: float = 15.0) -> None:
        prototypes = {label: rng.uniform(40, 215, (PATCH, PATCH)) for label in set(LABELS)}
        self.labels = tuple(rng.choice(LABELS, count).tolist())
        gaps = rng.uniform(3.0, 6.0, count)
        x = np.cumsum(gaps) - gaps[0]
        x *= length / max(x[-1], 1e-9)
        side = np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
        y = side * rng.uniform(4.0, 7.0, count)
        self.centers = np.column_stack([x, y, rng.uniform(0.3, 1.2, count)])
        self.textures = np.array(
            [prototypes[label] + rng.normal(0, individuality, (PATCH, PATCH)) for label in self.labels]
        )

    def patches(self, rng: np.random.Generator, indices, noise: float = 5.0) -> np.ndarray:
        """Patches of objects `indices` as one more observation sees them."""
        seen = self.textures[np.asarray(indices)] + rng.normal(0, noise, (len(indices), PATCH, PATCH))
        return np.clip(np.round(seen), 0, 255).astype(np.uint8)


@pytest.fixture
def make_keyframe() -> Callable[..., Keyframe]:
    return keyframe


@pytest.fixture
def make_street() -> Callable[..., Street]:
    return Street


@pytest.fixture
def make_yaw_pose() -> Callable[..., np.ndarray]:
    return yaw_pose
