"""The object map: every observation moved to the world with the current pose estimate and fused with the
nearest earlier object of the same label (running mean of its centre)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import ObjectMapConfig
from neoslam.geometry import transform_points
from neoslam.io.frames import camera_points_to_robot
from neoslam.types import ObjectObservation

__all__ = ["MapObject", "ObjectMap"]


@dataclass(frozen=True, slots=True)
class MapObject:
    id: int
    label: str
    position: np.ndarray  # (3,) world frame, mean of its observations
    observations: int


class ObjectMap:
    """Objects fused from observations; grows as the robot drives."""

    def __init__(self, config: ObjectMapConfig) -> None:
        self.config = config
        self._labels: list[str] = []
        self._sums = np.zeros((0, 3))
        self._counts = np.zeros(0, dtype=int)

    def add(self, pose: np.ndarray, observations: tuple[ObjectObservation, ...]) -> list[int]:
        """Fuse one frame's observations seen from robot pose T_world_robot; returns their object ids."""
        if not observations:
            return []
        centres = camera_points_to_robot(np.array([o.center_camera for o in observations]))
        return [self._associate(o.label, p) for o, p in zip(observations, transform_points(pose, centres), strict=True)]

    def _associate(self, label: str, position: np.ndarray) -> int:
        if len(self._counts):
            means = self._sums / self._counts[:, None]
            distance = np.linalg.norm(means - position, axis=1)
            distance[np.asarray(self._labels) != label] = np.inf
            nearest = int(np.argmin(distance))
            if distance[nearest] <= self.config.association_radius:
                self._sums[nearest] += position
                self._counts[nearest] += 1
                return nearest
        self._labels.append(label)
        self._sums = np.vstack([self._sums, position])
        self._counts = np.append(self._counts, 1)
        return len(self._counts) - 1

    def objects(self) -> list[MapObject]:
        """Objects seen at least min_observations times (single sightings are mostly false positives)."""
        return [
            MapObject(i, self._labels[i], self._sums[i] / self._counts[i], int(self._counts[i]))
            for i in range(len(self._counts))
            if self._counts[i] >= self.config.min_observations
        ]
