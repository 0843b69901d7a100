"""The world of objects along a route: off the road, class mix, repeated layout, standing on the road surface."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from neoslam.config import DetectionNoiseConfig, SimulatorConfig, WorldConfig
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.world import CLASS_SIZES, World, build_world
from neoslam.types import Trajectory

CONFIG = SimulatorConfig(detection_profile="ideal")  # both sides of the street at lateral_offset
HEIGHT = CONFIG.camera.height_above_ground


@pytest.fixture(scope="module")
def town_world(town_truth: Trajectory) -> World:
    rng = np.random.default_rng(0)
    return build_world(town_truth, CONFIG.world, CONFIG.detection, HEIGHT, rng, ROUTES["town"].repeats)


def _distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    start, end = polyline[:-1], polyline[1:]
    segment = end - start
    length2 = np.maximum((segment**2).sum(axis=1), 1e-12)
    distances = []
    for point in points:
        t = np.clip(((point - start) * segment).sum(axis=1) / length2, 0.0, 1.0)
        distances.append(np.linalg.norm(start + t[:, None] * segment - point, axis=1).min())
    return np.array(distances)


def _local(xy: np.ndarray, start: tuple[float, float], heading: float) -> np.ndarray:
    """(along, across) coordinates of points relative to a stretch of road."""
    c, s = np.cos(heading), np.sin(heading)
    d = xy - np.asarray(start)
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


def test_world_arrays_are_consistent(town_world: World) -> None:
    n = len(town_world)
    assert n > 150
    assert town_world.positions.shape == (n, 3) and town_world.sizes.shape == (n, 3)
    assert town_world.yaws.shape == (n,) and town_world.textures.shape == (n, 16, 16)
    for label, size in zip(town_world.labels, town_world.sizes, strict=True):
        np.testing.assert_array_equal(size, CLASS_SIZES[str(label)])
    np.testing.assert_array_equal(town_world.velocities, 0.0)  # moving_fraction defaults to 0
    np.testing.assert_array_equal(town_world.positions_at(100.0), town_world.positions)


def test_no_object_on_the_road(town_world: World, town_truth: Trajectory) -> None:
    distance = _distance_to_polyline(town_world.positions[:, :2], town_truth.positions[:, :2])
    assert distance.min() >= 3.0
    assert np.median(distance) < 10.0  # but beside it, not far away


def test_class_mix_roughly_as_configured(town_world: World) -> None:
    mix = CONFIG.world.class_mix
    total = sum(mix.values())
    labels = town_world.labels.tolist()
    for label, weight in mix.items():
        share = labels.count(label) / len(labels)
        assert share == pytest.approx(weight / total, abs=0.06), label
    assert set(labels) <= set(mix)


def test_class_mix_of_a_single_class(town_truth: Trajectory) -> None:
    config = WorldConfig(class_mix={"truck": 1.0})
    world = build_world(town_truth, config, CONFIG.detection, HEIGHT, np.random.default_rng(1))
    assert len(world) > 50 and set(world.labels.tolist()) == {"truck"}


def test_objects_stand_on_the_road_surface(town_world: World) -> None:
    feet = town_world.positions[:, 2] - town_world.sizes[:, 2] / 2
    ground = ROUTES["town"].ground_height(town_world.positions[:, :2])
    # objects stand at the height of the road beside them (the hill's slope over ~7 m is below 1 m)
    assert np.abs(feet - ground).max() < 1.0


def test_repeated_layout_is_a_rigid_copy(town_world: World) -> None:
    (repeat,) = ROUTES["town"].repeats
    xy = town_world.positions[:, :2]

    def stretch(start, heading):
        local = _local(xy, start, heading)
        inside = (local[:, 0] >= 0) & (local[:, 0] < repeat.length) & (np.abs(local[:, 1]) < 12.0)
        order = np.lexsort((local[inside, 1], local[inside, 0]))
        return local[inside][order], town_world.labels[inside][order], np.flatnonzero(inside)[order]

    source_xy, source_labels, source_ids = stretch(repeat.source_start, repeat.source_heading)
    target_xy, target_labels, target_ids = stretch(repeat.target_start, repeat.target_heading)
    assert len(source_xy) >= 8
    assert len(target_xy) == len(source_xy)
    np.testing.assert_allclose(target_xy, source_xy, atol=1e-9)
    np.testing.assert_array_equal(target_labels, source_labels)
    turn = repeat.target_heading - repeat.source_heading
    np.testing.assert_allclose(town_world.yaws[target_ids], town_world.yaws[source_ids] + turn, atol=1e-12)
    # a copy of the layout, not of the objects' looks: every copy has a fresh texture
    for s, t in zip(source_ids, target_ids, strict=True):
        assert not np.allclose(town_world.textures[s], town_world.textures[t])


def test_textures_of_a_class_look_alike(town_world: World) -> None:
    textures = town_world.textures.reshape(len(town_world), -1)
    labels = town_world.labels
    cars, people = textures[labels == "car"], textures[labels == "person"]
    within = np.mean([np.corrcoef(cars[i], cars[i + 1])[0, 1] for i in range(20)])
    across = np.mean([np.corrcoef(cars[i], people[i % len(people)])[0, 1] for i in range(20)])
    assert within > across + 0.3
    individual = DetectionNoiseConfig(texture_individuality=1.0)
    world = build_world(
        drive_route(ROUTES["block"], CONFIG.frame_period, HEIGHT),
        CONFIG.world,
        individual,
        HEIGHT,
        np.random.default_rng(2),
    )
    flat = world.textures.reshape(len(world), -1)
    cars = flat[world.labels == "car"]
    assert abs(np.mean([np.corrcoef(cars[i], cars[i + 1])[0, 1] for i in range(10)])) < 0.3


def test_objects_built_with_a_velocity_move_in_a_straight_line(town_world: World) -> None:
    # (the simulator's traffic follows the route: tests/sim/test_traffic.py)
    velocities = np.zeros_like(town_world.positions)
    velocities[::3, 0] = 2.0
    world = World(
        town_world.labels, town_world.positions, town_world.sizes, town_world.yaws, velocities, town_world.textures
    )
    np.testing.assert_allclose(world.positions_at(1.5), world.positions + 1.5 * velocities)
    np.testing.assert_array_equal(world.yaws_at(1.5), world.yaws)


def test_same_rng_same_world(town_truth: Trajectory) -> None:
    a = build_world(town_truth, CONFIG.world, CONFIG.detection, HEIGHT, np.random.default_rng(7))
    b = build_world(town_truth, CONFIG.world, CONFIG.detection, HEIGHT, np.random.default_rng(7))
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.textures, b.textures)


def test_no_two_objects_closer_than_min_separation(town_truth: Trajectory) -> None:
    for seed in range(5):
        rng = np.random.default_rng(seed)
        world = build_world(town_truth, CONFIG.world, CONFIG.detection, HEIGHT, rng, ROUTES["town"].repeats)
        assert pdist(world.positions[:, :2]).min() >= CONFIG.world.min_separation, f"seed {seed}"
