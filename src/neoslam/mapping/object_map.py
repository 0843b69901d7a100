"""The object map: every observation moved to the world with the current pose estimate and fused with the
nearest earlier object of the same label. Each observation is also kept relative to the experience it was made
in, so that the final map follows the experience map's correction."""

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
        self._anchored: list[tuple[int, int, np.ndarray]] = []  # (object, experience, point in its anchor frame)

    def add(
        self,
        pose: np.ndarray,
        observations: tuple[ObjectObservation, ...],
        anchor: int = 0,
        anchor_from_robot: np.ndarray | None = None,
    ) -> list[int]:
        """Fuse one frame's observations seen from robot pose T_world_robot; returns their object ids. `anchor`
        names the experience the frame belongs to and `anchor_from_robot` the robot pose in its frame."""
        if not observations:
            return []
        in_robot = camera_points_to_robot(np.array([o.center_camera for o in observations]))
        ids = [self._associate(o.label, p) for o, p in zip(observations, transform_points(pose, in_robot), strict=True)]
        relative = transform_points(np.eye(4) if anchor_from_robot is None else anchor_from_robot, in_robot)
        self._anchored += [(i, anchor, point) for i, point in zip(ids, relative, strict=True)]
        return ids

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

    def objects(self, anchor_poses: np.ndarray | None = None) -> list[MapObject]:
        """Objects seen at least min_observations times (single sightings are mostly false positives); with
        `anchor_poses` (the corrected experience poses) their observations follow the corrected map."""
        sums = self._sums
        if anchor_poses is not None and self._anchored:
            sums = np.zeros_like(self._sums)
            ids = np.array([i for i, _, _ in self._anchored])
            anchors = anchor_poses[[a for _, a, _ in self._anchored]]
            points = np.array([p for _, _, p in self._anchored])
            np.add.at(sums, ids, np.einsum("nij,nj->ni", anchors[:, :3, :3], points) + anchors[:, :3, 3])
        return [
            MapObject(i, self._labels[i], sums[i] / self._counts[i], int(self._counts[i]))
            for i in range(len(self._counts))
            if self._counts[i] >= self.config.min_observations
        ]
