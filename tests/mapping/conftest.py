"""Shared fixtures of the mapping tests: a square driven with odometry whose constant yaw bias keeps dead reckoning
from closing (used by the pose-graph, relaxation and experience-map tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.geometry import make_pose, relative_pose
from neoslam.mapping.graph import MapGraph
from neoslam.types import Link


def _yaw_pose(yaw: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.asarray(translation, dtype=float))


@dataclass(frozen=True)
class BiasedSquare:
    """A square of `side_nodes` nodes a side, `step_m` apart, turning left 90 degrees after each side; its odometry
    adds `yaw_bias_rad` of yaw to every step (by default 0.2 rad, 11 degrees, over one lap)."""

    side_nodes: int = 25
    step_m: float = 1.0
    yaw_bias_rad: float = 0.002

    @property
    def lap(self) -> int:
        """Nodes in one lap."""
        return 4 * self.side_nodes

    def truth(self, laps: int = 1, start: np.ndarray | None = None, closed: bool = False) -> np.ndarray:
        """True poses driving `laps` times around the square (`laps * lap` poses), plus with `closed` the pose back
        at the start after the last lap; with `start`, the square is driven from that pose instead of the origin."""
        one_lap = []
        position, yaw = np.zeros(3), 0.0
        for _ in range(4):
            for _ in range(self.side_nodes):
                one_lap.append(_yaw_pose(yaw, position))
                position = position + self.step_m * np.array([np.cos(yaw), np.sin(yaw), 0.0])
            yaw += np.pi / 2
        poses = one_lap * laps + ([_yaw_pose(yaw, position)] if closed else [])
        poses = np.array(poses)
        return poses if start is None else start @ poses

    def odometry_steps(self, truth: np.ndarray) -> np.ndarray:
        """The yaw-biased odometry between consecutive true poses."""
        return relative_pose(truth[:-1], truth[1:]) @ _yaw_pose(self.yaw_bias_rad)

    def dead_reckoned(self, truth: np.ndarray) -> np.ndarray:
        """The yaw-biased odometry chained from the first true pose."""
        odometry = [truth[0]]
        for step in self.odometry_steps(truth):
            odometry.append(odometry[-1] @ step)
        return np.array(odometry)

    def graph(self, truth: np.ndarray, loops: list[tuple[int, int, np.ndarray]]) -> MapGraph:
        """Nodes at the dead-reckoned poses of yaw-biased odometry, odometry links, then the given loop links."""
        graph = MapGraph(poses=truth[:1].copy())
        for index, step in enumerate(self.odometry_steps(truth)):
            graph.add_node(graph.poses[-1] @ step)
            graph.add_link(Link(index, index + 1, step, "odometry", float(np.linalg.norm(step[:3, 3]))))
        for source, target, relative in loops:
            graph.add_link(Link(source, target, relative, "loop", 0.0))
        return graph

    @staticmethod
    def loop(truth: np.ndarray, source: int, target: int) -> tuple[int, int, np.ndarray]:
        """A loop link from `source` to `target` measured between their true poses."""
        return source, target, relative_pose(truth[source], truth[target])


@pytest.fixture(scope="session")
def biased_square() -> BiasedSquare:
    """The yaw-biased square: 25 nodes a side, 1 m apart, 0.002 rad of yaw bias per odometry step."""
    return BiasedSquare()
