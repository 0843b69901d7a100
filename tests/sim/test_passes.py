"""A route driven several times in a row (neoslam.sim.passes): where a pass is cut, continuity across the joins,
timestamps that run on, and one world for every pass."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import SimulatorConfig
from neoslam.geometry import make_pose, relative_pose, rotation_angle
from neoslam.io.trajectory_files import read_trajectory
from neoslam.sim.passes import find_pass, join_passes
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate
from neoslam.types import Trajectory

PERIOD = SimulatorConfig().frame_period
HEIGHT = SimulatorConfig().camera.height_above_ground


def _circle(radius: float = 40.0, laps: float = 1.3, step: float = 0.8, offset: float = 0.0) -> Trajectory:
    """Counter-clockwise circle from (0, -radius) heading +x, `laps` laps; after one lap the circle is widened by
    `offset` (the route comes back beside its start)."""
    angles = np.arange(0.0, 2 * np.pi * laps, step / radius)
    r = radius + offset * (angles >= 2 * np.pi)
    poses = [
        make_pose(Rotation.from_euler("z", a), [r_ * np.sin(a), -r_ * np.cos(a), 1.6])
        for a, r_ in zip(angles, r, strict=True)
    ]
    return Trajectory(PERIOD * np.arange(len(poses)), np.array(poses))


def _steps(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Length (m) and turn (rad) of every step."""
    steps = relative_pose(trajectory.poses[:-1], trajectory.poses[1:])
    return np.linalg.norm(steps[:, :3, 3], axis=1), rotation_angle(steps[:, :3, :3])


def test_a_pass_ends_where_the_route_comes_back_to_its_start() -> None:
    circle = _circle()
    j, k = find_pass(circle)
    lap = int(np.ceil(2 * np.pi * 40.0 / 0.8))
    assert j == 0 and abs(k - lap) <= 1
    assert np.linalg.norm(circle.positions[k, :2] - circle.positions[0, :2]) <= 1.2


@pytest.mark.parametrize("offset", [0.0, 1.0])
def test_passes_join_without_a_jump(offset: float) -> None:
    circle = _circle(offset=offset)  # with an offset, the route comes back 1 m beside its start
    drive = join_passes(circle, 3)
    j, k = drive.source_frames
    assert drive.passes == 3 and drive.frames_per_pass == k - j
    assert len(drive.trajectory) == 3 * (k - j)
    np.testing.assert_array_equal(drive.pass_starts, [0, k - j, 2 * (k - j)])
    length, turn = _steps(drive.trajectory)
    source_length, source_turn = _steps(circle)
    assert length.max() <= source_length.max() * 1.05  # the joins are steps like the others
    assert turn.max() <= source_turn.max() + np.radians(0.5)
    # every pass is the same poses, the first frame of each the route's frame j
    poses = drive.trajectory.poses.reshape(3, k - j, 4, 4)
    np.testing.assert_array_equal(poses[0], poses[2])
    np.testing.assert_allclose(poses[1, 0], circle.poses[j], atol=1e-12)
    # only the last `blend_m` metres of a pass moved (to lead into the next)
    unchanged = np.linalg.norm(poses[0, :, :3, 3] - circle.positions[j:k], axis=1) < 1e-9
    arc = np.concatenate([[0.0], np.cumsum(source_length)])
    np.testing.assert_array_equal(unchanged, arc[k] - arc[j:k] >= 20.0)  # blend_m
    np.testing.assert_array_equal(drive.pass_of()[[0, k - j, -1]], [0, 1, 2])


def test_timestamps_run_on_across_the_joins() -> None:
    circle = _circle()
    drive = join_passes(circle, 4)
    stamps = drive.trajectory.timestamps
    np.testing.assert_allclose(np.diff(stamps), PERIOD, atol=1e-9)  # the joins too
    assert stamps[0] == circle.timestamps[0]


def test_a_route_that_never_comes_back_cannot_be_joined() -> None:
    straight = Trajectory(np.arange(200.0), np.array([make_pose(np.eye(3), [float(x), 0, 0]) for x in range(200)]))
    with pytest.raises(ValueError, match="never comes back"):
        join_passes(straight, 2)
    with pytest.raises(ValueError, match="at least 1"):
        join_passes(_circle(), 0)


def test_the_block_route_is_one_lap_a_pass() -> None:
    """The block route starts on a corner and comes back round it on the fillet: the pass begins a few metres on,
    where the second lap comes back within 1.2 m heading the same way."""
    block = drive_route(ROUTES["block"], PERIOD, HEIGHT)
    drive = join_passes(block, 2)
    j, k = drive.source_frames
    lap = 2 * (120.0 + 80.0)
    travelled = Trajectory(block.timestamps[j : k + 1], block.poses[j : k + 1]).path_length()
    assert 0 < j < 50 and lap - 30.0 < travelled < lap
    length, _ = _steps(drive.trajectory)
    assert length.max() <= _steps(block)[0].max() * 1.05


@pytest.mark.slow
def test_one_world_for_every_pass_count() -> None:
    """Simulated along one pass, the world is the same however many passes are driven, and a second pass is seen
    in the objects of the first: no second set of objects."""
    config = SimulatorConfig(detection_profile="ideal", seed=3)
    block = drive_route(ROUTES["block"], PERIOD, HEIGHT)
    one = join_passes(block, 1).trajectory
    worlds = [
        simulate(join_passes(block, passes).trajectory, config, "b", "b", world_along=one).world for passes in (1, 2)
    ]
    np.testing.assert_array_equal(worlds[0].positions, worlds[1].positions)
    np.testing.assert_array_equal(worlds[0].labels, worlds[1].labels)
    # Without world_along the world is built along both passes; the second adds no objects (revisit_radius).
    along_both = simulate(join_passes(block, 2).trajectory, config, "b", "b").world
    assert abs(len(along_both) - len(worlds[0])) <= 0.05 * len(worlds[0])


def test_kitti_00_comes_back_within_1_2_m_of_its_start(kitti_poses) -> None:
    truth = read_trajectory(kitti_poses("00"), "kitti", None, frame_period=PERIOD)
    j, k = find_pass(truth)
    assert j == 0 and k == 4447
    assert np.linalg.norm(truth.positions[k, :2] - truth.positions[0, :2]) <= 1.2
    drive = join_passes(truth, 2)
    length, _ = _steps(drive.trajectory)
    assert length.max() <= _steps(truth)[0].max() + 1e-9
