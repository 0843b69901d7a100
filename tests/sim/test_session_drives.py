"""Sessions in one simulated world: the same objects at the same true places, independent noise, each from the
identity; and the pieces under them (a world moved to another frame, a world given to `simulate`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import SimulatorConfig
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.geometry import body_velocities, make_pose
from neoslam.sim.detections import DetectionSimulator
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.session_drives import session_recordings
from neoslam.sim.simulator import simulate, world_for
from neoslam.types import Trajectory

SPANS = [(0, 500), (300, 816)]  # frames 300-499 are in both sessions
SEEDS = [11, 12]


@pytest.fixture(scope="module")
def config() -> SimulatorConfig:
    return SimulatorConfig(detection_profile="ideal", seed=5)


@pytest.fixture(scope="module")
def truth(config: SimulatorConfig) -> Trajectory:
    """The block route (816 frames, with hills: small pitch), not starting at the identity."""
    return drive_route(ROUTES["block"], config.frame_period, config.camera.height_above_ground)


@pytest.fixture(scope="module")
def sessions(truth: Trajectory, config: SimulatorConfig):
    return session_recordings(truth, SPANS, config, SEEDS, "block")


def _wrapped(angles: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * angles))


def test_each_session_starts_at_the_identity(sessions, truth, tmp_path: Path) -> None:
    for session, (start, stop) in zip(sessions, SPANS, strict=True):
        recording = session.recording
        assert len(recording.truth) == stop - start
        np.testing.assert_array_equal(recording.truth.poses[0], np.eye(4))
        np.testing.assert_array_equal(recording.truth.timestamps, truth.timestamps[start:stop])
        np.testing.assert_allclose(session.to_world(recording.truth.poses), truth.poses[start:stop], atol=1e-9)
        np.testing.assert_array_equal(session.start_pose, truth.poses[start])
    folder = tmp_path / "second"
    write_dataset(folder, sessions[1].recording)
    dataset = read_dataset(folder)
    np.testing.assert_array_equal(dataset.odometry().poses[0], np.eye(4))
    np.testing.assert_allclose(dataset.ground_truth.poses[0], np.eye(4), atol=1e-9)


def test_sessions_share_one_world_at_the_same_true_places(sessions, truth, config) -> None:
    shared = world_for(truth, config)
    assert len(shared) > 20
    for session in sessions:
        back = session.recording.world.moved(session.start_pose)
        np.testing.assert_array_equal(back.labels, shared.labels)
        np.testing.assert_allclose(back.positions, shared.positions, atol=1e-9)
        np.testing.assert_allclose(back.velocities, shared.velocities, atol=1e-12)
        np.testing.assert_allclose(_wrapped(back.yaws - shared.yaws), 0.0, atol=2e-3)  # the boxes stay upright
        np.testing.assert_array_equal(back.textures, shared.textures)


def test_the_same_objects_are_in_view_at_the_same_true_pose(sessions, config) -> None:
    first, second = (s.recording for s in sessions)
    offset = SPANS[1][0]
    seen = 0
    views = [DetectionSimulator(r.world, config.camera, config.detection) for r in (first, second)]
    for frame in range(offset, SPANS[0][1], 10):
        a = views[0].in_view(first.truth.poses[frame], float(first.truth.timestamps[frame]))
        b = views[1].in_view(second.truth.poses[frame - offset], float(second.truth.timestamps[frame - offset]))
        assert [v.index for v in a] == [v.index for v in b]
        np.testing.assert_allclose([v.depth for v in a], [v.depth for v in b], atol=1e-6)
        seen += len(a)
    assert seen > 20


def test_sessions_measure_with_their_own_noise(sessions) -> None:
    first, second = (s.recording for s in sessions)
    offset = SPANS[1][0]
    overlap = slice(offset + 1, SPANS[0][1])
    again = slice(1, SPANS[0][1] - offset)
    assert not np.allclose(first.linear_velocity[overlap], second.linear_velocity[again])
    # under both, the same true motion
    true_a, true_b = (body_velocities(r.truth.poses, r.truth.timestamps)[0] for r in (first, second))
    np.testing.assert_allclose(true_a[overlap], true_b[again], atol=1e-6)
    ids_a = [sorted(d.object_id for d in f) for f in first.detections[overlap]]
    ids_b = [sorted(d.object_id for d in f) for f in second.detections[again]]
    assert ids_a != ids_b  # misses and false positives drawn independently
    assert first.config.seed == SEEDS[0] and second.config.seed == SEEDS[1]


def test_sessions_are_deterministic(sessions, truth, config) -> None:
    again = session_recordings(truth, SPANS, config, SEEDS, "block")
    for one, two in zip(sessions, again, strict=True):
        np.testing.assert_array_equal(one.recording.linear_velocity, two.recording.linear_velocity)
        np.testing.assert_array_equal(one.recording.angular_velocity, two.recording.angular_velocity)
        np.testing.assert_array_equal(one.recording.world.positions, two.recording.world.positions)
        for a, b in zip(one.recording.detections, two.recording.detections, strict=True):
            assert [d.object_id for d in a] == [d.object_id for d in b]
            np.testing.assert_array_equal([d.center_camera for d in a], [d.center_camera for d in b])


def test_session_arguments_are_checked(truth, config) -> None:
    with pytest.raises(ValueError, match="seeds"):
        session_recordings(truth, SPANS, config, [1], "block")
    with pytest.raises(ValueError, match="span"):
        session_recordings(truth, [(500, 900)], config, [1], "block")


def test_moved_world_round_trip_and_pure_yaw(sessions) -> None:
    world = sessions[0].recording.world
    transform = make_pose(Rotation.from_euler("ZYX", [0.7, 0.03, -0.02]), np.array([5.0, -3.0, 1.0]))
    there = world.moved(transform)
    np.testing.assert_allclose(there.positions, world.positions @ transform[:3, :3].T + transform[:3, 3])
    back = there.moved(np.linalg.inv(transform))
    np.testing.assert_allclose(back.positions, world.positions, atol=1e-9)
    np.testing.assert_allclose(_wrapped(back.yaws - world.yaws), 0.0, atol=2e-3)
    turn = make_pose(Rotation.from_euler("z", 0.7), np.array([1.0, 2.0, 0.0]))
    turned = world.moved(turn)
    np.testing.assert_allclose(_wrapped(turned.yaws - world.yaws - 0.7), 0.0, atol=1e-12)
    np.testing.assert_allclose(turned.positions_at(3.0), world.positions_at(3.0) @ turn[:3, :3].T + turn[:3, 3])
    with pytest.raises(ValueError, match="4, 4"):
        world.moved(np.eye(3))


def test_simulate_takes_a_given_world_as_it_is(sessions, truth, config) -> None:
    world = sessions[1].recording.world
    part = sessions[1].recording.truth
    recording = simulate(part, config.model_copy(update={"seed": SEEDS[1]}), "x", "x", world=world)
    assert recording.world is world
    np.testing.assert_array_equal(recording.linear_velocity, sessions[1].recording.linear_velocity)
    # and without one, the world and the noise are those of the seed, as before
    whole = simulate(truth, config, "x", "x")
    np.testing.assert_array_equal(whole.world.positions, world_for(truth, config).positions)
