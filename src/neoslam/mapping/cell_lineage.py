"""Where the grid cells' state comes from (beyond the paper): the chain of anchors the closure gate judges drift by.

The cells integrate the odometry, so their state drifts with it; a recall (a closure's local-view calibration)
re-anchors them at a stored experience's state. An experience stores the cells as they were when it was made:
derived from the last anchor (the experience made before it, or the place a recall re-anchored them at) by the
metres of path integration since. Those derivations form a tree over the experiences, and the drift between the
cells now and a stored experience's cells is the drift of the odometry along the tree path between them: the metres
from the current anchor up to where the two derivations meet and down to the experience. Right after a recall at a
place made long after the candidate, that path runs through the place's own derivation, not only the few metres
since the recall; with no recall at all it is the travel since the candidate was made.

Experiences of another session (a stored map) have no derivation here: their cells started elsewhere, and the gate
does not compare them.
"""

from __future__ import annotations

import math

import numpy as np

from neoslam.config import ExperienceMapConfig

__all__ = ["CellLineage", "allowed_cell_distance"]

ROOT = -1  # the cells' starting state


class CellLineage:
    """Per experience, the anchor its cells were derived from and the metres of path integration since; and the
    current cells' anchor and metres."""

    def __init__(self) -> None:
        self._parent: list[int] = []
        self._metres: list[float] = []
        self._anchor = ROOT
        self._since = 0.0

    def __len__(self) -> int:
        return len(self._parent)

    @property
    def anchor(self) -> int:
        """The experience the current cells were last anchored at (ROOT: none yet)."""
        return self._anchor

    def travelled(self, metres: float) -> None:
        """The cells integrated this much odometry."""
        self._since += metres

    def made(self) -> int:
        """A new experience stores the current cells: it is their anchor from now on. Returns its id."""
        self._parent.append(self._anchor)
        self._metres.append(self._since)
        self._anchor, self._since = len(self._parent) - 1, 0.0
        return self._anchor

    def restored(self, count: int) -> None:
        """`count` experiences of another session: no derivation known in this one."""
        self._parent.extend([ROOT] * count)
        self._metres.extend([math.inf] * count)

    def anchored(self, experience: int) -> None:
        """A recall put the cells in a stored experience's state."""
        self._anchor, self._since = experience, 0.0

    def chain_metres(self, experience: int, limit: float = math.inf) -> float:
        """Metres of path integration between the cells now and `experience`'s stored cells (inf: no chain within
        `limit`, or through another session's experience)."""
        up = {self._anchor: self._since}  # the current anchor's ancestors, each with the metres to the cells now
        node, metres = self._anchor, self._since
        while node != ROOT and metres <= limit:
            metres += self._metres[node]
            node = self._parent[node]
            up.setdefault(node, metres)
        node, metres = experience, 0.0
        while metres <= limit:
            if node in up:
                chain = metres + up[node]
                return chain if chain <= limit else math.inf
            if node == ROOT:
                return math.inf
            metres += self._metres[node]
            node = self._parent[node]
        return math.inf


def allowed_cell_distance(
    config: ExperienceMapConfig, grid_dims: np.ndarray, lineage: CellLineage, experience: int
) -> float:
    """The paper's guard, gc_distance_threshold cells; the drift gate adds gc_drift_cells_per_100m for every 100 m
    of path integration between the cells now and the stored experience's cells, along the chain of anchors they
    were derived from. Right after a recall at the candidate's neighbour it is the paper's check; after a long loop,
    or after a recall at a place made long after the candidate, it admits the drift the odometry may have gathered
    along the chain. A chain longer than the grid can tell apart (the allowed distance beyond the farthest cells)
    opens the gate."""
    threshold = config.gc_distance_threshold
    rate = config.gc_drift_cells_per_100m
    if config.closure_gate != "drift" or rate == 0:
        return threshold
    farthest = float(np.linalg.norm(np.asarray(grid_dims, dtype=float) / 2.0))
    limit = 100.0 * max(farthest - threshold, 0.0) / rate
    return threshold + rate * lineage.chain_metres(experience, limit) / 100.0
