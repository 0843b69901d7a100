"""Compiled loops of the contradiction test: objects one side holds where the other has none (loop.verification)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["counterparts", "ground", "missed", "in_view"]


@njit(cache=True)
def _has_counterpart(
    point: np.ndarray,
    code: int,
    cov: np.ndarray,
    others: np.ndarray,
    other_codes: np.ndarray,
    other_covariances: np.ndarray,
    radius: float,
    gate: float,
    floor: float,
    covariance: bool,
) -> bool:
    for j in range(len(others)):
        if code != other_codes[j]:
            continue
        dx, dy = point[0] - others[j, 0], point[1] - others[j, 1]
        if math.sqrt(dx * dx + dy * dy) <= radius:
            return True
        if covariance:
            a = cov[0, 0] + other_covariances[j, 0, 0] + floor
            b = cov[0, 1] + other_covariances[j, 0, 1]
            d = cov[1, 1] + other_covariances[j, 1, 1] + floor
            if (d * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / (a * d - b * b) <= gate:
                return True
    return False


@njit(cache=True)
def counterparts(
    points: np.ndarray,
    codes: np.ndarray,
    covariances: np.ndarray,
    others: np.ndarray,
    other_codes: np.ndarray,
    other_covariances: np.ndarray,
    radius: float,
    gate: float,
    floor: float,
    covariance: bool,
) -> np.ndarray:
    """Bool per point (ground x, y): an other of the same label code within `radius`, or (with `covariance`) within
    the d² `gate` of the two centres' ground covariances plus `floor` on the diagonal."""
    found = np.zeros(len(points), dtype=np.bool_)
    for i in range(len(points)):
        found[i] = _has_counterpart(
            points[i], codes[i], covariances[i], others, other_codes, other_covariances, radius, gate, floor,
            covariance,
        )  # fmt: skip
    return found


@njit(cache=True)
def ground(centres: np.ndarray, robot: np.ndarray) -> tuple[float, float, float]:
    """Centre (x, y) and radius of the ground a keyframe covers: its object nearest the robot (the first of equally
    near ones) and the farthest of its objects from that one."""
    nearest, nearest_distance = 0, math.inf
    for i in range(len(centres)):
        distance = math.sqrt((centres[i, 0] - robot[0]) ** 2 + (centres[i, 1] - robot[1]) ** 2)
        if distance < nearest_distance:
            nearest, nearest_distance = i, distance
    x, y = centres[nearest, 0], centres[nearest, 1]
    farthest = 0.0
    for i in range(len(centres)):
        farthest = max(farthest, math.sqrt((centres[i, 0] - x) ** 2 + (centres[i, 1] - y) ** 2))
    return x, y, farthest


@njit(cache=True)
def missed(
    points: np.ndarray,
    codes: np.ndarray,
    covariances: np.ndarray,
    known: np.ndarray,
    other_ground: tuple[float, float, float],
    margin: float,
    others: np.ndarray,
    other_codes: np.ndarray,
    other_covariances: np.ndarray,
    radius: float,
    gate: float,
    floor: float,
    covariance: bool,
) -> np.ndarray:
    """Bool per point: known, at least `margin` inside the other keyframe's ground (x, y, radius) and with no
    counterpart among the others (counterparts)."""
    x, y, extent = other_ground
    out = np.zeros(len(points), dtype=np.bool_)
    for i in range(len(points)):
        if not known[i] or math.sqrt((points[i, 0] - x) ** 2 + (points[i, 1] - y) ** 2) > extent - margin:
            continue
        out[i] = not _has_counterpart(
            points[i], codes[i], covariances[i], others, other_codes, other_covariances, radius, gate, floor,
            covariance,
        )  # fmt: skip
    return out


@njit(cache=True)
def in_view(points: np.ndarray, views: np.ndarray, half_angle: float) -> np.ndarray:
    """Bool per ground point (x, y): within `half_angle` (rad) of the heading of one of the views (x, y, yaw), seen
    from its position."""
    seen = np.zeros(len(points), dtype=np.bool_)
    for i in range(len(points)):
        for v in range(len(views)):
            bearing = math.atan2(points[i, 1] - views[v, 1], points[i, 0] - views[v, 0]) - views[v, 2]
            if abs((bearing + math.pi) % (2.0 * math.pi) - math.pi) <= half_angle:
                seen[i] = True
                break
    return seen
