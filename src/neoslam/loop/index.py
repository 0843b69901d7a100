"""Candidate retrieval: which stored keyframes a new keyframe is matched against in full.

The paper compares a keyframe with all others. Here the query cost stays small as the map grows: a stored keyframe
is a candidate only if it is not recent (`exclude_recent_distance` of travel), and lies within a search radius of
the current estimated position that grows with the distance travelled since it was made (odometry drift bounds
how far the estimate can be off). Candidates are ranked by the object triangles they share with the query
(`matching.retrieval: triangles`, loop.triangles) or by a coarse signature (label histogram and histogram of
pairwise object distances), and the best few places are matched.

Keyframes are named by their id everywhere (eligible, candidates, nearest, odometer): a keyframe that a closure
recognises as a stored one is not stored again (lifelong mapping), so the stored ids need not be consecutive.
"""

from __future__ import annotations

from collections.abc import Iterator
from itertools import islice

import numpy as np

from neoslam.config import MatchingConfig
from neoslam.loop import kernels
from neoslam.loop.triangles import TriangleIndex
from neoslam.types import Keyframe

__all__ = ["KeyframeIndex", "StoredKeyframes", "signature"]

LABEL_BINS = 8  # labels hashed into this many bins (YOLO's classes in use are far fewer)
DISTANCE_BINS = np.linspace(0.0, 40.0, 21)  # m, pairwise object distances
INITIAL_CAPACITY = 256
RANK_CHUNK = 64  # eligible keyframes sorted at a time (best_first): a query tries a few places of a few keyframes


def _best_first(ids: np.ndarray, scores: np.ndarray) -> Iterator[int]:
    """The ids by decreasing score, ties in the order given (a stable sort of all of them), sorting only the best
    RANK_CHUNK (with any tied with the last of them) still left each time more are asked for."""
    remaining = np.arange(len(ids))
    while len(remaining):
        left = scores[remaining]
        if len(remaining) > RANK_CHUNK:
            threshold = -np.partition(-left, RANK_CHUNK - 1)[RANK_CHUNK - 1]
            best = left >= threshold  # every id scoring at least the chunk's last: the stable sort's next ones
        else:
            best = np.ones(len(remaining), dtype=bool)
        chosen = remaining[best]
        yield from ids[chosen[np.argsort(-scores[chosen], kind="stable")]].tolist()
        remaining = remaining[~best]


def _label_bin(label: str) -> int:
    return sum(label.encode()) % LABEL_BINS  # stable across runs, unlike hash()


def signature(keyframe: Keyframe) -> np.ndarray:
    """Unit vector of label counts and the distribution of pairwise distances: invariant to rotation and to the
    direction the place is driven in."""
    labels = np.bincount([_label_bin(label) for label in keyframe.labels], minlength=LABEL_BINS).astype(float)
    upper = keyframe.distances[np.triu_indices(len(keyframe.labels), k=1)]
    distances = np.histogram(upper, bins=DISTANCE_BINS)[0].astype(float)
    vector = np.concatenate([labels / max(labels.sum(), 1.0), distances / max(distances.sum(), 1.0)])
    return vector / max(np.linalg.norm(vector), 1e-12)


class StoredKeyframes:
    """The stored keyframes by id (`store[id]`, `id in store`), iterated in the order they were stored."""

    def __init__(self) -> None:
        self._by_id: dict[int, Keyframe] = {}
        self._ordered: list[Keyframe] = []

    def __getitem__(self, keyframe_id: int) -> Keyframe:
        return self._by_id[int(keyframe_id)]

    def __contains__(self, keyframe_id: object) -> bool:
        return keyframe_id in self._by_id

    def __iter__(self) -> Iterator[Keyframe]:
        return iter(self._by_id.values())

    def __len__(self) -> int:
        return len(self._by_id)

    def append(self, keyframe: Keyframe) -> None:
        if keyframe.id in self._by_id:
            raise ValueError(f"keyframe {keyframe.id} is stored already")
        self._by_id[keyframe.id] = keyframe
        self._ordered.append(keyframe)

    def at(self, slot: int) -> Keyframe:
        """The keyframe stored `slot`-th (0: the first)."""
        return self._ordered[slot]


class KeyframeIndex:
    """Stored keyframes with their position, odometer reading and signature, in growable arrays."""

    def __init__(self, config: MatchingConfig) -> None:
        self.config = config
        self.keyframes = StoredKeyframes()
        self._ids = np.zeros(INITIAL_CAPACITY, dtype=int)  # increasing: keyframes are stored in the order made
        self._slots: dict[int, int] = {}
        self._positions = np.zeros((INITIAL_CAPACITY, 2))
        self._odometer = np.zeros(INITIAL_CAPACITY)
        self._signatures = np.zeros((INITIAL_CAPACITY, LABEL_BINS + len(DISTANCE_BINS) - 1))
        self._label_counts: dict[str, int] = {}
        self._label_shares: dict[str, float] | None = None
        self._triangles = TriangleIndex(config.triangle_side_bin, config.triangle_objects, config.triangle_max_side)
        # the last eligible ids and their slots: a query ranks the ids `eligible` gave it, and finding 10,000 slots
        # of 20,000 stored by search costs a third of a millisecond
        self._last_eligible: tuple[np.ndarray, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.keyframes)

    def add(self, keyframe: Keyframe, odometer_m: float) -> None:
        n = len(self.keyframes)
        if n and keyframe.id <= self._ids[n - 1]:
            raise ValueError(f"keyframe {keyframe.id} stored after keyframe {self._ids[n - 1]}: ids must increase")
        if n == len(self._odometer):  # double the capacity
            self._ids = np.concatenate([self._ids, np.zeros_like(self._ids)])
            self._positions = np.concatenate([self._positions, np.zeros_like(self._positions)])
            self._odometer = np.concatenate([self._odometer, np.zeros_like(self._odometer)])
            self._signatures = np.concatenate([self._signatures, np.zeros_like(self._signatures)])
        self._ids[n] = keyframe.id
        self._slots[keyframe.id] = n
        self._positions[n] = keyframe.pose[:2, 3]
        self._odometer[n] = odometer_m
        self._signatures[n] = signature(keyframe)
        self._triangles.add(keyframe)
        self.keyframes.append(keyframe)
        for label in keyframe.labels:
            self._label_counts[label] = self._label_counts.get(label, 0) + 1
        self._label_shares = None

    def label_shares(self) -> dict[str, float]:
        """Each label's share among the stored keyframes' objects (an object in several keyframes counts in each)."""
        if self._label_shares is None:  # worked out once per keyframe stored: every match of a query asks for it
            total = sum(self._label_counts.values())
            self._label_shares = {label: count / total for label, count in self._label_counts.items()}
        return self._label_shares

    def slot(self, keyframe_id: int) -> int:
        """Where keyframe `keyframe_id` stands in the order stored."""
        return self._slots[int(keyframe_id)]

    def odometer(self, keyframe_id: int) -> float:
        """The odometer reading (m) when stored keyframe `keyframe_id` was made."""
        return float(self._odometer[self._slots[int(keyframe_id)]])

    def _slots_of(self, keyframe_ids: np.ndarray) -> np.ndarray:
        if self._last_eligible is not None and keyframe_ids is self._last_eligible[0]:
            return self._last_eligible[1]
        return np.searchsorted(self._ids[: len(self.keyframes)], keyframe_ids)

    def eligible(self, position: np.ndarray, odometer_m: float) -> np.ndarray:
        """Ids (increasing, read-only) of stored keyframes that are old enough and within the drift-bounded search
        radius."""
        n = len(self.keyframes)
        slots = kernels.within_reach(
            self._positions[:n], self._odometer[:n], np.asarray(position[:2], dtype=float), float(odometer_m),
            self.config.search_radius, self.config.search_radius_per_metre, self.config.exclude_recent_distance,
        )  # fmt: skip
        return self._eligible_ids(slots)

    def _eligible_ids(self, slots: np.ndarray) -> np.ndarray:
        """The ids of the eligible keyframes at `slots` (increasing), remembered with them for the ranking that
        follows."""
        ids = self._ids[slots]
        ids.flags.writeable = False  # known by identity to _slots_of
        self._last_eligible = (ids, slots)
        return ids

    def recent(self, keyframe_id: int, odometer_m: float) -> bool:
        """Whether a stored keyframe was made within the last `exclude_recent_distance` metres of travel."""
        return odometer_m - self.odometer(keyframe_id) < self.config.exclude_recent_distance

    def _scores(self, query: Keyframe, eligible: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """How alike each eligible keyframe is to the query: by shared triangles (`retrieval: triangles`,
        loop.triangles), or by signature; and with triangles, the number of triangle keys every stored keyframe
        (by slot) shares with the query."""
        slots = self._slots_of(eligible)
        if self.config.retrieval == "triangles":
            scores, shared = self._triangles.scores(query)
            return scores[slots], shared
        return self._signatures[slots] @ signature(query), None

    def best_first(self, query: Keyframe, eligible: np.ndarray) -> tuple[Iterator[int], np.ndarray | None]:
        """The eligible ids (increasing), most alike to the query first, ties in the order given, sorted a few at a
        time as they are read (a query tries a few places, and sorting every eligible keyframe of a large map costs
        more than matching them); and with triangles, the number of triangle keys every stored keyframe (by slot)
        shares with the query."""
        scores, shared = self._scores(query, eligible)
        return _best_first(eligible, scores), shared

    def candidates(self, query: Keyframe, odometer_m: float) -> np.ndarray:
        """Ids of the best `candidates` eligible keyframes, best first."""
        eligible = self.eligible(query.pose[:3, 3], odometer_m)
        ids, _ = self.best_first(query, eligible)
        return np.fromiter(islice(ids, self.config.candidates), dtype=eligible.dtype)

    @property
    def nbytes(self) -> int:
        """Memory of the retrieval arrays (positions, odometer, signatures, triangle keys), bytes."""
        arrays = (self._ids, self._positions, self._odometer, self._signatures)
        return int(sum(a.nbytes for a in arrays) + self._triangles.nbytes)

    def nearest(self, position: np.ndarray, among: np.ndarray) -> int:
        """The id of the keyframe among `among` (ids) whose pose is closest to a position (x, y)."""
        slots = self._slots_of(np.asarray(among))
        return int(among[np.argmin(np.linalg.norm(self._positions[slots] - position[:2], axis=1))])
