"""The navigation graph: the experience map as a road network a robot can follow (RatSLAM's and OpenRatSLAM's use
of the map: plan over experience links, both ways, weighted by travel).

Nodes are experiences at their corrected poses; every link of the map (odometry and loop links alike) joins its two
experiences both ways. A link weighs its length, the corrected distance (3-D) between its two experiences: the
experience map's relative pose is what was measured, but after the correction the corrected poses are where the
robot will drive. A loop link between two places a metre apart therefore weighs 1 m, as an odometry link of 1 m
does; a loop link between two experiences of one place (a street driven again) weighs MIN_LINK_M. With
`navigation.cost: time` a link weighs its expected travel time instead: its length over the mean speed its two
experiences were made at (those made slower than `min_known_speed` give none; without any, `expected_speed`).

Shortest routes are Dijkstra's (scipy.sparse.csgraph) from one start to every experience at once, which also
ranks every candidate of an object query. "Nearest experience" is a KD-tree of positions in the ground plane. A
running map grows every few frames and a correction moves every pose: `update` takes the new experiences and links
(links only grow) and rebuilds the sparse matrix and the tree only when something changed, when next asked.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from neoslam.config import NavigationConfig
from neoslam.errors import NoRouteError
from neoslam.navigation.view import MapView
from neoslam.types import Link

__all__ = ["MIN_LINK_M", "NavigationGraph", "ShortestPaths"]

# A link between two experiences at one place (a street driven again) still counts as a step: a zero weight would
# be no edge to scipy, and routes of equal length then take the fewer links.
MIN_LINK_M = 1e-3
_NO_PREDECESSOR = -9999  # scipy.sparse.csgraph's mark of a start or an unreached node


@dataclass(frozen=True)
class ShortestPaths:
    """Dijkstra from one start over the whole graph: each experience's cost from the start (inf: unreachable) and
    its predecessor on the cheapest route."""

    start: int
    costs: np.ndarray  # (n,) metres or seconds, as navigation.cost says
    predecessors: np.ndarray  # (n,) int

    def reachable(self, experience: int) -> bool:
        return bool(np.isfinite(self.costs[experience]))

    def path(self, goal: int) -> np.ndarray:
        """The experiences from the start to `goal`, both included; NoRouteError when it is unreachable."""
        if not self.reachable(goal):
            raise NoRouteError(f"no route from experience {self.start} to experience {goal}")
        predecessors = self.predecessors.tolist()  # Python ints: the walk back is a tight loop
        path, node = [goal], goal
        while node != self.start:
            node = predecessors[node]
            path.append(node)
        return np.asarray(path[::-1], dtype=int)


class NavigationGraph:
    """Experiences and their links both ways, weighted by length (or expected time), for shortest routes."""

    def __init__(self, config: NavigationConfig) -> None:
        self.config = config
        self.positions = np.zeros((0, 3))  # corrected experience positions
        self.speeds = np.zeros(0)  # per experience, the speed it was made at; NaN: none known
        self.sessions = np.zeros(0, dtype=int)  # per experience, the session that made it
        self.frames = np.zeros(0, dtype=int)  # per experience, the frame (of its session) it was made at
        self.pairs = np.zeros((0, 2), dtype=int)  # linked experiences, smaller id first, each pair once
        self._links: Sequence[Link] | None = None  # the list the pairs were read from
        self._links_read = 0
        self._withdrawn_read = 0  # withdrawn links known when the pairs were read
        self._pair_keys: set[tuple[int, int]] = set()
        self._matrix: csr_matrix | None = None  # None: rebuilt when next asked
        self._tree: cKDTree | None = None
        self._components: np.ndarray | None = None

    @classmethod
    def build(cls, view: MapView, config: NavigationConfig) -> NavigationGraph:
        graph = cls(config)
        graph.update(view)
        return graph

    def __len__(self) -> int:
        return len(self.positions)

    def update(self, view: MapView) -> bool:
        """Follow the map: new experiences and links, moved poses. Returns whether anything changed."""
        positions = np.asarray(view.positions, dtype=float)
        moved = positions.shape != self.positions.shape or not np.array_equal(positions, self.positions)
        if moved:
            self.positions = positions.copy()
            self._tree = None
        self._read_experiences(view)
        linked = self._read_links(view.links, view.withdrawn, len(positions))
        if moved or linked:
            self._matrix = None
        if linked:
            self._components = None
        return moved or linked

    def _read_experiences(self, view: MapView) -> None:
        """Each new experience's session, frame and speed when it was made (the norm of its linear velocity; NaN
        below min_known_speed). Experiences never change once made: only the new ones are read."""
        known = len(self.speeds) if len(self.speeds) <= len(view.experiences) else 0
        new = view.experiences[known:]
        if not new and known == len(self.speeds):
            return
        velocities = np.array([e.linear_velocity for e in new], dtype=float).reshape(-1, 3)
        speeds = np.linalg.norm(velocities, axis=1)
        speeds[~(speeds >= self.config.min_known_speed)] = np.nan  # also a NaN velocity
        self.speeds = np.concatenate([self.speeds[:known], speeds])
        sessions = np.fromiter((e.session for e in new), dtype=int, count=len(new))
        frames = np.fromiter((e.frame_index for e in new), dtype=int, count=len(new))
        self.sessions = np.concatenate([self.sessions[:known], sessions])
        self.frames = np.concatenate([self.frames[:known], frames])

    def _read_links(self, links: Sequence[Link], withdrawn: Sequence[int], n: int) -> bool:
        """Take the links not read yet, but the withdrawn (a map's links only grow; another list, or a link
        withdrawn since, is read from its start)."""
        reset = links is not self._links or len(links) < self._links_read or len(withdrawn) != self._withdrawn_read
        if reset:
            self._links, self._links_read, self._withdrawn_read = links, 0, len(withdrawn)
            self._pair_keys = set()
            self.pairs = np.zeros((0, 2), dtype=int)
        out = set(withdrawn)
        start = self._links_read
        self._links_read = len(links)
        added = []
        for index in range(start, len(links)):
            if index in out:
                continue
            link = links[index]
            a, b = sorted((int(link.source), int(link.target)))
            if a != b and a >= 0 and b < n and (a, b) not in self._pair_keys:
                self._pair_keys.add((a, b))
                added.append((a, b))
        if added:
            self.pairs = np.concatenate([self.pairs, np.asarray(added, dtype=int)])
        return reset or bool(added)

    # Weights

    def lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Length of the steps a[i] -> b[i], metres: the corrected distance, at least MIN_LINK_M."""
        return np.maximum(np.linalg.norm(self.positions[b] - self.positions[a], axis=-1), MIN_LINK_M)

    def times(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Expected time of the steps a[i] -> b[i], seconds: length over the two experiences' mean known speed (one
        known: that one; none: expected_speed)."""
        both = np.stack([self.speeds[a], self.speeds[b]])
        known = np.isfinite(both).sum(axis=0)
        mean = np.nan_to_num(both).sum(axis=0) / np.maximum(known, 1)
        return self.lengths(a, b) / np.where(known > 0, mean, self.config.expected_speed)

    def known_speed(self, experiences: np.ndarray) -> bool:
        """Whether any of these experiences recorded a speed."""
        return bool(np.isfinite(self.speeds[experiences]).any())

    def costs(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """What a route minimises over the steps a[i] -> b[i] (navigation.cost)."""
        return self.times(a, b) if self.config.cost == "time" else self.lengths(a, b)

    # Queries

    @property
    def matrix(self) -> csr_matrix:
        """The links both ways as a sparse matrix of costs (rebuilt after a change)."""
        if self._matrix is None:
            a, b = self.pairs[:, 0], self.pairs[:, 1]
            costs = self.costs(a, b)
            rows, columns = np.concatenate([a, b]), np.concatenate([b, a])
            n = len(self)
            self._matrix = csr_matrix((np.concatenate([costs, costs]), (rows, columns)), shape=(n, n))
        return self._matrix

    def shortest_paths(self, start: int) -> ShortestPaths:
        """Cheapest routes from `start` to every experience."""
        if not 0 <= start < len(self):
            raise NoRouteError(f"no experience {start} in the map (experiences 0 to {len(self) - 1})")
        with np.errstate(invalid="ignore"):
            costs, predecessors = dijkstra(self.matrix, directed=True, indices=start, return_predecessors=True)
        return ShortestPaths(start, costs, predecessors)

    @property
    def tree(self) -> cKDTree:
        """The experiences' positions in the ground plane."""
        if self._tree is None:
            self._tree = cKDTree(self.positions[:, :2])
        return self._tree

    def nearest(self, point: np.ndarray) -> tuple[int, float]:
        """The experience nearest to a point in the ground plane, and its distance (ties: the lowest id)."""
        distance, index = self.tree.query(np.asarray(point, dtype=float)[:2])
        return int(index), float(distance)

    def within(self, point: np.ndarray, radius: float) -> np.ndarray:
        """The experiences within `radius` of a point in the ground plane, ids increasing."""
        return np.asarray(sorted(self.tree.query_ball_point(np.asarray(point, dtype=float)[:2], radius)), dtype=int)

    @property
    def components(self) -> np.ndarray:
        """(n,) the part of the map each experience lies in: experiences joined by links, as label numbers (a session
        that never relocalised is a part of its own, in its own frame)."""
        if self._components is None:
            self._components = connected_components(self.matrix, directed=False)[1]
        return self._components
