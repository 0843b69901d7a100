"""ATE / RPE / association cross-checked with evo on real KITTI ground truth, plus known-answer tests.

Only the comparisons need evo (a test dependency): without it they skip, and fail under NEOSLAM_REQUIRE_DATA=1 (CI),
where a missing oracle must not pass silently; the known-answer tests run either way."""

from __future__ import annotations

import copy
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.evaluation import (
    absolute_trajectory_error,
    align,
    associate,
    kitti_drift,
    relative_pose_error,
)
from neoslam.geometry import make_pose
from neoslam.types import Trajectory

FRAME_PERIOD_S = 0.1
# docs/evaluation.md's claim: better than 1e-12 relative (measured: statistics within 2.4e-13, each error within 5e-13).
RELATIVE_AGREEMENT = 1e-12
ABSOLUTE_AGREEMENT = 1e-12  # m or degrees, for errors near zero (one-frame RPE)
STEP_NOISE_M = 0.03
STEP_NOISE_RAD = 2e-3
STATISTICS = ("rmse", "mean", "median", "max")


def load_kitti_poses(path: Path) -> np.ndarray:
    rows = np.loadtxt(path).reshape(-1, 3, 4)
    bottom = np.tile([0.0, 0.0, 0.0, 1.0], (len(rows), 1, 1))
    return np.concatenate([rows, bottom], axis=1)


def as_trajectory(poses: np.ndarray, period: float = FRAME_PERIOD_S) -> Trajectory:
    return Trajectory(np.arange(len(poses)) * period, poses)


def noisy_estimate(gt: np.ndarray, seed: int) -> np.ndarray:
    """Integrate the ground-truth steps with noise, then move the whole estimate by a rigid offset."""
    rng = np.random.default_rng(seed)
    steps = np.linalg.inv(gt[:-1]) @ gt[1:]
    noise = np.stack(
        [
            make_pose(Rotation.from_rotvec(rng.normal(0, STEP_NOISE_RAD, 3)), rng.normal(0, STEP_NOISE_M, 3))
            for _ in range(len(steps))
        ]
    )
    est = [gt[0]]
    for step in steps @ noise:
        est.append(est[-1] @ step)
    offset = make_pose(Rotation.from_euler("zyx", [0.7, -0.2, 0.3]), np.array([12.0, -5.0, 3.0]))
    return offset @ np.stack(est)


@pytest.fixture(scope="module")
def evo() -> SimpleNamespace:
    """evo's metrics, sync and trajectory modules: the oracle of the comparisons."""
    try:
        from evo.core import metrics, sync, trajectory
    except ImportError as error:
        reason = f"evo is not importable ({error}): the comparisons with evo cannot run"
        if os.environ.get("NEOSLAM_REQUIRE_DATA") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    return SimpleNamespace(metrics=metrics, sync=sync, trajectory=trajectory)


@pytest.fixture(scope="module")
def kitti_pair(kitti_poses):
    cache: dict[str, tuple[Trajectory, Trajectory]] = {}

    def _pair(sequence: str) -> tuple[Trajectory, Trajectory]:
        if sequence not in cache:
            gt = load_kitti_poses(kitti_poses(sequence))
            cache[sequence] = (as_trajectory(noisy_estimate(gt, seed=int(sequence))), as_trajectory(gt))
        return cache[sequence]

    return _pair


def to_evo(evo: SimpleNamespace, traj: Trajectory):
    return evo.trajectory.PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=traj.timestamps.copy())


def assert_agrees(evo: SimpleNamespace, ours, evo_metric) -> None:
    for name in STATISTICS:
        expected = evo_metric.get_statistic(evo.metrics.StatisticsType(name))
        assert getattr(ours, name) == pytest.approx(expected, rel=RELATIVE_AGREEMENT, abs=0), name
    np.testing.assert_allclose(ours.errors, evo_metric.error, rtol=RELATIVE_AGREEMENT, atol=ABSOLUTE_AGREEMENT)


@pytest.mark.parametrize("sequence", ["05", "00"])
@pytest.mark.parametrize("mode", ["se3", "sim3", "none"])
def test_ate_matches_evo(evo, kitti_pair, sequence, mode):
    est, ref = kitti_pair(sequence)
    evo_est, evo_ref = to_evo(evo, est), to_evo(evo, ref)
    if mode != "none":
        evo_est.align(evo_ref, correct_scale=mode == "sim3")
    ape = evo.metrics.APE(evo.metrics.PoseRelation.translation_part)
    ape.process_data((evo_ref, evo_est))
    assert_agrees(evo, absolute_trajectory_error(est, ref, align=mode), ape)


@pytest.mark.slow
@pytest.mark.parametrize("sequence", ["05", "00"])
@pytest.mark.parametrize(("delta", "unit"), [(1, "frames"), (10, "frames"), (100.0, "m")])
def test_rpe_matches_evo(evo, kitti_pair, sequence, delta, unit):
    est, ref = kitti_pair(sequence)
    ours = relative_pose_error(est, ref, delta=delta, unit=unit)
    evo_unit = evo.metrics.Unit.frames if unit == "frames" else evo.metrics.Unit.meters
    for relation, stats in [
        (evo.metrics.PoseRelation.translation_part, ours.translation),
        (evo.metrics.PoseRelation.rotation_angle_deg, ours.rotation),
    ]:
        rpe = evo.metrics.RPE(relation, delta, evo_unit, all_pairs=False, pairs_from_reference=True)
        rpe.process_data((to_evo(evo, ref), to_evo(evo, est)))
        assert len(stats.errors) == len(rpe.error)
        assert_agrees(evo, stats, rpe)


def jittered_stamps(rng, n: int, period: float, jitter: float, keep: float) -> np.ndarray:
    stamps = np.arange(n) * period + rng.uniform(-jitter, jitter, n)
    return np.sort(stamps[rng.random(n) < keep])


@pytest.mark.parametrize(
    ("est_period", "offset"),
    [(FRAME_PERIOD_S, 0.0), (FRAME_PERIOD_S / 2, 0.0), (FRAME_PERIOD_S, 0.3), (FRAME_PERIOD_S / 2, -0.2)],
)
def test_associate_matches_evo(evo, est_period, offset):
    rng = np.random.default_rng(7)
    ref_stamps = 1000.0 + jittered_stamps(rng, 400, FRAME_PERIOD_S, 0.002, keep=0.9)
    est_stamps = 1000.0 - offset + jittered_stamps(rng, int(40 / est_period), est_period, 0.008, keep=0.8)
    ref = Trajectory(ref_stamps, np.tile(np.eye(4), (len(ref_stamps), 1, 1)))
    est = Trajectory(est_stamps, np.tile(np.eye(4), (len(est_stamps), 1, 1)))
    ref.poses[:, 0, 3] = np.arange(len(ref))
    est.poses[:, 0, 3] = np.arange(len(est))
    evo_ref, evo_est = evo.sync.associate_trajectories(
        to_evo(evo, ref), to_evo(evo, est), max_diff=0.01, offset_2=offset
    )
    est_sync, ref_sync = associate(est, ref, max_time_diff=0.01, offset=offset)
    assert 0 < len(est_sync) < min(len(est), len(ref))
    np.testing.assert_array_equal(est_sync.timestamps, evo_est.timestamps)
    np.testing.assert_array_equal(ref_sync.timestamps, evo_ref.timestamps)
    np.testing.assert_array_equal(est_sync.positions, evo_est.positions_xyz)
    np.testing.assert_array_equal(ref_sync.positions, evo_ref.positions_xyz)


def test_associate_uses_each_stamp_once_and_rejects_disjoint_stamps():
    poses = np.tile(np.eye(4), (3, 1, 1))
    est = Trajectory(np.array([0.0, 0.02]), poses[:2])
    ref = Trajectory(np.array([0.01, 1.0, 2.0]), poses)
    est_sync, ref_sync = associate(est, ref, max_time_diff=0.05)
    np.testing.assert_array_equal(est_sync.timestamps, [0.0])  # 0.0 and 0.02 tie on 0.01: the earlier wins
    np.testing.assert_array_equal(ref_sync.timestamps, [0.01])
    with pytest.raises(ValueError, match="no matching timestamps"):
        associate(est, Trajectory(ref.timestamps + 10.0, poses))


def straight_line(n: int, step_m: float = 1.0) -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n) * step_m
    return as_trajectory(poses)


def test_identical_trajectories_have_zero_errors(kitti_pair):
    _, ref = kitti_pair("05")
    for mode in ("se3", "sim3", "none"):
        assert absolute_trajectory_error(ref, ref, align=mode).max < 1e-9
    for delta, unit in [(1, "frames"), (100.0, "m")]:
        rpe = relative_pose_error(ref, ref, delta, unit)
        assert rpe.translation.max < 1e-9
        assert rpe.rotation.max < 1e-6
    drift = kitti_drift(ref, ref)
    assert drift.translation_percent < 1e-9
    assert drift.rotation_deg_per_100m < 1e-4
    assert sorted(drift.per_length) == [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0]


def test_rigid_offset_vanishes_with_se3_and_shows_without_alignment(kitti_pair):
    _, ref = kitti_pair("05")
    offset = make_pose(Rotation.from_euler("z", 0.4), np.array([3.0, 4.0, 0.0]))
    moved = Trajectory(ref.timestamps, offset @ ref.poses)
    aligned, transform = align(moved, ref, "se3")
    np.testing.assert_allclose(transform.as_matrix() @ offset, np.eye(4), atol=1e-9)
    np.testing.assert_allclose(aligned.poses, ref.poses, atol=1e-8)
    assert absolute_trajectory_error(moved, ref, align="se3").rmse < 1e-8
    shifted = Trajectory(ref.timestamps, make_pose(np.eye(3), np.array([3.0, 4.0, 0.0])) @ ref.poses)
    ate = absolute_trajectory_error(shifted, ref, align="none")
    np.testing.assert_allclose(ate.errors, 5.0)
    assert relative_pose_error(moved, ref).translation.max < 1e-9  # RPE ignores the world frame


def test_uniform_scale_vanishes_with_sim3_only(kitti_pair):
    _, ref = kitti_pair("05")
    scaled_poses = ref.poses.copy()
    scaled_poses[:, :3, 3] *= 0.5
    scaled = Trajectory(ref.timestamps, scaled_poses)
    aligned, transform = align(scaled, ref, "sim3")
    assert transform.scale == pytest.approx(2.0)
    assert absolute_trajectory_error(scaled, ref, align="sim3").max < 1e-8
    assert absolute_trajectory_error(scaled, ref, align="se3").rmse > 10.0


def test_kitti_drift_of_a_one_percent_scale_error(kitti_pair):
    _, ref = kitti_pair("05")
    scaled_poses = ref.poses.copy()
    scaled_poses[:, :3, 3] *= 1.01
    drift = kitti_drift(Trajectory(ref.timestamps, scaled_poses), ref)
    # A scale error s makes each segment's end-point error s * chord, and the devkit divides by the path length:
    # exactly 1 % only for straight segments; KITTI 05's turns bring the all-segment average down to ~0.58 %.
    chords = np.array(
        [
            np.linalg.norm(ref.positions[ref_end] - ref.positions[first])
            for first, ref_end in zip(drift.first_frames, _segment_ends(ref, drift), strict=True)
        ]
    )
    np.testing.assert_allclose(drift.translation_errors_percent, 1.0 * chords / drift.lengths, rtol=1e-6)
    assert drift.per_length[100.0][0] == pytest.approx(1.0, abs=0.1)
    assert 0.5 < drift.translation_percent < 1.0
    assert drift.rotation_deg_per_100m < 1e-4
    assert len(drift.first_frames) > 1000


def _segment_ends(ref: Trajectory, drift) -> np.ndarray:
    """Brute-force devkit rule: the first frame whose path distance exceeds the start's by the length."""
    distance = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ref.positions, axis=0), axis=1))])
    starts = zip(drift.first_frames, drift.lengths, strict=True)
    return np.array([np.flatnonzero(distance > distance[f] + length)[0] for f, length in starts])


def test_kitti_drift_known_answer_on_a_straight_line():
    ref = straight_line(1000)
    est_poses = ref.poses.copy()
    est_poses[:, :3, 3] *= 1.02
    drift = kitti_drift(Trajectory(ref.timestamps, est_poses), ref)
    assert drift.translation_percent == pytest.approx(2.0 * 101 / 100, rel=0.02)  # ends 1 frame past length
    for length, (t_err, _) in drift.per_length.items():
        assert t_err == pytest.approx(2.0 * (length + 1) / length)
    # segment of 100 m from frame 0 ends at frame 101 (first distance strictly beyond 100 m), as the devkit
    assert drift.first_frames[0] == 0


@pytest.mark.parametrize("yaw_error_deg_per_m", [0.01, -0.03])
def test_kitti_rotational_drift_of_a_constant_yaw_rate_error_on_a_straight_line(yaw_error_deg_per_m: float):
    """The estimate drives the same 1 m steps but turns by a constant extra yaw each step (a yaw-rate bias): over a
    segment of L m, which ends L + 1 frames on (the first frame beyond L m), its rotation error is (L + 1) times the
    step's, the devkit's r_err = angle / L, reported per 100 m."""
    ref = straight_line(1000)
    turn = make_pose(Rotation.from_euler("z", yaw_error_deg_per_m, degrees=True), np.zeros(3))
    steps = np.linalg.inv(ref.poses[:-1]) @ ref.poses[1:]
    est = [ref.poses[0]]
    for step in steps:
        est.append(est[-1] @ step @ turn)
    drift = kitti_drift(Trajectory(ref.timestamps, np.stack(est)), ref)
    per_100m = abs(yaw_error_deg_per_m) * 100.0
    for length, (t_err, r_err) in drift.per_length.items():
        assert r_err == pytest.approx(per_100m * (length + 1) / length, rel=1e-9), length
        assert t_err > 0.0
    np.testing.assert_allclose(
        drift.rotation_errors_deg_per_100m, per_100m * (drift.lengths + 1) / drift.lengths, rtol=1e-9
    )
    assert drift.rotation_deg_per_100m == pytest.approx(np.mean(per_100m * (drift.lengths + 1) / drift.lengths))


def test_kitti_drift_of_a_short_trajectory_is_nan():
    ref = straight_line(50)
    drift = kitti_drift(ref, ref)
    assert np.isnan(drift.translation_percent)
    assert np.isnan(drift.rotation_deg_per_100m)
    assert drift.per_length == {}
    assert len(drift.first_frames) == 0


def test_rpe_pairs_follow_the_delta():
    ref = straight_line(25, step_m=0.5)
    rpe = relative_pose_error(ref, ref, delta=10, unit="frames")
    np.testing.assert_array_equal(rpe.pairs, [[0, 10], [10, 20]])
    rpe = relative_pose_error(ref, ref, delta=2.0, unit="m")
    np.testing.assert_array_equal(rpe.pairs[:3], [[0, 4], [4, 8], [8, 12]])


def test_invalid_inputs_raise_value_error():
    ref = straight_line(30)
    with pytest.raises(ValueError, match="associated"):
        absolute_trajectory_error(ref.subset(np.arange(10)), ref)
    with pytest.raises(ValueError, match="positive integer"):
        relative_pose_error(ref, ref, delta=1.5)
    with pytest.raises(ValueError, match="no pose pairs"):
        relative_pose_error(ref, ref, delta=1000.0, unit="m")
    with pytest.raises(ValueError, match="alignment mode"):
        align(ref, ref, "sim2")  # type: ignore[arg-type]


def test_evo_alignment_is_not_mutating_our_trajectories(kitti_pair):
    est, ref = kitti_pair("05")
    before = copy.deepcopy(est.poses)
    absolute_trajectory_error(est, ref, align="sim3")
    np.testing.assert_array_equal(est.poses, before)
