"""Retrieval by object triangles (geometric hashing): which stored keyframes share the most of a query's layout.

Most street objects are cars in rows, so a keyframe's label counts and its histogram of pairwise distances look
alike everywhere. Three objects say more: the triangle they make is fixed by the place, whatever the direction it is
seen from. A keyframe's triangles (every three of its objects nearest its current object, sides in the ground
plane) are hashed by their labels and their sides, sorted, each rounded to `side_bin` metres; a query looks up each
of its triangles under the two nearest bins of every side (so that depth noise across a bin edge still finds it),
and a stored keyframe scores the inverse document frequency of every key it shares: a triangle found in few
keyframes counts for much, a common one (three cars a parking space apart) for little. The keys are held in one
sorted array, with the latest keyframes in a short unsorted tail merged in now and then, so a query is a few
vectorised searches whatever the map's size.
"""

from __future__ import annotations

import numpy as np

from neoslam.config.loop import TRIANGLE_SIDE_BITS
from neoslam.loop import kernels
from neoslam.types import Keyframe

__all__ = ["TriangleIndex", "triangle_keys"]

LABEL_BITS = 6  # up to 63 labels (COCO has 80 classes; a street uses far fewer)
SIDE_BITS = TRIANGLE_SIDE_BITS  # up to 255 bins a side (matching.triangle_max_side / triangle_side_bin)
MERGE_SHARE = 0.25  # the tail is merged into the main keys once it holds this share of them
MIN_TAIL = 4096  # or, while the index is small, this many keys
MAX_TAIL = 32768  # and at most this many: an add copies the tail (a merge costs a sort of all keys, < 1 ms per add)


def triangle_keys(
    keyframe: Keyframe, codes: np.ndarray, side_bin: float, max_objects: int, max_side: float, spread: bool
) -> np.ndarray:
    """The unique keys (sorted) of a keyframe's triangles (every three of its `max_objects` objects nearest its
    current object, ground plane, the longest side at most `max_side`) hashed by their label codes (`codes`: one per
    object) and their sides in `side_bin` bins, each ordered by its sides, shortest first, each label that of the
    vertex opposite its side; `spread`: each side also under its nearer neighbouring bin (a query's keys), else its
    own bin only (a stored keyframe's)."""
    return kernels.triangle_keys(
        kernels.plane(keyframe.centers), kernels.plane(keyframe.pose[None, :3, 3])[0],
        np.asarray(codes, dtype=np.int64), max_objects, max_side, side_bin, spread, LABEL_BITS, SIDE_BITS,
    )  # fmt: skip


class TriangleIndex:
    """Triangle keys of stored keyframes (by slot, in the order stored) and their scores against a query."""

    def __init__(self, side_bin: float, max_objects: int, max_side: float) -> None:
        self.side_bin, self.max_objects, self.max_side = side_bin, max_objects, max_side
        self._codes: dict[str, int] = {}
        self._keys = np.zeros(0, dtype=np.int64)  # sorted
        self._slots = np.zeros(0, dtype=np.int32)
        self._tail_keys = np.zeros(0, dtype=np.int64)  # sorted; equal keys in the order stored
        self._tail_slots = np.zeros(0, dtype=np.int32)
        self._key_counts = np.zeros(256)  # per slot: its number of keys (grown by doubling)
        self._stored = 0

    def __len__(self) -> int:
        return self._stored

    @property
    def nbytes(self) -> int:
        """Memory held by the keys, bytes."""
        return int(self._keys.nbytes + self._slots.nbytes + self._tail_keys.nbytes + self._tail_slots.nbytes)

    def _label_codes(self, labels: tuple[str, ...], add: bool) -> np.ndarray:
        for label in labels if add else ():
            self._codes.setdefault(label, min(len(self._codes) + 1, 2**LABEL_BITS - 1))
        return np.array([self._codes.get(label, 0) for label in labels], dtype=np.int64)

    def add(self, keyframe: Keyframe) -> None:
        """Store the next keyframe's keys (its slot is the number stored before it)."""
        codes = self._label_codes(keyframe.labels, add=True)
        keys = triangle_keys(keyframe, codes, self.side_bin, self.max_objects, self.max_side, spread=False)
        at = np.searchsorted(self._tail_keys, keys, side="right")
        self._tail_keys = np.insert(self._tail_keys, at, keys)
        self._tail_slots = np.insert(self._tail_slots, at, np.int32(self._stored))
        if self._stored == len(self._key_counts):
            self._key_counts = np.concatenate([self._key_counts, np.zeros_like(self._key_counts)])
        self._key_counts[self._stored] = len(keys)
        self._stored += 1
        if len(self._tail_keys) >= min(max(MIN_TAIL, MERGE_SHARE * len(self._keys)), MAX_TAIL):
            self._merge()

    def _merge(self) -> None:
        keys = np.concatenate([self._keys, self._tail_keys])
        slots = np.concatenate([self._slots, self._tail_slots])
        order = np.argsort(keys, kind="stable")
        self._keys, self._slots = keys[order], slots[order]
        self._tail_keys, self._tail_slots = self._tail_keys[:0], self._tail_slots[:0]

    def scores(self, query: Keyframe) -> tuple[np.ndarray, np.ndarray]:
        """Per stored slot: the summed inverse document frequency of the keys it shares with the query, over the
        square root of its number of keys (a keyframe of many objects shares more by chance); and the number of
        keys it shares."""
        stored = self._stored
        if not stored:
            return np.zeros(0), np.zeros(0)
        codes = self._label_codes(query.labels, add=False)
        keys = triangle_keys(query, codes, self.side_bin, self.max_objects, self.max_side, spread=True)
        return kernels.triangle_scores(
            self._keys, self._slots, self._tail_keys, self._tail_slots, keys, self._key_counts[:stored]
        )
