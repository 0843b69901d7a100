"""Compiled loops of the weighted fit of matched centres, its trimming and its evidence (loop.verification).

A fit's pairs are the columns of one (k, 11) array (pair_columns): query x, y; stored x, y; height offset; the query
centre's ground covariance (a, b, d: [[a, b], [b, d]]); the stored centre's plus both centres' floor.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["pair_covariances", "pair_columns", "fit_pairs", "trimmed", "pair_bits"]

_QX, _QY, _SX, _SY, _DZ, _QA, _QB, _QD, _SA, _SB, _SD = range(11)
_STEP_TOLERANCE = 1e-9  # a Gauss-Newton step smaller than this (rad, m) has converged


@njit(cache=True)
def _solve3(h: np.ndarray, g: np.ndarray) -> tuple[bool, np.ndarray]:
    """x with h x = g for a 3 x 3 h, by elimination with partial pivoting; False when a pivot is 0 (singular)."""
    a = h.copy()
    b = g.copy()
    for k in range(3):
        pivot = k
        for r in range(k + 1, 3):
            if abs(a[r, k]) > abs(a[pivot, k]):
                pivot = r
        if a[pivot, k] == 0.0:
            return False, b
        if pivot != k:
            for col in range(3):
                a[k, col], a[pivot, col] = a[pivot, col], a[k, col]
            b[k], b[pivot] = b[pivot], b[k]
        for r in range(k + 1, 3):
            factor = a[r, k] / a[k, k]
            for col in range(k, 3):
                a[r, col] -= factor * a[k, col]
            b[r] -= factor * b[k]
    x = np.empty(3)
    for k in range(2, -1, -1):
        total = b[k]
        for col in range(k + 1, 3):
            total -= a[k, col] * x[col]
        x[k] = total / a[k, k]
    return True, x


@njit(cache=True)
def _pair_covariance(
    qa: float, qb: float, qd: float, sa: float, sb: float, sd: float, c: float, s: float
) -> tuple[float, float, float]:
    """Components (a, b, d) of C = R Σ_q Rᵀ + Σ_s, R turned by (cos, sin), from those of Σ_q and Σ_s."""
    a = c * c * qa - 2.0 * c * s * qb + s * s * qd + sa
    d = s * s * qa + 2.0 * c * s * qb + c * c * qd + sd
    b = c * s * (qa - qd) + (c * c - s * s) * qb + sb
    return a, b, d


@njit(cache=True)
def pair_covariances(
    query_covariances: np.ndarray, stored_covariances: np.ndarray, yaw: float, floor: float
) -> np.ndarray:
    """(k, 2, 2) covariance of each pair's residual: the query centre's turned by `yaw`, plus the stored centre's,
    plus `floor` on the diagonal."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty((len(query_covariances), 2, 2))
    for p in range(len(query_covariances)):
        q, t = query_covariances[p], stored_covariances[p]
        a, b, d = _pair_covariance(q[0, 0], q[0, 1], q[1, 1], t[0, 0] + floor, t[0, 1], t[1, 1] + floor, c, s)
        out[p, 0, 0], out[p, 0, 1], out[p, 1, 0], out[p, 1, 1] = a, b, b, d
    return out


@njit(cache=True)
def _information(pairs: np.ndarray, k: int, c: float, s: float) -> tuple[float, float, float]:
    """Components (a, b, d) of pair k's information C⁻¹, C = R Σ_q Rᵀ + Σ_s + floor, R turned by (cos, sin)."""
    a, b, d = _pair_covariance(
        pairs[k, _QA], pairs[k, _QB], pairs[k, _QD], pairs[k, _SA], pairs[k, _SB], pairs[k, _SD], c, s
    )
    determinant = a * d - b * b
    return d / determinant, -b / determinant, a / determinant


@njit(cache=True)
def _unweighted_start(pairs: np.ndarray) -> tuple[float, float, float]:
    """Yaw and translation (x, y) of the plain least-squares fit (geometry.least_squares_yaw, ground plane)."""
    n = len(pairs)
    mqx, mqy = pairs[:, _QX].sum() / n, pairs[:, _QY].sum() / n
    msx, msy = pairs[:, _SX].sum() / n, pairs[:, _SY].sum() / n
    cross, dot = 0.0, 0.0
    for k in range(n):
        qx, qy = pairs[k, _QX] - mqx, pairs[k, _QY] - mqy
        sx, sy = pairs[k, _SX] - msx, pairs[k, _SY] - msy
        cross += qx * sy - qy * sx
        dot += qx * sx + qy * sy
    yaw = math.atan2(cross, dot)
    c, s = math.cos(yaw), math.sin(yaw)
    return yaw, msx - (c * mqx - s * mqy), msy - (s * mqx + c * mqy)


@njit(cache=True)
def pair_columns(
    query: np.ndarray, stored: np.ndarray, query_covariances: np.ndarray, stored_covariances: np.ndarray, floor: float
) -> np.ndarray:
    """The (k, 11) columns of a fit's pairs (above) from the paired centres (k, 3) and ground covariances (k, 2, 2),
    `floor` added to the stored covariance's diagonal."""
    out = np.empty((len(query), 11))
    for k in range(len(query)):
        out[k, _QX], out[k, _QY] = query[k, 0], query[k, 1]
        out[k, _SX], out[k, _SY] = stored[k, 0], stored[k, 1]
        out[k, _DZ] = stored[k, 2] - query[k, 2]
        out[k, _QA], out[k, _QB], out[k, _QD] = (
            query_covariances[k, 0, 0],
            query_covariances[k, 0, 1],
            query_covariances[k, 1, 1],
        )
        out[k, _SA] = stored_covariances[k, 0, 0] + floor
        out[k, _SB] = stored_covariances[k, 0, 1]
        out[k, _SD] = stored_covariances[k, 1, 1] + floor
    return out


@njit(cache=True)
def fit_pairs(pairs: np.ndarray, steps: int) -> tuple[float, float, float, float, np.ndarray, np.ndarray]:
    """Yaw, translation (x, y, z) minimising Σ d² of the pairs (columns as above), by at most `steps` Gauss-Newton
    steps from the unweighted fit, the height offset the mean one; with each pair's d² and residual length (m)."""
    yaw, tx, ty = _unweighted_start(pairs)
    hessian = np.empty((3, 3))
    gradient = np.empty(3)
    for _ in range(steps):
        c, s = math.cos(yaw), math.sin(yaw)
        sums = np.zeros(9)
        for k in range(len(pairs)):
            wa, wb, wd = _information(pairs, k, c, s)
            qx, qy = pairs[k, _QX], pairs[k, _QY]
            rx = c * qx - s * qy + tx - pairs[k, _SX]
            ry = s * qx + c * qy + ty - pairs[k, _SY]
            jx, jy = -s * qx - c * qy, c * qx - s * qy  # ∂r/∂yaw; ∂r/∂translation is I
            ux, uy = wa * jx + wb * jy, wb * jx + wd * jy  # W J, yaw's column
            sums[0] += jx * ux + jy * uy
            sums[1] += ux
            sums[2] += uy
            sums[3] += wa
            sums[4] += wb
            sums[5] += wd
            sums[6] += ux * rx + uy * ry
            sums[7] += wa * rx + wb * ry
            sums[8] += wb * rx + wd * ry
        hessian[0, 0], hessian[0, 1], hessian[0, 2] = sums[0], sums[1], sums[2]  # Jᵀ W J
        hessian[1, 0], hessian[1, 1], hessian[1, 2] = sums[1], sums[3], sums[4]
        hessian[2, 0], hessian[2, 1], hessian[2, 2] = sums[2], sums[4], sums[5]
        gradient[0], gradient[1], gradient[2] = sums[6], sums[7], sums[8]  # Jᵀ W r
        solved, step = _solve3(hessian, gradient)
        if not solved:
            break  # degenerate geometry: keep the current fit
        yaw -= step[0]
        tx, ty = tx - step[1], ty - step[2]
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < _STEP_TOLERANCE:
            break
    c, s = math.cos(yaw), math.sin(yaw)
    d2 = np.empty(len(pairs))
    distances = np.empty(len(pairs))
    for k in range(len(pairs)):
        qx, qy = pairs[k, _QX], pairs[k, _QY]
        rx = c * qx - s * qy + tx - pairs[k, _SX]
        ry = s * qx + c * qy + ty - pairs[k, _SY]
        wa, wb, wd = _information(pairs, k, c, s)
        d2[k] = wa * rx * rx + 2.0 * wb * rx * ry + wd * ry * ry
        distances[k] = math.sqrt(rx * rx + ry * ry)
    return yaw, tx, ty, pairs[:, _DZ].sum() / len(pairs), d2, distances


@njit(cache=True)
def trimmed(
    pairs: np.ndarray, steps: int, needed: float, gate: float, max_distance: float, distance_only: bool
) -> tuple[bool, float, float, float, float, np.ndarray, np.ndarray, np.ndarray]:
    """fit_pairs, trimmed: drop the pair that exceeds its bound most and refit until every pair is within its d²
    `gate` and `max_distance` (with `distance_only`, within `max_distance` alone), giving up (False) once fewer than
    `needed` pairs (and 2) are left. With the last fit and the inlier mask."""
    inliers = np.ones(len(pairs), dtype=np.bool_)
    left = len(pairs)
    yaw, tx, ty, tz = 0.0, 0.0, 0.0, 0.0
    d2 = np.empty(0)
    distances = np.empty(0)
    while left >= max(needed, 2.0):
        yaw, tx, ty, tz, d2, distances = fit_pairs(pairs[inliers], steps)
        worst, most = 0, -1.0
        for k in range(len(d2)):
            excess = distances[k] / max_distance
            if not distance_only:
                excess = max(d2[k] / gate, excess)
            if excess > most:
                worst, most = k, excess
        if most <= 1.0:
            return True, yaw, tx, ty, tz, d2, distances, inliers
        inliers[np.flatnonzero(inliers)[worst]] = False
        left -= 1
    return False, yaw, tx, ty, tz, d2, distances, inliers


@njit(cache=True)
def pair_bits(
    query_covariances: np.ndarray,
    stored_covariances: np.ndarray,
    yaw: float,
    floor: float,
    d2: np.ndarray,
    label_shares: np.ndarray,
    object_area: float,
) -> tuple[np.ndarray, float]:
    """Each fitted pair's bits, log2(N(r; 0, C) · object_area / label share) and at least 0, C its residual's
    covariance (the query centre's turned by `yaw`, the stored one's, `floor` on the diagonal) and d² = rᵀ C⁻¹ r;
    with the position bits spent fixing the fit: the best pair's and half the next one's."""
    c, s = math.cos(yaw), math.sin(yaw)
    k = len(d2)
    bits = np.empty(k)
    spent = np.empty(k)
    for p in range(k):
        q, t = query_covariances[p], stored_covariances[p]
        a, b, d = _pair_covariance(q[0, 0], q[0, 1], q[1, 1], t[0, 0] + floor, t[0, 1], t[1, 1] + floor, c, s)
        likelihood = math.exp(-0.5 * d2[p]) / (2.0 * math.pi * math.sqrt(a * d - b * b))
        place = math.log2(likelihood * object_area)
        bits[p] = max(place - math.log2(label_shares[p]), 0.0)
        spent[p] = min(max(place, 0.0), bits[p])
    spent = np.sort(spent)[::-1]
    return bits, (spent[0] + 0.5 * spent[1] if k > 1 else spent.sum())
