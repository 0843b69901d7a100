"""Compiled loops of keyframe matching (loop.matching, eq. 2-5) and of merging a place's objects (loop.places)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "distance_variances",
    "affinity",
    "compressed",
    "block",
    "principal_eigenvector",
    "greedy_assignment",
    "supported",
    "group_sum",
    "merged_objects",
]


@njit(cache=True)
def distance_variances(centres: np.ndarray, covariances: np.ndarray, floor: float) -> np.ndarray:
    """(n, n) variance of each distance between two centres (ground x, y): each centre's ground covariance along the
    line between them, summed, plus `floor`."""
    n = len(centres)
    along = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            dx, dy = centres[j, 0] - centres[i, 0], centres[j, 1] - centres[i, 1]
            length = max(math.sqrt(dx * dx + dy * dy), 1e-9)
            dx, dy = dx / length, dy / length
            c = covariances[j]
            along[i, j] = dx * (c[0, 0] * dx + c[0, 1] * dy) + dy * (c[1, 0] * dx + c[1, 1] * dy)
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = along[i, j] + along[j, i] + floor
    return out


@njit(cache=True)
def _entry(
    query_distances: np.ndarray,
    stored_distances: np.ndarray,
    query_variances: np.ndarray,
    stored_variances: np.ndarray,
    i: int,
    j: int,
    p: int,
    q: int,
    e_max: float,
    sigmas: float,
    covariance: bool,
) -> float:
    """M's entry for the assignments (i, p) and (j, q) (see affinity)."""
    if i == j or p == q:
        return 0.0  # one object cannot match two
    difference = abs(query_distances[i, j] - stored_distances[p, q])
    if not covariance:
        return max(e_max - difference, 0.0)
    if difference >= e_max:  # most pairs: 0 unless the covariances widen the tolerance past it
        variance = query_variances[i, j] + stored_variances[p, q]
        if difference * difference >= variance * (sigmas * sigmas):
            return 0.0
    tolerance = max(math.sqrt(query_variances[i, j] + stored_variances[p, q]) * sigmas, e_max)
    return max(1.0 - difference / tolerance, 0.0) * e_max


@njit(cache=True)
def affinity(
    query_distances: np.ndarray,
    stored_distances: np.ndarray,
    query_variances: np.ndarray,
    stored_variances: np.ndarray,
    query_objects: np.ndarray,
    stored_objects: np.ndarray,
    e_max: float,
    sigmas: float,
    covariance: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M over the candidate assignments (query_objects[a], stored_objects[a]) as compressed rows (starts (c + 1,),
    columns, values; each row's columns increasing), its non-zero entries only (an affinity keeps a few per cent of
    them): e_max − |e_ij − e_i'j'| clipped at 0, or with `covariance` e_max · (1 − |e_ij − e_i'j'| / tolerance)
    clipped at 0, the tolerance at least e_max and `sigmas` standard deviations of the difference (the variances
    unused otherwise); 0 for two assignments that share an object."""
    c = len(query_objects)
    upper = c * (c - 1) // 2
    rows, columns, values = np.empty(upper, dtype=np.int64), np.empty(upper, dtype=np.int64), np.empty(upper)
    counts = np.zeros(c + 1, dtype=np.int64)
    found = 0
    for a in range(c):
        for b in range(a + 1, c):
            value = _entry(
                query_distances, stored_distances, query_variances, stored_variances, query_objects[a],
                query_objects[b], stored_objects[a], stored_objects[b], e_max, sigmas, covariance,
            )  # fmt: skip
            if value != 0.0:
                rows[found], columns[found], values[found] = a, b, value
                counts[a + 1] += 1
                counts[b + 1] += 1
                found += 1
    starts = np.cumsum(counts)
    filled = starts[:-1].copy()
    out_columns, out_values = np.empty(2 * found, dtype=np.int64), np.empty(2 * found)
    # in the order found, row r receives its columns below r (as the second of a pair) before those above it
    for k in range(found):
        a, b = rows[k], columns[k]
        out_columns[filled[a]], out_values[filled[a]] = b, values[k]
        filled[a] += 1
        out_columns[filled[b]], out_values[filled[b]] = a, values[k]
        filled[b] += 1
    return starts, out_columns, out_values


@njit(cache=True)
def compressed(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A dense matrix as compressed rows (starts, columns, values) of its non-zero entries."""
    n = matrix.shape[0]
    starts = np.zeros(n + 1, dtype=np.int64)
    columns = np.empty(n * n, dtype=np.int64)
    values = np.empty(n * n)
    count = 0
    for i in range(n):
        for j in range(n):
            if matrix[i, j] != 0.0:
                columns[count], values[count] = j, matrix[i, j]
                count += 1
        starts[i + 1] = count
    return starts, columns[:count], values[:count]


@njit(cache=True)
def block(starts: np.ndarray, columns: np.ndarray, values: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """The dense (k, k) block of a compressed matrix at rows and columns `indices`."""
    k = len(indices)
    out = np.zeros((k, k))
    for x in range(k):
        row = columns[starts[indices[x]] : starts[indices[x] + 1]]
        for y in range(k):
            at = np.searchsorted(row, indices[y])
            if at < len(row) and row[at] == indices[y]:
                out[x, y] = values[starts[indices[x]] + at]
    return out


@njit(cache=True)
def principal_eigenvector(
    starts: np.ndarray, columns: np.ndarray, values: np.ndarray, iterations: int, tolerance: float
) -> np.ndarray:
    """Power iteration on M + I (M as compressed rows) from the uniform unit vector (see
    loop.matching.principal_eigenvector)."""
    n = len(starts) - 1
    if len(values) == 0:  # no pair of assignments agrees: nothing to rank
        return np.zeros(n)
    vector = np.full(n, 1.0 / math.sqrt(n))
    product = np.empty(n)
    for _ in range(iterations):
        squares = 0.0
        for i in range(n):
            total = 0.0
            for entry in range(starts[i], starts[i + 1]):
                total += values[entry] * vector[columns[entry]]
            total += vector[i]
            product[i] = total
            squares += total * total
        norm = math.sqrt(squares)  # never 0: (M + I) v >= v for the non-negative v
        change = 0.0
        for i in range(n):
            product[i] /= norm
            change = max(change, abs(product[i] - vector[i]))
        if change < tolerance:
            return product
        vector, product = product, vector
    return vector


@njit(cache=True)
def greedy_assignment(
    weight: np.ndarray, query_objects: np.ndarray, stored_objects: np.ndarray, n_query: int, n_stored: int
) -> np.ndarray:
    """Indices of the assignments taken best weight first (a stable order), each skipped when its query or stored
    object is already used, until the weights reach 0 or one side's objects among the candidates are used up."""
    seen_query = np.zeros(n_query, dtype=np.bool_)
    seen_stored = np.zeros(n_stored, dtype=np.bool_)
    for a in range(len(weight)):
        seen_query[query_objects[a]] = True
        seen_stored[stored_objects[a]] = True
    most = min(np.count_nonzero(seen_query), np.count_nonzero(seen_stored))
    used_query = np.zeros(n_query, dtype=np.bool_)
    used_stored = np.zeros(n_stored, dtype=np.bool_)
    chosen = np.empty(most, dtype=np.int64)
    taken = 0
    for a in np.argsort(-weight, kind="mergesort"):
        if weight[a] <= 0.0 or taken == most:
            break
        i, p = query_objects[a], stored_objects[a]
        if used_query[i] or used_stored[p]:
            continue
        chosen[taken] = a
        taken += 1
        used_query[i], used_stored[p] = True, True
    return chosen[:taken]


@njit(cache=True)
def supported(matrix: np.ndarray, chosen: np.ndarray, min_support: int) -> np.ndarray:
    """The chosen assignments left once those with fewer than `min_support` consistent partners (M > 0) among the
    others are dropped, repeatedly until none is."""
    keep = chosen.copy()
    while len(keep):
        support = np.zeros(len(keep), dtype=np.int64)
        for x in range(len(keep)):
            for y in range(len(keep)):
                if matrix[keep[x], keep[y]] > 0.0:
                    support[x] += 1
        enough = support >= min_support
        if enough.all():
            break
        keep = keep[enough]
    return keep


@njit(cache=True)
def group_sum(matrix: np.ndarray, indices: np.ndarray) -> float:
    """Σ of matrix[a, b] over a, b in `indices`."""
    total = 0.0
    for a in indices:
        for b in indices:
            total += matrix[a, b]
    return total


@njit(cache=True)
def merged_objects(centres: np.ndarray, codes: np.ndarray, order: np.ndarray, radius: float) -> np.ndarray:
    """Objects taken in `order`: each joins the nearest object of its label code kept before it within `radius`
    (ground plane; the lowest index of equally near ones), else is kept. Per object, the one it joined, or -1 for
    one kept; the kept ones are those, in `order`."""
    n = len(centres)
    standing = np.zeros(n, dtype=np.bool_)
    joined = np.full(n, -1, dtype=np.int64)
    for i in order:
        nearest, nearest_distance = -1, 0.0
        for j in range(n):
            if not standing[j] or codes[j] != codes[i]:
                continue
            dx, dy = centres[i, 0] - centres[j, 0], centres[i, 1] - centres[j, 1]
            distance = math.sqrt(dx * dx + dy * dy)
            if distance <= radius and (nearest < 0 or distance < nearest_distance):
                nearest, nearest_distance = j, distance
        if nearest >= 0:
            joined[i] = nearest
        else:
            standing[i] = True
    return joined


@njit(cache=True)
def kept_objects(
    centres: np.ndarray, codes: np.ndarray, order: np.ndarray, radius: float, provisional: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The objects kept by merged_objects, in `order`, and whether each is provisional: only when it and every object
    that joined it are."""
    joined = merged_objects(centres, codes, order, radius)
    known = ~provisional
    for i in range(len(joined)):
        if joined[i] >= 0 and not provisional[i]:
            known[joined[i]] = True
    keep = np.array([i for i in order if joined[i] < 0], dtype=np.int64)
    return keep, ~known[keep]
