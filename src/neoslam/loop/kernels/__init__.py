"""The inner loops of retrieval and place matching, compiled with numba.

A place match runs over a few dozen to a few hundred candidate assignments and a few to a few dozen fitted pairs,
and a query's retrieval over a few hundred triangle keys and their tens of thousands of postings, where numpy's cost
per call, not the arithmetic, is what they took: written out as loops and compiled, each of these takes
microseconds. They are pure functions of arrays with the same arithmetic as the formulas their callers document
(loop.index and loop.triangles: the eligible keyframes, triangle keys and scores; loop.matching: the affinity, eq. 2
and 4, and spectral matching, eq. 5; loop.verification: the weighted fit, its trimming and the contradiction test;
loop.places: a place's merged objects). Compiled once per machine and cached beside their source (numba's
`cache=True`); `make setup` compiles them (`python -m neoslam.loop.kernels`).
"""

from __future__ import annotations

import threading
from functools import lru_cache

import numpy as np

from neoslam.loop.kernels.assignment import (
    affinity,
    block,
    compressed,
    distance_variances,
    greedy_assignment,
    group_sum,
    kept_objects,
    merged_objects,
    principal_eigenvector,
    supported,
)
from neoslam.loop.kernels.contradiction import counterparts, ground, in_view, missed_objects
from neoslam.loop.kernels.fit import fit_pairs, pair_bits, pair_columns, pair_covariances, trimmed
from neoslam.loop.kernels.retrieval import triangle_keys, triangle_scores, within_reach

__all__ = [
    "affinity", "block", "compressed", "distance_variances", "greedy_assignment", "group_sum",
    "kept_objects", "merged_objects", "principal_eigenvector", "supported", "counterparts", "ground", "in_view",
    "missed_objects", "fit_pairs", "pair_bits", "pair_columns", "pair_covariances", "trimmed", "triangle_keys",
    "triangle_scores", "within_reach", "plane", "label_codes", "compile_all",
]  # fmt: skip


LABEL_CODES_CACHED = 4096  # label tuples (a keyframe's, a place's, a query's) whose codes are kept


def plane(points: np.ndarray, columns: int = 2) -> np.ndarray:
    """The first `columns` columns of (n, >= columns) points (ground x, y by default) as a contiguous float array, as
    the kernels take them."""
    return np.ascontiguousarray(np.asarray(points, dtype=float)[:, :columns])


_CODES: dict[str, int] = {}  # every label coded so far: a code stands for one label in every call
_CODING = threading.Lock()  # two threads coding new labels at once must not give them one code


@lru_cache(maxsize=LABEL_CODES_CACHED)
def _codes_of(labels: tuple[str, ...]) -> np.ndarray:
    with _CODING:
        return np.array([_CODES.setdefault(label, len(_CODES)) for label in labels], dtype=np.int64)


def label_codes(*sequences) -> tuple[np.ndarray, ...]:
    """Integer codes (int64) of label sequences, equal wherever the labels are; the labels of a keyframe (a tuple)
    are coded once and their codes kept, shared by every caller: not to be written to."""
    return tuple(_codes_of(tuple(labels)) for labels in sequences)


def compile_all() -> None:
    """Compile (or load from the cache) every kernel for the argument types matching passes them: a first run on a
    machine otherwise compiles each when first called, some seconds in all."""
    centres = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    ground_points = np.ascontiguousarray(centres[:, :2])
    covariances = np.repeat(np.eye(2)[None] * 0.1, 3, axis=0)
    objects = np.arange(3, dtype=np.int64)
    distances = np.sqrt(((ground_points[:, None] - ground_points[None]) ** 2).sum(axis=2))
    variances = distance_variances(ground_points, covariances, 0.1)
    sparse = affinity(distances, distances, variances, variances, objects, objects, 1.5, 2.5, True)
    weight = principal_eigenvector(*sparse, 50, 1e-5)
    principal_eigenvector(*compressed(np.eye(3)), 50, 1e-5)
    chosen = greedy_assignment(weight, objects, objects, 3, 3)
    among = block(*sparse, chosen)
    group_sum(among, supported(among, np.arange(len(chosen)), 1))
    columns = pair_columns(centres, centres, covariances, covariances, 0.1)
    fit_pairs(columns, 2)
    found, yaw, *_, d2, _distances, _inliers = trimmed(columns, 2, 2.0, 9.2, 4.0, False)
    pair_covariances(covariances, covariances, yaw, 0.1)
    pair_bits(covariances, covariances, yaw, 0.1, d2, np.ones(3), 150.0)
    counterparts(ground_points, objects, covariances, ground_points, objects, covariances, 2.5, 9.2, 0.1, True)
    ground(ground_points, np.zeros(2))
    known = np.ones(3, dtype=np.bool_)
    side = (ground_points, objects, covariances, known, np.zeros(2))
    missed_objects(side, side, 1.0, (2.5, 9.2, 0.1, True))
    in_view(ground_points, np.zeros((1, 3)), 0.5)
    kept_objects(ground_points, objects, objects, 2.5, np.zeros(3, dtype=np.bool_))
    for spread in (False, True):
        keys = triangle_keys(ground_points, np.zeros(2), objects, 12, 40.0, 1.0, spread, 6, 8)
    slots = np.zeros(len(keys), dtype=np.int32)
    triangle_scores(keys, slots, keys, slots, keys, np.ones(1))
    within_reach(ground_points, np.zeros(3), np.zeros(2), 1.0, 1.0, 0.1, 0.5)
