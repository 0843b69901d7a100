"""Pose-graph back end on synthetic squares whose odometry has a constant yaw bias, so dead reckoning does not close."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import ExperienceMapConfig
from neoslam.geometry import make_pose
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.pose_graph import ROLL_PITCH_SIGMA_RAD, link_sigmas, optimise_pose_graph
from neoslam.types import Link

WRONG_OFFSET_M = 20.0


@pytest.fixture(scope="module")
def honest(biased_square) -> ExperienceMapConfig:
    """An odometry model honest about the square's yaw bias (0.2 sigma per step), so a true closure is cheap to
    accept: odometry loose enough to explain the simulated drift, a Cauchy kernel at one sigma on loop links."""
    return ExperienceMapConfig(
        odometry_yaw_sigma_per_root_metre=0.01 * np.sqrt(biased_square.step_m),
        odometry_sigma_per_root_metre=0.05 * np.sqrt(biased_square.step_m),
        robust_kernel="cauchy",
        robust_threshold=1.0,
    )


def yaw_pose(yaw: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.asarray(translation, dtype=float))


def ate(graph: MapGraph, truth: np.ndarray) -> float:
    """RMS position error without alignment: node 0 anchors both in the same world frame."""
    return float(np.sqrt(np.mean(np.sum((graph.poses[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))


def two_laps_with_loops(square, wrong: bool) -> tuple[MapGraph, np.ndarray, int]:
    """Two laps, good closures from lap 2 onto lap 1 and optionally one wrong closure; returns its link index."""
    truth = square.truth(laps=2)
    loops = [square.loop(truth, source, source - square.lap) for source in (110, 135, 160, 185, 199)]
    if wrong:
        source, target, relative = square.loop(truth, 140, 40)
        loops.append((source, target, relative @ make_pose(np.eye(3), [0.0, WRONG_OFFSET_M, 0.0])))
    graph = square.graph(truth, loops)
    return graph, truth, len(graph.links) - 1


def test_one_true_loop_link_closes_a_biased_square(biased_square, honest):
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    poses = graph.poses
    drift_end = np.linalg.norm(graph.poses[-1, :3, 3] - truth[-1, :3, 3])
    drift_ate = ate(graph, truth)

    report = optimise_pose_graph(graph, honest)

    assert graph.poses is poses  # corrected in place
    assert drift_end > 1.0  # dead reckoning did not close
    assert np.linalg.norm(graph.poses[-1, :3, 3] - truth[-1, :3, 3]) < 0.05
    assert ate(graph, truth) < drift_ate / 10
    assert report.final_error < report.initial_error
    assert report.outlier_links == ()
    assert report.loops[0].link_index == biased_square.lap - 1


def test_robust_kernel_ignores_a_wrong_loop_link(biased_square, honest):
    good_only, truth, _ = two_laps_with_loops(biased_square, wrong=False)
    optimise_pose_graph(good_only, honest)
    robust, _, wrong_index = two_laps_with_loops(biased_square, wrong=True)
    report = optimise_pose_graph(robust, honest)
    plain, _, _ = two_laps_with_loops(biased_square, wrong=True)
    optimise_pose_graph(plain, honest.model_copy(update={"robust_kernel": "none"}))

    def gap(graph: MapGraph) -> float:
        return float(np.abs(graph.poses[:, :3, 3] - good_only.poses[:, :3, 3]).max())

    assert gap(robust) < 0.05
    assert gap(plain) > 1.0
    assert ate(plain, truth) > 3 * ate(robust, truth)
    assert report.outlier_links == (wrong_index,)
    assert report.loops[-1].kernel_weight < 0.01


def test_huber_bounds_a_wrong_loop_links_pull(biased_square, honest):
    good_only, _, _ = two_laps_with_loops(biased_square, wrong=False)
    huber = honest.model_copy(update={"robust_kernel": "huber"})
    optimise_pose_graph(good_only, huber)
    robust, _, _ = two_laps_with_loops(biased_square, wrong=True)
    optimise_pose_graph(robust, huber)
    plain, _, _ = two_laps_with_loops(biased_square, wrong=True)
    optimise_pose_graph(plain, honest.model_copy(update={"robust_kernel": "none"}))

    def gap(graph: MapGraph) -> float:
        return float(np.abs(graph.poses[:, :3, 3] - good_only.poses[:, :3, 3]).max())

    assert gap(robust) < gap(plain) / 10


def test_odometry_only_graph_is_left_as_it_is(biased_square, honest):
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [])
    before = graph.poses.copy()

    report = optimise_pose_graph(graph, honest)

    np.testing.assert_allclose(graph.poses, before, atol=1e-6)
    assert report.loops == ()


def test_optimisation_is_deterministic(biased_square, honest):
    first, _, _ = two_laps_with_loops(biased_square, wrong=True)
    second, _, _ = two_laps_with_loops(biased_square, wrong=True)

    assert optimise_pose_graph(first, honest) == optimise_pose_graph(second, honest)
    assert np.array_equal(first.poses, second.poses)


def test_node_zero_anchors_the_map(biased_square, honest):
    start = yaw_pose(0.7, (5.0, -3.0, 1.0))
    truth = biased_square.truth(start=start)
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])

    optimise_pose_graph(graph, honest)

    np.testing.assert_allclose(graph.poses[0], start, atol=1e-9)
    assert np.linalg.norm(graph.poses[-1, :3, 3] - truth[-1, :3, 3]) < 0.05


def test_link_sigmas_follow_gtsam_tangent_order():
    """Rotation (roll, pitch, yaw) first, then translation; odometry grows with distance, above its floors."""
    config = ExperienceMapConfig()
    long_step = Link(0, 1, np.eye(4), "odometry", 10.0)
    standstill = Link(0, 1, np.eye(4), "odometry", 0.0)
    loop = Link(1, 0, np.eye(4), "loop", 0.0)

    np.testing.assert_allclose(
        link_sigmas(long_step, config),
        [ROLL_PITCH_SIGMA_RAD, ROLL_PITCH_SIGMA_RAD, np.sqrt(10) * config.odometry_yaw_sigma_per_root_metre]
        + [np.sqrt(10) * config.odometry_sigma_per_root_metre] * 3,
    )
    assert np.all(link_sigmas(standstill, config)[3:] == config.odometry_sigma_floor)
    assert link_sigmas(standstill, config)[2] > 0
    np.testing.assert_allclose(
        link_sigmas(loop, config), [ROLL_PITCH_SIGMA_RAD] * 2 + [config.loop_yaw_sigma] + [config.loop_sigma] * 3
    )


@pytest.mark.parametrize("count", [0, 1])
def test_trivial_graphs_are_left_as_they_are(count, honest):
    graph = MapGraph(poses=np.tile(yaw_pose(0.3, (1.0, 2.0, 3.0)), (count, 1, 1)))
    before = graph.poses.copy()

    report = optimise_pose_graph(graph, honest)

    np.testing.assert_allclose(graph.poses, before, atol=1e-9)
    assert report.loops == ()


def test_a_yaw_only_disagreement_is_weighed_by_the_yaw_sigma(honest):
    """A loop link one yaw sigma off a stiff standstill link keeps (almost) all of it: about 1 sigma of residual."""
    config = honest.model_copy(update={"robust_kernel": "none"})
    graph = MapGraph(poses=np.tile(np.eye(4), (2, 1, 1)))
    graph.add_link(Link(0, 1, np.eye(4), "odometry", 0.0))
    graph.add_link(Link(0, 1, yaw_pose(config.loop_yaw_sigma), "loop", 0.0))

    report = optimise_pose_graph(graph, config)

    assert report.loops[0].sigmas == pytest.approx(1.0, abs=0.01)
