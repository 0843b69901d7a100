"""Odometry noise profiles: none is exact, vo has its 1 % speed bias, heavy drifts more than vo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NOISE_PROFILES, SimulatorConfig
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import body_velocities, integrate_body_velocities, relative_pose
from neoslam.sim.odometry import noisy_odometry, noisy_step
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import SimulatedRecording, simulate_route
from neoslam.types import Trajectory

CONFIG = SimulatorConfig()


@pytest.fixture(scope="module")
def truth() -> Trajectory:
    return drive_route(ROUTES["block"], CONFIG.frame_period, CONFIG.camera.height_above_ground)


def replace_odometry(config: SimulatorConfig, profile: str) -> SimulatorConfig:
    return config.model_copy(update={"noise_profile": profile, "odometry": NOISE_PROFILES[profile]})


def _odometry(truth: Trajectory, profile: str, seed: int = 0) -> Trajectory:
    linear, angular = noisy_odometry(truth, NOISE_PROFILES[profile], np.random.default_rng(seed))
    poses = integrate_body_velocities(linear, angular, truth.timestamps, start=truth.poses[0])
    return Trajectory(truth.timestamps, poses)


def test_none_is_the_truth(truth: Trajectory) -> None:
    np.testing.assert_allclose(_odometry(truth, "none").poses, truth.poses, atol=1e-6)


@pytest.mark.slow
def test_none_is_the_truth_through_the_dataset_files(tmp_path: Path, truth: Trajectory) -> None:
    recording = simulate_route("block", replace_odometry(CONFIG, "none"))
    write_dataset(tmp_path / "d", recording)
    odometry = read_dataset(tmp_path / "d").odometry()  # starts at identity: the robot knows no world frame
    np.testing.assert_allclose(odometry.poses, relative_pose(truth.poses[0], truth.poses), atol=1e-6)


@pytest.mark.parametrize("profile", ["vo", "heavy"])
def test_a_step_at_a_time_has_the_noise_model_of_a_whole_trajectory(truth: Trajectory, profile: str) -> None:
    """A robot driven in closed loop gets its odometry a step at a time: the same noise model, the same draws as a
    trajectory of those two poses."""
    noise = NOISE_PROFILES[profile]
    for i in (1, 100, len(truth) - 1):
        pair = truth.subset(np.array([i - 1, i]))
        linear, angular = noisy_odometry(pair, noise, np.random.default_rng(i))
        dt = float(pair.timestamps[1] - pair.timestamps[0])
        step = noisy_step(pair.poses[0], pair.poses[1], dt, noise, np.random.default_rng(i))
        np.testing.assert_allclose(step[0], linear[1], atol=1e-9)
        np.testing.assert_allclose(step[1], angular[1], atol=1e-9)


def test_velocities_start_with_zero(truth: Trajectory) -> None:
    linear, angular = noisy_odometry(truth, NOISE_PROFILES["vo"], np.random.default_rng(0))
    assert linear.shape == angular.shape == (len(truth), 3)
    np.testing.assert_array_equal(linear[0], 0.0)
    np.testing.assert_array_equal(angular[0], 0.0)


def test_vo_noise_statistics(truth: Trajectory) -> None:
    vo = NOISE_PROFILES["vo"]
    true_linear, true_angular = body_velocities(truth.poses, truth.timestamps)
    linear, angular = noisy_odometry(truth, vo, np.random.default_rng(1))
    speed_error = np.linalg.norm(linear[1:], axis=1) - np.linalg.norm(true_linear[1:], axis=1) * (
        1 + vo.speed_scale_bias
    )
    assert np.std(speed_error) == pytest.approx(vo.sigma_speed, rel=0.15)
    assert abs(np.mean(speed_error)) < 0.03
    yaw_rate_error = angular[1:, 2] - true_angular[1:, 2]
    assert np.mean(yaw_rate_error) == pytest.approx(vo.yaw_rate_bias, abs=0.002)
    assert np.std(yaw_rate_error) == pytest.approx(vo.sigma_yaw_rate, rel=0.15)


def test_vo_path_is_one_percent_longer(truth: Trajectory) -> None:
    ratio = _odometry(truth, "vo").path_length() / truth.path_length()
    assert ratio == pytest.approx(1.0 + NOISE_PROFILES["vo"].speed_scale_bias, abs=0.003)


def test_heavy_drifts_more_than_vo(truth: Trajectory) -> None:
    for seed in range(3):
        vo = absolute_trajectory_error(_odometry(truth, "vo", seed), truth, align="se3").rmse
        heavy = absolute_trajectory_error(_odometry(truth, "heavy", seed), truth, align="se3").rmse
        assert 0.0 < vo < heavy, seed
        assert heavy > 2 * vo, seed


def test_odometry_noise_does_not_change_world_or_detections(block_recording: SimulatedRecording) -> None:
    """Each concern draws from its own random stream: another noise profile leaves world and detections alone."""
    heavy = simulate_route("block", replace_odometry(block_recording.config, "heavy"))
    np.testing.assert_array_equal(heavy.world.positions, block_recording.world.positions)
    assert len(heavy.detections) == len(block_recording.detections)
    for ours, theirs in zip(heavy.detections, block_recording.detections, strict=True):
        assert [(d.object_id, d.label) for d in ours] == [(d.object_id, d.label) for d in theirs]
        for a, b in zip(ours, theirs, strict=True):
            np.testing.assert_array_equal(a.center_camera, b.center_camera)
    assert not np.allclose(heavy.linear_velocity, block_recording.linear_velocity)
    np.testing.assert_array_equal(heavy.truth.poses, block_recording.truth.poses)


STRAIGHT_FRAMES = 20_000  # 2 km at 10 m/s: the standard error of a mean yaw-rate error is 7e-5 rad/s with vo


@pytest.fixture(scope="module")
def straight() -> Trajectory:
    """A flat straight road at 10 m/s: every velocity but the forward speed is zero, so each noise term shows alone."""
    poses = np.tile(np.eye(4), (STRAIGHT_FRAMES, 1, 1))
    poses[:, 0, 3] = np.arange(STRAIGHT_FRAMES) * 10.0 * CONFIG.frame_period
    return Trajectory(np.arange(STRAIGHT_FRAMES) * CONFIG.frame_period, poses)


@pytest.mark.parametrize("name", sorted(NOISE_PROFILES))
def test_each_noise_term_of_each_profile(straight: Trajectory, name: str) -> None:
    """Every term of every profile has its configured spread and its configured bias, and no other noise appears."""
    profile = NOISE_PROFILES[name]
    true_linear, true_angular = body_velocities(straight.poses, straight.timestamps)
    linear, angular = noisy_odometry(straight, profile, np.random.default_rng(11))
    terms = {  # error with the configured bias removed, configured std
        "speed": (linear[1:, 0] - true_linear[1:, 0] * (1 + profile.speed_scale_bias), profile.sigma_speed),
        "sideways speed": (linear[1:, 1] - true_linear[1:, 1], 0.0),
        "vertical speed": (linear[1:, 2] - true_linear[1:, 2], profile.sigma_vertical_speed),
        "roll rate": (angular[1:, 0] - true_angular[1:, 0], 0.0),
        "pitch rate": (angular[1:, 1] - true_angular[1:, 1], profile.sigma_pitch_rate),
        "yaw rate": (angular[1:, 2] - true_angular[1:, 2] - profile.yaw_rate_bias, profile.sigma_yaw_rate),
    }
    for term, (error, sigma) in terms.items():
        assert np.std(error) == pytest.approx(sigma, rel=0.05, abs=1e-9), term  # 10 standard errors
        standard_error = sigma / np.sqrt(len(error))
        assert abs(np.mean(error)) <= 5 * standard_error + 1e-9, term  # no bias left: vo's yaw bias is 14 s.e.


@pytest.mark.parametrize("name", sorted(NOISE_PROFILES))
def test_yaw_rate_bias_of_each_profile_exactly(straight: Trajectory, name: str) -> None:
    """The same draws with and without the profile's bias differ by exactly the bias, of its sign (heavy's yaw-rate
    noise is 100 times its bias: no mean over a drive could tell the bias from none, or from its opposite)."""
    profile = NOISE_PROFILES[name]
    _, biased = noisy_odometry(straight, profile, np.random.default_rng(5))
    _, unbiased = noisy_odometry(straight, profile.model_copy(update={"yaw_rate_bias": 0.0}), np.random.default_rng(5))
    np.testing.assert_allclose(biased[1:, 2] - unbiased[1:, 2], profile.yaw_rate_bias, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(biased[1:, :2], unbiased[1:, :2])
    assert NOISE_PROFILES["vo"].yaw_rate_bias == NOISE_PROFILES["heavy"].yaw_rate_bias == 0.001  # docs/formats.md
