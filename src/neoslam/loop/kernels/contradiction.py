"""Compiled loops of the contradiction test: objects one side holds where the other has none (loop.verification)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["counterparts", "ground", "in_view", "missed_objects"]


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
        for j in range(len(others)):
            if codes[i] != other_codes[j]:
                continue
            dx, dy = points[i, 0] - others[j, 0], points[i, 1] - others[j, 1]
            if math.sqrt(dx * dx + dy * dy) <= radius:
                found[i] = True
                break
            if covariance:
                a = covariances[i, 0, 0] + other_covariances[j, 0, 0] + floor
                b = covariances[i, 0, 1] + other_covariances[j, 0, 1]
                d = covariances[i, 1, 1] + other_covariances[j, 1, 1] + floor
                if (d * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / (a * d - b * b) <= gate:
                    found[i] = True
                    break
    return found


@njit(cache=True)
def ground(centres: np.ndarray, robot: np.ndarray) -> tuple[float, float, float]:
    """Centre (x, y) and radius of the ground a keyframe covers: its object nearest the robot (the first of equally
    near ones) and the farthest of its objects from that one; a keyframe without objects covers none (radius -inf,
    at the robot)."""
    if len(centres) == 0:
        return robot[0], robot[1], -math.inf
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


@njit(cache=True)
def _missed(side: tuple, other: tuple, other_ground: tuple, margin: float, tolerances: tuple) -> np.ndarray:
    points, codes, covariances, known, _ = side
    others, other_codes, other_covariances, _, _ = other
    x, y, reach = other_ground
    inside = np.zeros(len(points), dtype=np.bool_)
    for i in range(len(points)):
        dx, dy = points[i, 0] - x, points[i, 1] - y
        inside[i] = known[i] and math.sqrt(dx * dx + dy * dy) <= reach - margin
    chosen = np.flatnonzero(inside)
    radius, gate, floor, covariance = tolerances
    found = counterparts(
        points[chosen], codes[chosen], covariances[chosen], others, other_codes, other_covariances, radius, gate,
        floor, covariance,
    )  # fmt: skip
    for k in range(len(chosen)):
        inside[chosen[k]] = not found[k]
    return inside


@njit(cache=True)
def missed_objects(side: tuple, other: tuple, margin: float, tolerances: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Bool per object of either side, a side being (ground points (n, 2), label codes, ground covariances, known to
    be static, robot position (2,)), both in one frame: known, at least `margin` inside the other side's ground
    (`ground`, from the other's robot) and without a counterpart among the other side's objects (`counterparts`
    with `tolerances`: radius, gate, floor, covariance)."""
    here = _missed(side, other, ground(other[0], other[4]), margin, tolerances)
    there = _missed(other, side, ground(side[0], side[4]), margin, tolerances)
    return here, there
