"""Compiled loop of triangle retrieval: the scores of the stored keyframes that share a query's keys
(loop.triangles)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["triangle_keys", "triangle_scores", "within_reach"]


@njit(cache=True)
def _runs(sorted_keys: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each key's run of equal keys starts in `sorted_keys`, and its length (0: not there): its end found by
    walking the run, which is read next anyway, rather than by a second search through the whole array."""
    low = np.searchsorted(sorted_keys, keys)
    count = np.zeros(len(keys), dtype=np.int64)
    for k in range(len(keys)):
        end = low[k]
        while end < len(sorted_keys) and sorted_keys[end] == keys[k]:
            end += 1
        count[k] = end - low[k]
    return low, count


@njit(cache=True)
def _add_postings(
    slots: np.ndarray,
    query_keys: np.ndarray,
    low: np.ndarray,
    count: np.ndarray,
    idf: np.ndarray,
    scores: np.ndarray,
    shared: np.ndarray,
) -> None:
    """Add each query key's idf to the score of every slot in its run [low, low + count) of `slots`, and 1 to its
    shared count."""
    for k in range(len(query_keys)):
        for j in range(low[k], low[k] + count[k]):
            scores[slots[j]] += idf[k]
            shared[slots[j]] += 1.0


@njit(cache=True)
def triangle_scores(
    keys: np.ndarray,
    slots: np.ndarray,
    tail_keys: np.ndarray,
    tail_slots: np.ndarray,
    query_keys: np.ndarray,
    key_counts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per stored slot (len(key_counts) of them): the summed inverse document frequency, log((N + 1) / (n_k + 0.5)),
    of the query keys it holds (n_k: the stored keyframes holding key k, N: the stored keyframes), over the square
    root of its number of keys; and the number of query keys it holds. `keys` and `tail_keys` are sorted, each with
    the slot of its keyframe; a keyframe's keys are all in one of them."""
    stored = len(key_counts)
    low, count = _runs(keys, query_keys)
    tail_low, tail_count = _runs(tail_keys, query_keys)
    idf = np.empty(len(query_keys))
    for k in range(len(query_keys)):
        idf[k] = math.log((stored + 1.0) / (count[k] + tail_count[k] + 0.5))
    scores = np.zeros(stored)
    shared = np.zeros(stored)
    _add_postings(slots, query_keys, low, count, idf, scores, shared)
    _add_postings(tail_slots, query_keys, tail_low, tail_count, idf, scores, shared)
    for slot in range(stored):
        scores[slot] /= math.sqrt(max(key_counts[slot], 1.0))
    return scores, shared


@njit(cache=True)
def _sorted_sides(sides: np.ndarray, labels: np.ndarray) -> None:
    """Sort a triangle's three sides in place, shortest first, ties in their order, each label with its side."""
    for i in range(1, 3):
        j = i
        while j > 0 and sides[j] < sides[j - 1]:
            sides[j], sides[j - 1] = sides[j - 1], sides[j]
            labels[j], labels[j - 1] = labels[j - 1], labels[j]
            j -= 1


@njit(cache=True)
def triangle_keys(
    centres: np.ndarray,
    position: np.ndarray,
    codes: np.ndarray,
    max_objects: int,
    max_side: float,
    side_bin: float,
    spread: bool,
    label_bits: int,
    side_bits: int,
) -> np.ndarray:
    """The unique keys (sorted) of the triangles of every three of the `max_objects` objects nearest the keyframe's
    current object (the one nearest `position`), ground plane (centres (n, 2)), whose longest side is at most
    `max_side`: the triangle's label codes and side bins (`side_bin` m), each ordered by its sides, shortest first,
    each label that of the vertex opposite its side, packed `label_bits` and `side_bits` to a field. `spread`: each
    side also under its nearer neighbouring bin (a query's keys), else its own bin only (a stored keyframe's)."""
    n = len(centres)
    if n < 3:
        return np.zeros(0, dtype=np.int64)
    current, nearest_distance = 0, np.inf
    for i in range(n):
        dx, dy = centres[i, 0] - position[0], centres[i, 1] - position[1]
        distance = math.sqrt(dx * dx + dy * dy)
        if distance < nearest_distance:
            current, nearest_distance = i, distance
    around = np.empty(n)
    for i in range(n):
        dx, dy = centres[i, 0] - centres[current, 0], centres[i, 1] - centres[current, 1]
        around[i] = math.sqrt(dx * dx + dy * dy)
    nearest = np.argsort(around, kind="mergesort")[:max_objects]
    m = len(nearest)
    choices = 8 if spread else 1
    keys = np.empty(m * (m - 1) * (m - 2) // 6 * choices, dtype=np.int64)
    count = 0
    sides, labels = np.empty(3), np.empty(3, dtype=np.int64)
    bins, neighbours = np.empty(3, dtype=np.int64), np.empty(3, dtype=np.int64)
    for a in range(m):
        for b in range(a + 1, m):
            for c in range(b + 1, m):
                vertices = (nearest[a], nearest[b], nearest[c])
                for k in range(3):  # the side opposite each vertex
                    p, q = vertices[(k + 1) % 3], vertices[(k + 2) % 3]
                    dx, dy = centres[p, 0] - centres[q, 0], centres[p, 1] - centres[q, 1]
                    sides[k] = math.sqrt(dx * dx + dy * dy)
                    labels[k] = codes[vertices[k]]
                _sorted_sides(sides, labels)
                if not sides[2] <= max_side:
                    continue
                for k in range(3):
                    scaled = sides[k] / side_bin
                    bins[k] = np.int64(math.floor(scaled))
                    neighbours[k] = bins[k] + 1 if scaled - bins[k] >= 0.5 else bins[k] - 1
                for choice in range(choices):
                    key, valid = np.int64(0), True
                    for k in range(3):
                        key = (key << label_bits) | labels[k]
                    for k in range(3):
                        side = neighbours[k] if (choice >> k) & 1 else bins[k]
                        if spread and (side < 0 or side >= 2**side_bits):
                            valid = False
                        key = (key << side_bits) | side
                    if valid:
                        keys[count] = key
                        count += 1
    return np.unique(keys[:count])


@njit(cache=True)
def within_reach(
    positions: np.ndarray,
    odometer: np.ndarray,
    position: np.ndarray,
    odometer_now: float,
    radius: float,
    radius_per_metre: float,
    exclude_recent: float,
) -> np.ndarray:
    """Slots (increasing) of the stored keyframes (ground positions (n, 2), odometer readings (n,)) made at least
    `exclude_recent` metres of travel ago and within `radius` plus `radius_per_metre` of the metres travelled since
    of `position` (compared squared: no root over every stored keyframe)."""
    found = np.empty(len(odometer), dtype=np.int64)
    count = 0
    for slot in range(len(odometer)):
        travelled = odometer_now - odometer[slot]
        reach = radius + radius_per_metre * travelled
        dx, dy = positions[slot, 0] - position[0], positions[slot, 1] - position[1]
        if dx * dx + dy * dy <= reach * reach and travelled >= exclude_recent:
            found[count] = slot
            count += 1
    return found[:count]
