"""Built-in routes: street polylines driven at town speeds, with height, sampled at the camera's frame rate.

`town` is the default scenario (about 2.4 km, several loops, one street pair driven in the opposite direction, a
hill, and a stretch whose object layout repeats another's). `block` is a short loop for quick tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.types import Trajectory

__all__ = ["RepeatedLayout", "Route", "ROUTES", "route_names", "drive_route"]

CRUISE_SPEED = 8.0  # m/s, about 29 km/h in town
MIN_SPEED = 2.0  # m/s at the start
MAX_LATERAL_ACCELERATION = 2.0  # m/s^2, sets the speed in corners
MAX_ACCELERATION = 1.5  # m/s^2, forward and braking
CORNER_RADIUS = 12.0  # m, fillet of every turn
SAMPLE_STEP = 0.1  # m, resolution of the dense centre line
MAX_TURN = np.radians(150.0)  # sharper corners would need a U-turn manoeuvre


@dataclass(frozen=True)
class RepeatedLayout:
    """Objects beside [start, start + length) along `source_heading` from `source_start` are copied, in the same
    layout relative to the road, to the stretch starting at `target_start` along `target_heading`."""

    source_start: tuple[float, float]
    source_heading: float
    target_start: tuple[float, float]
    target_heading: float
    length: float


@dataclass(frozen=True)
class Route:
    """A built-in route: corner points of the streets in driving order and a smooth height field."""

    name: str
    description: str
    corners: tuple[tuple[float, float], ...]
    hill_height: float = 0.0  # m, amplitude of the Gaussian hill
    hill_center: tuple[float, float] = (0.0, 0.0)
    hill_width: float = 100.0  # m, σ of the hill
    repeats: tuple[RepeatedLayout, ...] = field(default_factory=tuple)

    def ground_height(self, xy: np.ndarray) -> np.ndarray:
        """Height of the road surface at (n, 2) points, so every pass over a street sees the same height."""
        offset = (xy - np.asarray(self.hill_center)) / self.hill_width
        return self.hill_height * np.exp(-0.5 * (offset**2).sum(axis=-1))


ROUTES: dict[str, Route] = {
    "town": Route(
        name="town",
        description="2.4 km town drive: a block loop, two of its streets again in the opposite direction, a hill, "
        "two streets again in the same direction, and a stretch whose parked objects repeat another's layout",
        corners=(
            (0, 0),
            (240, 0),
            (240, 120),
            (0, 120),
            (0, 0),  # loop 1, counter-clockwise
            (0, -120),
            (120, -120),
            (120, 0),  # round the block to the south
            (0, 0),
            (0, 120),
            (120, 120),  # three streets of loop 1 driven the other way
            (120, 240),
            (360, 240),
            (360, 0),
            (240, 0),  # over the hill
            (240, 120),
            (120, 120),  # two streets of loop 1 again, same direction
        ),  # fmt: skip
        hill_height=12.0,
        hill_center=(300.0, 200.0),
        hill_width=70.0,
        repeats=(RepeatedLayout((10.0, -120.0), 0.0, (140.0, 240.0), 0.0, 100.0),),
    ),
    "block": Route(
        name="block",
        description="a 120 m x 80 m block driven once and a half (about 600 m)",
        corners=((0, 0), (120, 0), (120, 80), (0, 80), (0, 0), (120, 0), (120, 80)),
        hill_height=3.0,
        hill_center=(120.0, 80.0),
        hill_width=40.0,
    ),
}


def route_names() -> list[str]:
    return sorted(ROUTES)


def _centre_line(corners: np.ndarray) -> np.ndarray:
    """Dense (n, 2) polyline through the corners with circular fillets of CORNER_RADIUS at every turn."""
    points = [corners[0]]
    for previous, corner, following in zip(corners[:-2], corners[1:-1], corners[2:], strict=True):
        incoming = (corner - previous) / np.linalg.norm(corner - previous)
        outgoing = (following - corner) / np.linalg.norm(following - corner)
        turn = np.arctan2(incoming[0] * outgoing[1] - incoming[1] * outgoing[0], incoming @ outgoing)
        if abs(turn) > MAX_TURN:
            raise ValueError(f"route turns by {np.degrees(turn):.0f} degrees at {corner}: no U-turns")
        if abs(turn) < 1e-6:
            points.append(corner)
            continue
        cut = CORNER_RADIUS * np.tan(abs(turn) / 2)
        start = corner - incoming * cut
        normal = np.array([-incoming[1], incoming[0]]) * np.sign(turn)
        centre = start + normal * CORNER_RADIUS
        angles = np.linspace(0, turn, max(int(abs(turn) * CORNER_RADIUS / SAMPLE_STEP), 2))
        start_angle = np.arctan2(*(start - centre)[::-1])
        arc = centre + CORNER_RADIUS * np.stack([np.cos(start_angle + angles), np.sin(start_angle + angles)], 1)
        points.extend(arc)
    points.append(corners[-1])
    return _resample(np.asarray(points, dtype=float), SAMPLE_STEP)


def _resample(polyline: np.ndarray, step: float) -> np.ndarray:
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(arc) > 1e-9])
    polyline, arc = polyline[keep], arc[keep]
    samples = np.arange(0.0, arc[-1], step)
    return np.stack([np.interp(samples, arc, polyline[:, k]) for k in range(polyline.shape[1])], axis=1)


def _speed_profile(xy: np.ndarray) -> np.ndarray:
    """Speed at each centre-line sample: cruise, slower in corners, with bounded acceleration."""
    heading = np.unwrap(np.arctan2(*np.gradient(xy, axis=0).T[::-1]))
    curvature = np.abs(np.gradient(heading)) / SAMPLE_STEP
    speed = np.minimum(CRUISE_SPEED, np.sqrt(MAX_LATERAL_ACCELERATION / np.maximum(curvature, 1e-9)))
    speed[0] = MIN_SPEED
    for i in range(1, len(speed)):  # accelerate no faster than MAX_ACCELERATION
        speed[i] = min(speed[i], np.sqrt(speed[i - 1] ** 2 + 2 * MAX_ACCELERATION * SAMPLE_STEP))
    for i in range(len(speed) - 2, -1, -1):  # brake in time for the next corner
        speed[i] = min(speed[i], np.sqrt(speed[i + 1] ** 2 + 2 * MAX_ACCELERATION * SAMPLE_STEP))
    return np.maximum(speed, MIN_SPEED)


def drive_route(route: Route, frame_period: float, camera_height: float) -> Trajectory:
    """True robot poses (camera centre, REP-103) every frame_period seconds along the route."""
    xy = _centre_line(np.asarray(route.corners, dtype=float))
    speed = _speed_profile(xy)
    arc = np.arange(len(xy)) * SAMPLE_STEP
    time = np.concatenate([[0.0], np.cumsum(SAMPLE_STEP / (0.5 * (speed[1:] + speed[:-1])))])
    stamps = np.arange(0.0, time[-1], frame_period)
    s = np.interp(stamps, time, arc)
    position = np.stack([np.interp(s, arc, xy[:, 0]), np.interp(s, arc, xy[:, 1])], axis=1)
    ground = route.ground_height(position)
    ahead = np.stack([np.interp(s + 1.0, arc, xy[:, 0]), np.interp(s + 1.0, arc, xy[:, 1])], axis=1)
    yaw = np.arctan2(*(ahead - position).T[::-1])
    slope = (route.ground_height(ahead) - ground) / np.maximum(np.linalg.norm(ahead - position, axis=1), 1e-9)
    poses = np.tile(np.eye(4), (len(stamps), 1, 1))
    # REP-103: a positive pitch turns the nose down, so climbing is a negative pitch.
    poses[:, :3, :3] = Rotation.from_euler("ZYX", np.stack([yaw, -np.arctan(slope), 0 * yaw], 1)).as_matrix()
    poses[:, :3, 3] = np.column_stack([position, ground + camera_height])
    return Trajectory(stamps, poses)
