"""Traffic: the objects of a simulated street that move, following the route's centre line.

Cars, trucks and bicycles drive on the road in a lane beside the centre line, on the side of their direction of
travel (`WorldConfig.drive_on`), some the way the route was driven and some against it; people walk along the kerb
at the offset where they were placed. Every mover goes along the line at its own speed and turns round at the ends
of the route (back and forth along the arc), so it stays on the streets however long the drive lasts. A vehicle
turning round crosses to the other lane over `turn_length` metres of the line (no jump across the road).

The line is kept as points and unit vectors (along it, to its left, up), which a rigid transform moves exactly, so
the traffic of a world seen from another frame (`World.moved`) is the same traffic there.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from neoslam.config import WorldConfig

__all__ = ["IN_LANE", "Traffic", "build_traffic"]

IN_LANE = frozenset({"car", "truck", "bicycle"})  # drive on the road; every other class walks along its kerb
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Traffic:
    """Moving objects (rows k) on a line of samples (rows m), arc-length parametrised."""

    ids: np.ndarray  # (k,) int: the world's index of each moving object
    start: np.ndarray  # (k,) place along the line at time 0, m of arc
    speed: np.ndarray  # (k,) signed speed along the line, m/s; > 0 the way the route was driven
    offset: np.ndarray  # (k,) lateral offset, m, left positive; of a lane object: while it travels along the line
    in_lane: np.ndarray  # (k,) bool: keeps to the side of its direction of travel (vehicles), else to its kerb
    lift: np.ndarray  # (k,) height of the object's centre above the road, m
    arc: np.ndarray  # (m,) arc length of each line sample from the first, m, increasing
    points: np.ndarray  # (m, 3) the line on the road surface
    along: np.ndarray  # (m, 3) unit direction of the line (horizontal in the frame it was built in)
    left: np.ndarray  # (m, 3) unit vector to the line's left (horizontal in that frame)
    up: np.ndarray  # (3,) the objects' up: world z in the frame it was built in
    turn_length: float  # m of line over which a vehicle turning round at an end changes lanes

    def __len__(self) -> int:
        return len(self.ids)

    def positions_at(self, time: float) -> np.ndarray:
        """(k, 3) centres of the moving objects at `time`."""
        place, _, side = self._fold(time)
        lateral = np.where(self.in_lane, self.offset * side, self.offset)
        left = _unit(self._on_line(self.left, place))
        return self._on_line(self.points, place) + lateral[:, None] * left + self.lift[:, None] * self.up

    def yaws_at(self, time: float) -> np.ndarray:
        """(k,) heading of each object's length axis at `time`: the line's, turned round when it travels back."""
        place, direction, _ = self._fold(time)
        heading = self._on_line(self.along, place) * direction[:, None]
        return np.arctan2(heading[:, 1], heading[:, 0])

    def velocities_at(self, time: float) -> np.ndarray:
        """(k, 3) velocity along the line at `time`, m/s (the lane change at a turn left out)."""
        place, direction, _ = self._fold(time)
        return _unit(self._on_line(self.along, place)) * (np.abs(self.speed) * direction)[:, None]

    def moved(self, rotation: np.ndarray, translation: np.ndarray) -> Traffic:
        """The same traffic seen from another frame: x' = R x + t."""
        return replace(
            self,
            points=self.points @ rotation.T + translation,
            along=self.along @ rotation.T,
            left=self.left @ rotation.T,
            up=rotation @ self.up,
        )

    def _fold(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per object: place along the line (m of arc), direction of travel (+1 along the line, -1 against) and
        side factor (the direction, eased to 0 within half a turn length of an end, where a vehicle turns round)."""
        length = self.arc[-1]
        # Back and forth along [0, length] is a walk round a loop of twice the length, folded in two.
        lap = np.mod(self.start + self.speed * time, 2.0 * length)
        outward = lap < length
        place = np.where(outward, lap, 2.0 * length - lap)
        direction = np.where(outward, 1.0, -1.0) * np.where(self.speed < 0, -1.0, 1.0)
        to_end = np.minimum(place, length - place)
        side = direction * np.sin(np.pi / 2 * np.minimum(to_end / (self.turn_length / 2), 1.0))
        return place, direction, side

    def _on_line(self, values: np.ndarray, place: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(place, self.arc, values[:, k]) for k in range(values.shape[1])])


def _unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=1, keepdims=True)


def _speed_range(label: str, config: WorldConfig) -> tuple[float, float]:
    if label == "bicycle":
        return config.bicycle_speed
    return config.vehicle_speed if label in IN_LANE else config.walking_speed


def build_traffic(
    ids: np.ndarray,
    labels: np.ndarray,
    xy: np.ndarray,
    lift: np.ndarray,
    backwards: np.ndarray,
    line_arc: np.ndarray,
    line_points: np.ndarray,
    line_heading: np.ndarray,
    config: WorldConfig,
    rng: np.random.Generator,
) -> Traffic:
    """The traffic of the world's objects `ids` (their `labels`, placed at `xy`, centres `lift` above the road):
    each starts level with the line sample nearest to where it was placed and goes along the line (against it where
    `backwards`) at a speed drawn from its class's range. Vehicles move into their lane; people keep their offset."""
    heading = np.asarray(line_heading, dtype=float)
    along = np.column_stack([np.cos(heading), np.sin(heading), np.zeros(len(heading))])
    left = np.column_stack([-np.sin(heading), np.cos(heading), np.zeros(len(heading))])
    _, nearest = cKDTree(line_points[:, :2]).query(np.asarray(xy, dtype=float).reshape(-1, 2))
    nearest = np.asarray(nearest, dtype=int).reshape(-1)
    beside = ((xy - line_points[nearest, :2]) * left[nearest, :2]).sum(axis=1).reshape(-1)
    in_lane = np.isin(labels, sorted(IN_LANE))
    lane_side = -1.0 if config.drive_on == "right" else 1.0  # left positive, while travelling along the line
    ranges = np.array([_speed_range(str(label), config) for label in labels]).reshape(-1, 2)
    speed = ranges[:, 0] + (ranges[:, 1] - ranges[:, 0]) * rng.random(len(labels))
    return Traffic(
        ids=np.asarray(ids, dtype=int).reshape(-1),
        start=np.asarray(line_arc, dtype=float)[nearest],
        speed=np.where(backwards, -speed, speed),
        offset=np.where(in_lane, lane_side * config.lane_offset, beside),
        in_lane=in_lane,
        lift=np.asarray(lift, dtype=float).reshape(-1),
        arc=np.asarray(line_arc, dtype=float),
        points=np.asarray(line_points, dtype=float),
        along=along,
        left=left,
        up=UP.copy(),
        turn_length=config.turn_length,
    )
