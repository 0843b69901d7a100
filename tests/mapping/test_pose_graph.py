"""Pose-graph back end on synthetic squares whose odometry has a constant yaw bias, so dead reckoning does not close."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import ExperienceMapConfig
from neoslam.geometry import make_pose, relative_pose
from neoslam.mapping.graph import Link, MapGraph
from neoslam.mapping.pose_graph import ROLL_PITCH_SIGMA_RAD, link_sigmas, optimise_pose_graph

SIDE_NODES = 25  # nodes along each side of the square
STEP_M = 1.0
LAP = 4 * SIDE_NODES
YAW_BIAS_RAD = 0.002  # per odometry step: 0.2 rad (11 degrees) over one lap
WRONG_OFFSET_M = 20.0
# An odometry model honest about the bias above (0.2 sigma per step), so a true closure is cheap to accept.
# Odometry loose enough to explain the simulated drift, a Cauchy kernel at one sigma on loop links.
HONEST = ExperienceMapConfig(
    odometry_yaw_sigma_per_root_metre=0.01 * np.sqrt(STEP_M),
    odometry_sigma_per_root_metre=0.05 * np.sqrt(STEP_M),
    robust_kernel="cauchy",
    robust_threshold=1.0,
)


def yaw_pose(yaw: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    return make_pose(Rotation.from_euler("z", yaw), np.asarray(translation, dtype=float))


def square_truth(laps: int = 1, start: np.ndarray | None = None) -> np.ndarray:
    """True poses driving `laps` times around a square, turning left 90 degrees after each side."""
    one_lap = []
    position, yaw = np.zeros(3), 0.0
    for _ in range(4):
        for _ in range(SIDE_NODES):
            one_lap.append(yaw_pose(yaw, position))
            position = position + STEP_M * np.array([np.cos(yaw), np.sin(yaw), 0.0])
        yaw += np.pi / 2
    poses = np.array(one_lap * laps)
    return poses if start is None else start @ poses


def biased_graph(truth: np.ndarray, loops: list[tuple[int, int, np.ndarray]]) -> MapGraph:
    """Nodes at the dead-reckoned poses of yaw-biased odometry, odometry links, then the given loop links."""
    measured = relative_pose(truth[:-1], truth[1:]) @ yaw_pose(YAW_BIAS_RAD)
    graph = MapGraph(poses=truth[:1].copy())
    for index, step in enumerate(measured):
        graph.add_node(graph.poses[-1] @ step)
        graph.add_link(Link(index, index + 1, step, "odometry", float(np.linalg.norm(step[:3, 3]))))
    for source, target, relative in loops:
        graph.add_link(Link(source, target, relative, "loop", 0.0))
    return graph


def true_loop(truth: np.ndarray, source: int, target: int) -> tuple[int, int, np.ndarray]:
    return source, target, relative_pose(truth[source], truth[target])


def ate(graph: MapGraph, truth: np.ndarray) -> float:
    """RMS position error without alignment: node 0 anchors both in the same world frame."""
    return float(np.sqrt(np.mean(np.sum((graph.poses[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))


def two_laps_with_loops(wrong: bool) -> tuple[MapGraph, np.ndarray, int]:
    """Two laps, good closures from lap 2 onto lap 1 and optionally one wrong closure; returns its link index."""
    truth = square_truth(laps=2)
    loops = [true_loop(truth, source, source - LAP) for source in (110, 135, 160, 185, 199)]
    if wrong:
        source, target, relative = true_loop(truth, 140, 40)
        loops.append((source, target, relative @ make_pose(np.eye(3), [0.0, WRONG_OFFSET_M, 0.0])))
    graph = biased_graph(truth, loops)
    return graph, truth, len(graph.links) - 1


def test_one_true_loop_link_closes_a_biased_square():
    truth = square_truth()
    graph = biased_graph(truth, [true_loop(truth, LAP - 1, 0)])
    poses = graph.poses
    drift_end = np.linalg.norm(graph.poses[-1, :3, 3] - truth[-1, :3, 3])
    drift_ate = ate(graph, truth)

    report = optimise_pose_graph(graph, HONEST)

    assert graph.poses is poses  # corrected in place
    assert drift_end > 1.0  # dead reckoning did not close
    assert np.linalg.norm(graph.poses[-1, :3, 3] - truth[-1, :3, 3]) < 0.05
    assert ate(graph, truth) < drift_ate / 10
    assert report.final_error < report.initial_error
    assert report.outlier_links == ()
    assert report.loops[0].link_index == LAP - 1


def test_robust_kernel_ignores_a_wrong_loop_link():
    good_only, truth, _ = two_laps_with_loops(wrong=False)
    optimise_pose_graph(good_only, HONEST)
    robust, _, wrong_index = two_laps_with_loops(wrong=True)
    report = optimise_pose_graph(robust, HONEST)
    plain, _, _ = two_laps_with_loops(wrong=True)
    optimise_pose_graph(plain, HONEST.model_copy(update={"robust_kernel": "none"}))

    def gap(graph: MapGraph) -> float:
        return float(np.abs(graph.poses[:, :3, 3] - good_only.poses[:, :3, 3]).max())

    assert gap(robust) < 0.05
    assert gap(plain) > 1.0
    assert ate(plain, truth) > 3 * ate(robust, truth)
    assert report.outlier_links == (wrong_index,)
    assert report.loops[-1].kernel_weight < 0.01


def test_huber_bounds_a_wrong_loop_links_pull():
    good_only, _, _ = two_laps_with_loops(wrong=False)
    huber = HONEST.model_copy(update={"robust_kernel": "huber"})
    optimise_pose_graph(good_only, huber)
    robust, _, _ = two_laps_with_loops(wrong=True)
    optimise_pose_graph(robust, huber)
    plain, _, _ = two_laps_with_loops(wrong=True)
    optimise_pose_graph(plain, HONEST.model_copy(update={"robust_kernel": "none"}))

    def gap(graph: MapGraph) -> float:
        return float(np.abs(graph.poses[:, :3, 3] - good_only.poses[:, :3, 3]).max())

    assert gap(robust) < gap(plain) / 10


def test_odometry_only_graph_is_left_as_it_is():
    truth = square_truth()
    graph = biased_graph(truth, [])
    before = graph.poses.copy()

    report = optimise_pose_graph(graph, HONEST)

    np.testing.assert_allclose(graph.poses, before, atol=1e-6)
    assert report.loops == ()


def test_optimisation_is_deterministic():
    first, _, _ = two_laps_with_loops(wrong=True)
    second, _, _ = two_laps_with_loops(wrong=True)

    assert optimise_pose_graph(first, HONEST) == optimise_pose_graph(second, HONEST)
    assert np.array_equal(first.poses, second.poses)


def test_node_zero_anchors_the_map():
    start = yaw_pose(0.7, (5.0, -3.0, 1.0))
    truth = square_truth(start=start)
    graph = biased_graph(truth, [true_loop(truth, LAP - 1, 0)])

    optimise_pose_graph(graph, HONEST)

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
def test_trivial_graphs_are_left_as_they_are(count):
    graph = MapGraph(poses=np.tile(yaw_pose(0.3, (1.0, 2.0, 3.0)), (count, 1, 1)))
    before = graph.poses.copy()

    report = optimise_pose_graph(graph, HONEST)

    np.testing.assert_allclose(graph.poses, before, atol=1e-9)
    assert report.loops == ()


def test_a_yaw_only_disagreement_is_weighed_by_the_yaw_sigma():
    """A loop link one yaw sigma off a stiff standstill link keeps (almost) all of it: about 1 sigma of residual."""
    config = HONEST.model_copy(update={"robust_kernel": "none"})
    graph = MapGraph(poses=np.tile(np.eye(4), (2, 1, 1)))
    graph.add_link(Link(0, 1, np.eye(4), "odometry", 0.0))
    graph.add_link(Link(0, 1, yaw_pose(config.loop_yaw_sigma), "loop", 0.0))

    report = optimise_pose_graph(graph, config)

    assert report.loops[0].sigmas == pytest.approx(1.0, abs=0.01)
