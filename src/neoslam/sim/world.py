"""A world of objects placed along a route the way a street holds them: parked cars on both sides, some trucks,
bicycles and people at the kerb, optionally a share that moves: traffic along the road (neoslam.sim.traffic)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from neoslam.config import DetectionNoiseConfig, WorldConfig
from neoslam.sim.routes import RepeatedLayout
from neoslam.sim.traffic import Traffic, build_traffic
from neoslam.types import Trajectory

__all__ = ["CLASS_SIZES", "World", "build_world"]

# Length, width, height of each class, metres (typical street objects).
CLASS_SIZES: dict[str, tuple[float, float, float]] = {
    "car": (4.3, 1.8, 1.5),
    "truck": (8.0, 2.5, 3.2),
    "bicycle": (1.8, 0.6, 1.1),
    "person": (0.6, 0.6, 1.75),
}
KERB_EXTRA = {"car": 0.0, "truck": 0.3, "bicycle": 1.5, "person": 2.0}  # m further out than parked cars
REPEAT_HALF_WIDTH = 12.0  # m: objects this far either side of a repeated stretch belong to it
CENTRE_LINE_STEP = 0.5  # m
MIN_CENTRE_LINE_SAMPLES = 3  # a shorter route (under about a metre) gets no objects
TEXTURE_SMOOTHING = 1.5  # px, σ of the blur that gives textures structure
TEXTURE_CONTRAST = 60.0  # grey levels, std of a texture around its mean
TEXTURE_MEAN = 120.0  # grey level
PER_100M = 100.0  # m: row densities are objects per 100 m of route


@dataclass(frozen=True)
class World:
    """Objects as arrays (one row each); positions, yaws and velocities are those at time 0 in the world frame.

    The objects of `traffic` follow the route's centre line (see neoslam.sim.traffic); any other object with a
    velocity (a world built by hand) moves in a straight line; the rest stand still."""

    labels: np.ndarray  # (n,) str
    positions: np.ndarray  # (n, 3)
    sizes: np.ndarray  # (n, 3) length, width, height
    yaws: np.ndarray  # (n,) heading of the object's length axis
    velocities: np.ndarray  # (n, 3) m/s, zero for static objects
    textures: np.ndarray  # (n, s, s) float grey levels
    traffic: Traffic | None = None  # the moving objects that follow the route

    def __len__(self) -> int:
        return len(self.labels)

    def positions_at(self, time: float) -> np.ndarray:
        """(n, 3) centres at `time`, s (the drive's timestamps)."""
        positions = self.positions + self.velocities * time
        if self.traffic is not None:
            positions[self.traffic.ids] = self.traffic.positions_at(time)
        return positions

    def yaws_at(self, time: float) -> np.ndarray:
        """(n,) headings at `time`: traffic turns with the road and round at its ends; the rest keep theirs."""
        if self.traffic is None:
            return self.yaws
        yaws = self.yaws.copy()
        yaws[self.traffic.ids] = self.traffic.yaws_at(time)
        return yaws

    def moved(self, transform: np.ndarray) -> World:
        """The same objects seen from another frame: x' = R x + t for the rigid (4, 4) `transform` [R | t].

        Positions move as points (at time 0; a moving object moves on from there, traffic along the moved centre
        line, so that positions_at and yaws_at commute with the transform), velocities turn with R, and each
        yaw becomes the heading of the object's length axis turned by R, projected onto the new ground plane. Objects
        are upright boxes that have only a yaw, so a transform should be a yaw and a translation, with at most a small
        roll and pitch (a road's few degrees, as between two poses of a KITTI drive): positions take that tilt
        exactly, the boxes stay upright (their tilt is dropped). Sizes, labels and textures are unchanged."""
        transform = np.asarray(transform, dtype=float)
        if transform.shape != (4, 4):
            raise ValueError(f"transform must be a (4, 4) matrix, got shape {transform.shape}")
        rotation, translation = transform[:3, :3], transform[:3, 3]
        axes = np.column_stack([np.cos(self.yaws), np.sin(self.yaws), np.zeros(len(self))]) @ rotation.T
        return World(
            labels=self.labels.copy(),
            positions=self.positions @ rotation.T + translation,
            sizes=self.sizes.copy(),
            yaws=np.arctan2(axes[:, 1], axes[:, 0]).reshape(-1),
            velocities=self.velocities @ rotation.T,
            textures=self.textures.copy(),
            traffic=None if self.traffic is None else self.traffic.moved(rotation, translation),
        )


@dataclass(frozen=True)
class _CentreLine:
    arc: np.ndarray  # (n,) arc length from the first sample, m
    xy: np.ndarray  # (n, 2)
    ground: np.ndarray  # (n,) road height
    heading: np.ndarray  # (n,)
    revisited: np.ndarray  # (n,) bool: an earlier pass already placed objects here


def _centre_line(trajectory: Trajectory, camera_height: float, revisit_radius: float) -> _CentreLine | None:
    positions = trajectory.positions
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(arc) > 1e-6])
    positions, arc = positions[keep], arc[keep]
    samples = np.arange(0.0, arc[-1], CENTRE_LINE_STEP)
    if len(samples) < MIN_CENTRE_LINE_SAMPLES:  # the robot hardly moves: there is no street to line
        return None
    dense = np.stack([np.interp(samples, arc, positions[:, k]) for k in range(3)], axis=1)
    heading = np.unwrap(np.arctan2(*np.gradient(dense[:, :2], axis=0).T[::-1]))
    tree = cKDTree(dense[:, :2])
    gap = int(3 * revisit_radius / CENTRE_LINE_STEP)  # neighbours within this many samples are the same pass
    revisited = np.array(
        [any(j < i - gap for j in tree.query_ball_point(dense[i, :2], revisit_radius)) for i in range(len(dense))],
        dtype=bool,
    )
    return _CentreLine(samples, dense[:, :2], dense[:, 2] - camera_height, heading, revisited)


def _class_textures(labels: list[str], size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {label: gaussian_filter(rng.normal(size=(size, size)), TEXTURE_SMOOTHING) for label in labels}


def _texture(prototype: np.ndarray, individuality: float, rng: np.random.Generator) -> np.ndarray:
    """Class prototype blended with an individual pattern, so that objects of a class look alike."""
    own = gaussian_filter(rng.normal(size=prototype.shape), TEXTURE_SMOOTHING)
    mixed = (1 - individuality) * prototype / prototype.std() + individuality * own / own.std()
    return TEXTURE_MEAN + TEXTURE_CONTRAST * mixed / mixed.std()


def _rows(config: WorldConfig) -> tuple[tuple[float, float, float], ...]:
    """(signed lateral offset, share of slots taken, lateral std) of each row of objects."""
    if config.rows is None:
        side = (config.occupancy, config.lateral_jitter)
        return ((config.lateral_offset, *side), (-config.lateral_offset, *side))
    return tuple((offset, density * config.spacing / PER_100M, jitter) for offset, density, jitter in config.rows)


def _slots(line: _CentreLine, config: WorldConfig, rng: np.random.Generator) -> list[tuple[int, float, float]]:
    """(centre-line sample, signed lateral offset of its row (left positive), lateral std) of every slot that holds an
    object: both sides at lateral_offset with `occupancy`, or the configured rows at their densities."""
    rows = _rows(config)
    spacing = int(config.spacing / CENTRE_LINE_STEP)
    slots = []
    for index in range(0, len(line.xy), spacing):
        jittered = min(index + int(rng.integers(0, max(spacing // 2, 1))), len(line.xy) - 1)
        for offset, occupancy, jitter in rows:
            if rng.random() < occupancy and not line.revisited[jittered]:
                slots.append((jittered, offset, jitter))
    return slots


def _place(line: _CentreLine, config: WorldConfig, patch: int, individuality: float, rng: np.random.Generator):
    classes = sorted(config.class_mix)
    weights = np.array([config.class_mix[c] for c in classes], dtype=float)
    prototypes = _class_textures(classes, patch, rng)
    road = cKDTree(line.xy)
    placed: list[dict] = []
    for index, offset, jitter in _slots(line, config, rng):
        label = classes[int(rng.choice(len(classes), p=weights / weights.sum()))]
        heading = line.heading[index]
        normal = np.array([-np.sin(heading), np.cos(heading)])
        lateral = abs(offset) + KERB_EXTRA[label] + rng.normal(0.0, jitter)
        xy = line.xy[index] + np.sign(offset) * lateral * normal
        if road.query_ball_point(xy, config.road_clearance):  # on the road or another street (near a crossing)
            continue
        if placed and np.linalg.norm(np.array([p["xy"] for p in placed]) - xy, axis=1).min() < config.min_separation:
            continue
        size = CLASS_SIZES[label]
        placed.append(
            {
                "label": label,
                "xy": xy,
                "z": line.ground[index] + size[2] / 2,
                "yaw": heading + rng.normal(0.0, 0.05),
                "texture": _texture(prototypes[label], individuality, rng),
            }
        )
    return placed, prototypes


def _repeat_layout(
    placed: list[dict], repeat: RepeatedLayout, line: _CentreLine, prototypes, individuality, rng
) -> list[dict]:
    """Remove what stands at the target stretch and copy the source stretch's layout there (fresh textures)."""

    def local(xy: np.ndarray, start, heading) -> np.ndarray:
        c, s = np.cos(heading), np.sin(heading)
        d = xy - np.asarray(start)
        return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

    def inside(xy, start, heading) -> bool:
        along, across = local(xy, start, heading)
        return 0.0 <= along < repeat.length and abs(across) < REPEAT_HALF_WIDTH

    kept = [p for p in placed if not inside(p["xy"], repeat.target_start, repeat.target_heading)]
    turn = repeat.target_heading - repeat.source_heading
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    for p in placed:
        if inside(p["xy"], repeat.source_start, repeat.source_heading):
            xy = rotation @ (p["xy"] - np.asarray(repeat.source_start)) + np.asarray(repeat.target_start)
            texture = _texture(prototypes[p["label"]], individuality, rng)
            ground = line.ground[int(np.argmin(np.linalg.norm(line.xy - xy, axis=1)))]
            z = ground + CLASS_SIZES[p["label"]][2] / 2
            kept.append(dict(p, xy=xy, z=z, yaw=p["yaw"] + turn, texture=texture))
    return kept


def build_world(
    trajectory: Trajectory,
    config: WorldConfig,
    detection: DetectionNoiseConfig,
    camera_height: float,
    rng: np.random.Generator,
    repeats: tuple[RepeatedLayout, ...] = (),
) -> World:
    """Objects along the true trajectory, standing on the road surface below the camera."""
    line = _centre_line(trajectory, camera_height, config.revisit_radius)
    if line is None:
        return _world_of([], detection.patch_size)
    placed, prototypes = _place(line, config, detection.patch_size, detection.texture_individuality, rng)
    for repeat in repeats:
        placed = _repeat_layout(placed, repeat, line, prototypes, detection.texture_individuality, rng)
    return _with_traffic(_world_of(placed, detection.patch_size), line, config, rng)


def _world_of(placed: list[dict], patch_size: int) -> World:
    labels = np.array([p["label"] for p in placed], dtype=str)
    xy = np.array([p["xy"] for p in placed]).reshape(-1, 2)
    sizes = np.array([CLASS_SIZES[label] for label in labels]).reshape(-1, 3)
    z = np.array([p["z"] for p in placed])
    yaws = np.array([p["yaw"] for p in placed])
    textures = np.array([p["texture"] for p in placed]).reshape(-1, patch_size, patch_size)
    return World(labels, np.column_stack([xy, z]), sizes, yaws, np.zeros((len(placed), 3)), textures)


def _with_traffic(world: World, line: _CentreLine, config: WorldConfig, rng: np.random.Generator) -> World:
    """The world with a share `moving_fraction` of its objects set moving, drawn after everything else is placed,
    so that a street with traffic holds the same objects as the static one (and a static one is as before)."""
    moving = np.flatnonzero(rng.random(len(world)) < config.moving_fraction)
    backwards = rng.choice([True, False], size=len(world))[moving]  # both ways, as many against the route as along
    if not len(moving):
        return world
    points = np.column_stack([line.xy, line.ground])
    lift = world.sizes[moving, 2] / 2
    labels, xy = world.labels[moving], world.positions[moving, :2]
    traffic = build_traffic(moving, labels, xy, lift, backwards, line.arc, points, line.heading, config, rng)
    positions, yaws, velocities = world.positions.copy(), world.yaws.copy(), world.velocities.copy()
    positions[moving], yaws[moving], velocities[moving] = (
        traffic.positions_at(0.0),
        traffic.yaws_at(0.0),
        traffic.velocities_at(0.0),
    )
    return World(world.labels, positions, world.sizes, yaws, velocities, world.textures, traffic)
