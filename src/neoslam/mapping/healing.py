"""A map that heals (beyond the paper): loop links the optimised map disagrees with are withdrawn.

A pose graph with a robust kernel on its loop links limits what one wrong closure can do, but does not undo it: the
link stays, and with every optimisation it still bends the map by what the kernel lets through. After each
optimisation every loop link of the part solved is re-checked against the solution: the one whose whitened residual
is largest, beyond `withdraw_sigmas` standard deviations (a Huber kernel at 3 sigma then weighs it at most a third),
is withdrawn, and the part is solved again without it, until every loop link agrees. With object landmarks the
loop links are judged the same way, by the pose graph of odometry and loop links, and a withdrawn link's factor is
removed from the landmark solver (neoslam.mapping.backend). A link that is the only tie between two stretches of
the part (the link that joined a later session to the map) is never withdrawn: without it the part falls apart and
its frame is lost. A true closure only disagrees when the odometry since the map last closed a loop has drifted
far more than its noise model allows; the benchmark counts such withdrawals.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from neoslam.mapping.graph import MapGraph
from neoslam.mapping.pose_graph import PoseGraphReport

__all__ = ["disagreeing_link"]


def disagreeing_link(graph: MapGraph, report: PoseGraphReport, part: np.ndarray, withdraw_sigmas: float) -> int | None:
    """The loop link (index into graph.links) the solution `report` disagrees with most beyond `withdraw_sigmas`,
    whose endpoints the other links in use of `part` still join; None: every loop link agrees (or 0: never)."""
    if withdraw_sigmas <= 0:
        return None
    outliers = sorted((loop for loop in report.loops if loop.sigmas > withdraw_sigmas), key=lambda loop: -loop.sigmas)
    for loop in outliers:
        if _joined_without(graph, loop.link_index, part):
            return loop.link_index
    return None


def _joined_without(graph: MapGraph, index: int, part: np.ndarray) -> bool:
    """Whether the link's two experiences are joined by the part's other links in use."""
    others = [i for i in graph.live() if i != index and part[graph.links[i].source]]
    sources = np.array([graph.links[i].source for i in others], dtype=int)
    targets = np.array([graph.links[i].target for i in others], dtype=int)
    n = len(graph)
    adjacency = coo_matrix((np.ones(len(others)), (sources, targets)), shape=(n, n))
    _, labels = connected_components(adjacency, directed=False)
    link = graph.links[index]
    return bool(labels[link.source] == labels[link.target])
