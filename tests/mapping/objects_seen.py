"""Objects along the sides of the yaw-biased square (tests/mapping/conftest.py) and a stand-in for the object map that
gives the landmark solver their observation sums: the mapping tests that run the solver share them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from neoslam.config import ObjectMapConfig
from neoslam.types import ObjectMapState

SIGHT_M = 15.0  # nodes see the objects this close
VIEW_SIGMA_M = 0.3  # each view's std (the object map's position_sigma_floor)


def object_positions(square) -> np.ndarray:
    """Objects 4 m outside and inside every side of the square, every 5 m."""
    side = square.side_nodes * square.step_m
    along = np.arange(2.5, side, 5.0)
    rows = []
    for offset in (-4.0, 4.0):
        rows += [[x, offset, 0.0] for x in along]
        rows += [[side - offset, y, 0.0] for y in along]
        rows += [[x, side - offset, 0.0] for x in along]
        rows += [[offset, y, 0.0] for y in along]
    return np.array(rows)


@dataclass
class FakeObjectMap:
    """The object map's observation sums as the solver reads them: one view per (object, node), count 1."""

    config: ObjectMapConfig = field(default_factory=ObjectMapConfig)
    merges: list[tuple[int, int]] = field(default_factory=list)
    footprints: dict[str, tuple[float, float]] | None = None  # views at the objects' middles: no centre shift
    objects: int = 0
    pairs: list[tuple[int, int, np.ndarray]] = field(default_factory=list)  # object, node, local position

    def see(self, node: int, pose: np.ndarray, positions: np.ndarray, ids: np.ndarray) -> None:
        local = (positions - pose[:3, 3]) @ pose[:3, :3]
        for index in np.flatnonzero(np.linalg.norm(local, axis=1) < SIGHT_M):
            self.pairs.append((int(ids[index]), node, local[index]))
        self.objects = max(self.objects, int(ids.max()) + 1)

    def merge(self, gone: int, kept: int) -> None:
        self.pairs = [(kept if o == gone else o, n, p) for o, n, p in self.pairs]
        self.merges.append((gone, kept))

    def state(self) -> ObjectMapState:
        weight = 1.0 / VIEW_SIGMA_M**2
        keys = sorted({(o, n) for o, n, _ in self.pairs})
        rows = {key: row for row, key in enumerate(keys)}
        sums, counts = np.zeros((len(keys), 3)), np.zeros(len(keys), dtype=int)
        for o, n, p in self.pairs:
            sums[rows[(o, n)]] += weight * p
            counts[rows[(o, n)]] += 1
        object_counts = np.zeros(self.objects, dtype=int)
        np.add.at(object_counts, [o for o, _ in keys], counts)
        return ObjectMapState(
            labels=["car"] * self.objects,
            counts=object_counts,
            pair_object=np.array([o for o, _ in keys], dtype=int),
            pair_experience=np.array([n for _, n in keys], dtype=int),
            pair_sums=sums,
            pair_weights=weight * counts,
            pair_counts=counts,
        )
