"""The true street graph of a simulated drive (benchmarks/navigation.py, part `deliveries`): where a robot can drive
in the world the drive mapped, and the true shortest street path between two places. Ground truth: only the
benchmark reads it, never the SLAM path.

The drive's true trajectory is resampled every SPACING_M of travel. Each sample becomes a node, unless a node made
at least REVISIT_GAP_M of travel earlier lies within MERGE_RADIUS_M of it in the ground plane: the drive is passing a
street it drove before (in either direction, or across it at a junction), and the sample takes that node. Consecutive
samples' nodes are joined both ways, so a robot can turn onto any street the drive used, in either direction.
Where the drive took a corner on a curve and later drove straight through the junction (or two passes run in lanes
farther apart than MERGE_RADIUS_M), nodes within JUNCTION_RADIUS_M of each other can be far apart along the edges: a
junction edge joins two such nodes when the way round is more than DETOUR_FACTOR times the straight line, nearest
pairs first, so that a robot can turn there as on a street. An edge weighs its length in the ground plane; shortest
paths are Dijkstra's (scipy).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

__all__ = [
    "DETOUR_FACTOR",
    "JUNCTION_RADIUS_M",
    "MERGE_RADIUS_M",
    "REVISIT_GAP_M",
    "SPACING_M",
    "StreetGraph",
    "street_graph",
]

SPACING_M = 1.5  # a node every this much travel
# A sample this close to an earlier pass's node is on the same street (KITTI 00 and 05 drive a revisited street
# within a metre of the first pass, and a crossing within one sample spacing).
MERGE_RADIUS_M = 3.0
REVISIT_GAP_M = 30.0  # an earlier pass: a node made at least this much travel before (not the drive's own last ones)
JUNCTION_RADIUS_M = 5.0  # nodes this close may be joined by a junction edge (a corner's curve is within 5 m of it)
DETOUR_FACTOR = 3.0  # ... when the way round along the edges is longer than this many times the straight line
_MIN_EDGE_M = 1e-3  # an edge shorter than this still counts (a zero would be no edge to scipy)


@dataclass(frozen=True)
class StreetGraph:
    """Nodes (positions (n, 3) in the world frame) and undirected edges (pairs (m, 2), smaller id first)."""

    positions: np.ndarray
    edges: np.ndarray
    neighbours: tuple[np.ndarray, ...]  # per node, its neighbours' ids (increasing)

    def __len__(self) -> int:
        return len(self.positions)

    @cached_property
    def matrix(self) -> csr_matrix:
        """The edges both ways, weighted by ground-plane length."""
        a, b = self.edges[:, 0], self.edges[:, 1]
        lengths = np.maximum(np.linalg.norm(self.positions[b, :2] - self.positions[a, :2], axis=1), _MIN_EDGE_M)
        n = len(self)
        return csr_matrix((np.r_[lengths, lengths], (np.r_[a, b], np.r_[b, a])), shape=(n, n))

    def distances(self, source: int) -> np.ndarray:
        """(n,) shortest street distance from `source` to every node, m (inf: not connected)."""
        return dijkstra(self.matrix, directed=True, indices=source)

    def path(self, source: int, target: int) -> np.ndarray:
        """The nodes of a shortest street path, source first."""
        _, predecessors = dijkstra(self.matrix, directed=True, indices=source, return_predecessors=True)
        path = [target]
        while path[-1] != source:
            previous = int(predecessors[path[-1]])
            if previous < 0:
                raise ValueError(f"node {target} is not connected to node {source}")
            path.append(previous)
        return np.asarray(path[::-1], dtype=int)

    @cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.positions[:, :2])

    def nearest(self, point: np.ndarray) -> int:
        """The node nearest to a point in the ground plane."""
        return int(self.tree.query(np.asarray(point, dtype=float)[:2])[1])

    def nearest_nodes(self, points: np.ndarray) -> np.ndarray:
        """(k,) the node nearest to each of (k, 2+) points in the ground plane."""
        return np.asarray(self.tree.query(np.asarray(points, dtype=float).reshape(-1, points.shape[-1])[:, :2])[1])

    def heading(self, source: int, target: int) -> float:
        """Yaw of the edge source -> target in the world frame, rad."""
        step = self.positions[target, :2] - self.positions[source, :2]
        return float(np.arctan2(step[1], step[0]))

    def length(self, source: int, target: int) -> float:
        return float(np.hypot(*(self.positions[target, :2] - self.positions[source, :2])))


def _resampled(positions: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) points every `spacing` metres of travel along a trajectory, and their travel from its start."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(arc) > 1e-9])
    positions, arc = positions[keep], arc[keep]
    samples = np.arange(0.0, arc[-1] + 1e-9, spacing)
    return np.stack([np.interp(samples, arc, positions[:, k]) for k in range(3)], axis=1), samples


def street_graph(
    positions: np.ndarray,
    spacing: float = SPACING_M,
    merge_radius: float = MERGE_RADIUS_M,
    revisit_gap: float = REVISIT_GAP_M,
) -> StreetGraph:
    """The street graph of a drive's true positions (n, 3), world frame (see the module)."""
    samples, travel = _resampled(np.asarray(positions, dtype=float), spacing)
    nodes = np.zeros_like(samples)  # the first `count` rows are the nodes made so far
    made_at = np.zeros(len(samples))  # travel when each node was made
    count = 0
    edges: set[tuple[int, int]] = set()
    previous = -1
    for point, travelled in zip(samples, travel, strict=True):
        node = _earlier_node(point, travelled, nodes[:count], made_at[:count], merge_radius, revisit_gap)
        if node < 0:
            node, nodes[count], made_at[count] = count, point, travelled
            count += 1
        if previous >= 0 and node != previous:
            edges.add((min(previous, node), max(previous, node)))
        previous = node
    positions = nodes[:count].copy()
    edges |= _junction_edges(positions, edges, JUNCTION_RADIUS_M, DETOUR_FACTOR)
    pairs = np.array(sorted(edges), dtype=int).reshape(-1, 2)
    return StreetGraph(positions, pairs, _neighbours(count, pairs))


def _earlier_node(
    point: np.ndarray, travelled: float, nodes: np.ndarray, made_at: np.ndarray, radius: float, gap: float
) -> int:
    """The nearest node within `radius` made at least `gap` of travel before, or -1."""
    earlier = np.flatnonzero(made_at <= travelled - gap)
    if not len(earlier):
        return -1
    distances = np.linalg.norm(nodes[earlier, :2] - point[:2], axis=1)
    best = int(np.argmin(distances))
    return int(earlier[best]) if distances[best] <= radius else -1


def _junction_edges(
    positions: np.ndarray, edges: set[tuple[int, int]], radius: float, detour: float
) -> set[tuple[int, int]]:
    """Edges between nodes within `radius` whose way round along the edges (those given and those added before,
    nearest pairs first) is more than `detour` times their straight distance."""
    adjacency: dict[int, dict[int, float]] = {i: {} for i in range(len(positions))}

    def join(a: int, b: int) -> None:
        length = max(float(np.hypot(*(positions[a, :2] - positions[b, :2]))), _MIN_EDGE_M)
        adjacency[a][b] = adjacency[b][a] = length

    for a, b in edges:
        join(a, b)
    pairs = cKDTree(positions[:, :2]).query_pairs(radius, output_type="ndarray")
    gaps = np.linalg.norm(positions[pairs[:, 0], :2] - positions[pairs[:, 1], :2], axis=1)
    added = set()
    for (a, b), gap in zip(pairs[np.argsort(gaps, kind="stable")].tolist(), np.sort(gaps).tolist(), strict=True):
        if _way_round(adjacency, a, b, detour * gap) > detour * gap:
            join(a, b)
            added.add((min(a, b), max(a, b)))
    return added


def _way_round(adjacency: dict[int, dict[int, float]], source: int, target: int, limit: float) -> float:
    """The shortest distance along the edges from source to target, searched up to `limit` (beyond: inf)."""
    best = {source: 0.0}
    queue = [(0.0, source)]
    while queue:
        distance, node = heapq.heappop(queue)
        if node == target:
            return distance
        if distance > best.get(node, np.inf):
            continue
        for neighbour, length in adjacency[node].items():
            through = distance + length
            if through <= limit and through < best.get(neighbour, np.inf):
                best[neighbour] = through
                heapq.heappush(queue, (through, neighbour))
    return np.inf


def _neighbours(n: int, pairs: np.ndarray) -> tuple[np.ndarray, ...]:
    both = np.concatenate([pairs, pairs[:, ::-1]])
    order = np.lexsort((both[:, 1], both[:, 0]))
    both = both[order]
    starts = np.searchsorted(both[:, 0], np.arange(n + 1))
    return tuple(both[starts[i] : starts[i + 1], 1] for i in range(n))
