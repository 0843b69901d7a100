"""Traffic on the simulated streets: vehicles in their lanes both ways, people slow along the kerb, all on the
streets for the whole drive; positions and yaws in time, a world seen from another frame, a static street as before,
and a dataset with traffic that reads back, the same for the same seed."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from neoslam.cli import app
from neoslam.config import SimulatorConfig, WorldConfig
from neoslam.datasets.simulated import OBJECT_COLUMNS, read_dataset, write_dataset
from neoslam.geometry import make_pose
from neoslam.io.tables import read_table
from neoslam.io.trajectory_files import write_tum
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate
from neoslam.sim.traffic import IN_LANE
from neoslam.sim.world import World, build_world
from neoslam.types import Trajectory

CONFIG = SimulatorConfig(detection_profile="ideal")
HEIGHT = CONFIG.camera.height_above_ground
WORLD = CONFIG.world.model_copy(update={"moving_fraction": 1.0})  # every object moves
LONG = np.arange(0.0, 1500.0, 1.3)  # s: several times the drive, so every mover turns round at the ends


@pytest.fixture(scope="module")
def traffic_world(town_truth: Trajectory) -> World:
    rng = np.random.default_rng(3)
    return build_world(town_truth, WORLD, CONFIG.detection, HEIGHT, rng, ROUTES["town"].repeats)


@pytest.fixture(scope="module")
def route_tree(town_truth: Trajectory) -> cKDTree:
    """The driven route, a point every 2 cm (so distances to it are the polyline's to well under a millimetre)."""
    xy = town_truth.positions[:, :2]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    dense = np.arange(0.0, arc[-1], 0.02)
    return cKDTree(np.column_stack([np.interp(dense, arc, xy[:, 0]), np.interp(dense, arc, xy[:, 1])]))


def _distance(route_tree: cKDTree, xy: np.ndarray) -> np.ndarray:
    return route_tree.query(xy)[0]


def _wrapped(angles: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * angles))


def test_every_object_moves_at_fraction_one(traffic_world: World) -> None:
    traffic = traffic_world.traffic
    assert traffic is not None and len(traffic) == len(traffic_world) > 150
    np.testing.assert_array_equal(np.sort(traffic.ids), np.arange(len(traffic_world)))
    assert (np.linalg.norm(traffic_world.velocities, axis=1) > 0).all()


def test_vehicles_stay_in_their_lane_for_the_whole_drive(traffic_world: World, route_tree: cKDTree) -> None:
    traffic = traffic_world.traffic
    lane = traffic.ids[traffic.in_lane]
    lateral = np.concatenate([_distance(route_tree, traffic_world.positions_at(t)[lane, :2]) for t in LONG])
    assert lateral.max() <= WORLD.lane_offset + 0.05  # never off the road
    # in their lane but where they turn round at an end of the route (or pass near a crossing street)
    assert np.mean(np.abs(lateral - WORLD.lane_offset) < 0.1) > 0.9
    feet = traffic_world.positions_at(LONG[-1])[lane]
    ground = ROUTES["town"].ground_height(feet[:, :2])
    np.testing.assert_allclose(feet[:, 2] - traffic_world.sizes[lane, 2] / 2, ground, atol=0.5)  # on the road


def test_vehicles_drive_both_ways_at_their_speeds(traffic_world: World) -> None:
    traffic = traffic_world.traffic
    labels = traffic_world.labels[traffic.ids]
    lane = traffic.in_lane
    np.testing.assert_array_equal(lane, np.isin(labels, sorted(IN_LANE)))
    along = np.mean(traffic.speed[lane] > 0)
    assert 0.35 < along < 0.65  # some along the robot's direction, some against
    for label, (slowest, fastest) in (("car", WORLD.vehicle_speed), ("bicycle", WORLD.bicycle_speed)):
        speed = np.abs(traffic.speed[labels == label])
        assert len(speed) > 10 and slowest <= speed.min() and speed.max() <= fastest, label
    # right-hand traffic: a vehicle keeps to the right of its direction of travel
    vehicles = traffic.ids[lane]
    xy = traffic_world.positions[vehicles, :2]
    _, nearest = cKDTree(traffic.points[:, :2]).query(xy)
    left_of_line = ((xy - traffic.points[nearest, :2]) * traffic.left[nearest, :2]).sum(axis=1)
    forwards = (traffic_world.velocities[vehicles, :2] * traffic.along[nearest, :2]).sum(axis=1) > 0
    assert np.mean(np.where(forwards, left_of_line < 0, left_of_line > 0)) > 0.9  # but near a crossing street


def test_yaws_follow_the_direction_of_travel(traffic_world: World) -> None:
    moving = traffic_world.traffic.ids
    for t in (0.0, 200.0, 900.0):
        dt = 0.05
        step = traffic_world.positions_at(t + dt)[moving] - traffic_world.positions_at(t)[moving]
        travel = np.arctan2(step[:, 1], step[:, 0])
        aligned = np.abs(_wrapped(travel - traffic_world.yaws_at(t)[moving])) < 0.3
        assert aligned.mean() > 0.9, t  # but where one turns round or crosses to the other lane


def test_people_walk_slowly_along_their_kerb(traffic_world: World, route_tree: cKDTree) -> None:
    traffic = traffic_world.traffic
    people = traffic.ids[~traffic.in_lane]
    assert len(people) > 10 and set(traffic_world.labels[people].tolist()) == {"person"}
    slowest, fastest = WORLD.walking_speed
    speed = np.abs(traffic.speed[~traffic.in_lane])
    assert slowest <= speed.min() and speed.max() <= fastest
    dt = 1.0
    walked = [
        np.linalg.norm(traffic_world.positions_at(t + dt)[people] - traffic_world.positions_at(t)[people], axis=1)
        for t in LONG[::11]
    ]
    assert np.median(walked) / dt <= fastest  # faster only round the outside of a corner
    start = _distance(route_tree, traffic_world.positions[people, :2])
    later = _distance(route_tree, traffic_world.positions_at(LONG[-1])[people, :2])
    assert start.min() >= WORLD.road_clearance - 0.5  # off the road, at the kerb where they were placed
    assert np.median(np.abs(later - start)) < 0.5  # and they keep to it


def test_time_zero_is_the_world_as_stored(traffic_world: World) -> None:
    np.testing.assert_array_equal(traffic_world.positions_at(0.0), traffic_world.positions)
    np.testing.assert_array_equal(traffic_world.yaws_at(0.0), traffic_world.yaws)
    speeds = np.linalg.norm(traffic_world.velocities[traffic_world.traffic.ids], axis=1)
    np.testing.assert_allclose(speeds, np.abs(traffic_world.traffic.speed))
    heading = np.arctan2(traffic_world.velocities[:, 1], traffic_world.velocities[:, 0])
    np.testing.assert_allclose(_wrapped(heading - traffic_world.yaws), 0.0, atol=1e-9)


@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.03, -0.02)])
def test_moved_world_commutes_with_time(traffic_world: World, tilt: tuple[float, float]) -> None:
    transform = make_pose(Rotation.from_euler("ZYX", [0.7, *tilt]), np.array([5.0, -3.0, 1.0]))
    rotation, translation = transform[:3, :3], transform[:3, 3]
    there = traffic_world.moved(transform)
    for t in (0.0, 37.5, 410.0, 1333.0):
        np.testing.assert_allclose(
            there.positions_at(t), traffic_world.positions_at(t) @ rotation.T + translation, atol=1e-9
        )
        atol = 1e-9 if tilt == (0.0, 0.0) else 2e-3  # the boxes stay upright: a tilt is dropped from the yaw
        np.testing.assert_allclose(_wrapped(there.yaws_at(t) - traffic_world.yaws_at(t) - 0.7), 0.0, atol=atol)
    np.testing.assert_allclose(there.velocities, traffic_world.velocities @ rotation.T, atol=1e-12)
    back = there.moved(np.linalg.inv(transform))
    np.testing.assert_allclose(back.positions_at(600.0), traffic_world.positions_at(600.0), atol=1e-9)


def test_static_street_is_the_street_of_the_traffic(traffic_world: World, town_truth: Trajectory) -> None:
    rng = np.random.default_rng(3)
    static = build_world(town_truth, CONFIG.world, CONFIG.detection, HEIGHT, rng, ROUTES["town"].repeats)
    assert static.traffic is None and CONFIG.world.moving_fraction == 0.0
    np.testing.assert_array_equal(static.velocities, 0.0)
    np.testing.assert_array_equal(static.positions_at(500.0), static.positions)
    np.testing.assert_array_equal(static.yaws_at(500.0), static.yaws)
    # traffic is drawn after the street is placed: the same objects, those that stay put in the same places
    some = CONFIG.world.model_copy(update={"moving_fraction": 0.2})
    rng = np.random.default_rng(3)
    busy = build_world(town_truth, some, CONFIG.detection, HEIGHT, rng, ROUTES["town"].repeats)
    np.testing.assert_array_equal(busy.labels, static.labels)
    np.testing.assert_array_equal(busy.textures, static.textures)
    parked = np.setdiff1d(np.arange(len(busy)), busy.traffic.ids)
    assert 0.1 < len(busy.traffic) / len(busy) < 0.3
    np.testing.assert_array_equal(busy.positions[parked], static.positions[parked])
    np.testing.assert_array_equal(busy.yaws[parked], static.yaws[parked])


def test_speed_ranges_are_checked() -> None:
    with pytest.raises(ValueError, match="slowest"):
        WorldConfig(vehicle_speed=(12.0, 5.0))
    with pytest.raises(ValueError, match="slowest"):
        WorldConfig(walking_speed=(0.0, 1.0))
    with pytest.raises(ValueError):
        WorldConfig(moving_speed=1.5)  # the straight-line speed it replaced


def test_left_hand_traffic_keeps_left(town_truth: Trajectory) -> None:
    world_config = WORLD.model_copy(update={"drive_on": "left", "class_mix": {"car": 1.0}})
    world = build_world(town_truth, world_config, CONFIG.detection, HEIGHT, np.random.default_rng(4))
    traffic = world.traffic
    forwards = traffic.speed > 0
    np.testing.assert_allclose(traffic.offset, WORLD.lane_offset)  # left of the line while travelling along it
    assert forwards.any() and (~forwards).any()


@pytest.mark.slow
def test_dataset_with_traffic_reads_back(tmp_path: Path) -> None:
    config = SimulatorConfig(seed=5, world={"moving_fraction": 0.2})
    truth = drive_route(ROUTES["block"], config.frame_period, HEIGHT)
    recording = simulate(truth, config, "block", "route:block", route=ROUTES["block"])
    write_dataset(tmp_path / "busy", recording)
    dataset = read_dataset(tmp_path / "busy")
    assert sum(len(o) for o in dataset.observations) == sum(len(d) for d in recording.detections)
    rows = read_table(tmp_path / "busy" / "truth" / "objects.csv", OBJECT_COLUMNS)
    speeds = np.array([np.linalg.norm([float(v) for v in row[-3:]]) for row in rows.rows])
    moving = np.flatnonzero(speeds > 0)
    np.testing.assert_array_equal(moving, np.sort(recording.world.traffic.ids))
    seen = {d.object_id for frame in recording.detections for d in frame}
    assert seen & set(moving.tolist())  # the robot sees some traffic


def _executable() -> str:
    beside = Path(sys.executable).parent / "neoslam"
    return str(beside) if beside.is_file() else str(shutil.which("neoslam"))


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_same_seed_same_bytes_with_traffic(town_truth: Trajectory, tmp_path: Path) -> None:
    drive = tmp_path / "drive.txt"  # the town's first 40 s: traffic crosses the robot's path both ways
    write_tum(drive, Trajectory(town_truth.timestamps[:400], town_truth.poses[:400]))
    busy = {"NEOSLAM_SIMULATOR__WORLD__MOVING_FRACTION": "0.4"}
    arguments = ["simulate", "--trajectory", str(drive), "--format", "tum", "--seed", "3", "-q", "--out"]
    result = CliRunner().invoke(app, [*arguments, str(tmp_path / "A")], env=busy)
    assert result.exit_code == 0, result.output
    # B in a separate process with another string-hash seed: nothing may depend on set or dict hash order
    environment = os.environ | busy | {"PYTHONHASHSEED": "123"}
    done = subprocess.run([_executable(), *arguments, str(tmp_path / "B")], capture_output=True, env=environment)
    assert done.returncode == 0, done.stderr
    a, b = _files(tmp_path / "A"), _files(tmp_path / "B")
    assert set(a) == set(b) and all(a[name] == b[name] for name in a)
    assert b"moving_fraction: 0.4" in a["dataset.yaml"]
    assert b"0.0000,0.0000,0.0000" in a["truth/objects.csv"]  # some parked
    assert a["detections.csv"].count(b"\n") > 400
