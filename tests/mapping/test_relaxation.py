"""The paper's map correction (eq. 18, NeuroSLAM's relaxation) on small graphs and on a yaw-biased square."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import make_pose, relative_pose, yaw_pitch_roll
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.relaxation import link_measurement, relax
from neoslam.types import Link, Trajectory

CORRECTION = 0.5  # NeuroSLAM's EXP_CORRECTION
PASSES = 5  # NeuroSLAM's EXP_LOOPS
CALLS = 200  # relax() calls, as if once per frame after the closure


def pose(yaw: float, translation, roll: float = 0.0, pitch: float = 0.0) -> np.ndarray:
    return make_pose(Rotation.from_euler("ZYX", [yaw, pitch, roll]), np.asarray(translation, dtype=float))


def turn_about_vertical(p: np.ndarray, angle: float) -> np.ndarray:
    """The pose turned about the world's vertical through its own position."""
    turned = p.copy()
    turned[:3, :3] = Rotation.from_euler("z", angle).as_matrix() @ p[:3, :3]
    return turned


def graph_of(poses: np.ndarray, pairs: list[tuple[int, int]], truth: np.ndarray | None = None) -> MapGraph:
    """Nodes at `poses`; links measured between the `truth` poses (default: the nodes themselves)."""
    truth = poses if truth is None else truth
    graph = MapGraph(poses=np.array(poses, dtype=float))
    for source, target in pairs:
        graph.add_link(Link(source, target, relative_pose(truth[source], truth[target]), "odometry", 1.0))
    return graph


def ate(poses: np.ndarray, truth: np.ndarray) -> float:
    stamps = np.arange(len(truth), dtype=float)
    return absolute_trajectory_error(Trajectory(stamps, poses), Trajectory(stamps, truth), "se3").rmse


# ---------------------------------------------------------------------------------------------------------------
# link_measurement


def test_link_measurement_of_a_flat_link() -> None:
    source = pose(0.7, (1.0, 2.0, 0.5))
    target = source @ pose(0.3, (2.0, 1.0, 0.25))
    graph = graph_of(np.array([source, target]), [(0, 1)])

    measured = link_measurement(graph, graph.links[0])

    assert measured[:2] == (0, 1)
    np.testing.assert_allclose(measured[2:], [2.0, 1.0, 0.25, 0.3], atol=1e-12)


@pytest.mark.parametrize("angle", [0.4, -2.0, np.pi - 0.01, 3.0])
def test_link_measurement_is_invariant_to_a_yaw_turn_of_the_source(angle: float) -> None:
    """Relaxation only turns poses about the vertical, so a measurement taken once stays valid."""
    source = pose(0.2, (1.0, -2.0, 0.3), roll=0.08, pitch=-0.12)
    relative = pose(0.9, (3.0, 1.5, -0.4), roll=-0.03, pitch=0.05)
    graph = MapGraph(poses=np.array([source, source @ relative]))
    link = Link(0, 1, relative, "odometry", 3.0)
    graph.add_link(link)
    before = link_measurement(graph, link)

    graph.poses[0] = turn_about_vertical(source, angle)
    after = link_measurement(graph, link)

    assert after[:2] == before[:2]
    np.testing.assert_allclose(after[2:], before[2:], atol=1e-12)


def test_link_measurement_of_a_sloped_source_is_in_its_yaw_frame() -> None:
    """On a slope the link's forward step climbs: dz takes the climb, dx the horizontal part; dy stays 0."""
    slope = 0.2
    source = pose(1.1, (0.0, 0.0, 0.0), pitch=-slope)  # REP-103: negative pitch = nose up
    graph = MapGraph(poses=np.array([source, source @ pose(0.0, (5.0, 0.0, 0.0))]))
    link = Link(0, 1, pose(0.0, (5.0, 0.0, 0.0)), "odometry", 5.0)
    graph.add_link(link)

    _, _, dx, dy, dz, dyaw = link_measurement(graph, link)

    np.testing.assert_allclose([dx, dy, dz, dyaw], [5 * np.cos(slope), 0.0, 5 * np.sin(slope), 0.0], atol=1e-12)


# ---------------------------------------------------------------------------------------------------------------
# relax


def test_relax_closes_a_yaw_biased_square(biased_square) -> None:
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    measurements = [link_measurement(graph, link) for link in graph.links]
    drift_ate = ate(graph.poses, truth)
    drift_gap = graph.link_residuals()[-1]

    for _ in range(CALLS):
        relax(graph, measurements, CORRECTION, PASSES)

    assert drift_gap > 1.0  # dead reckoning did not close
    assert graph.link_residuals()[-1] < 0.01
    assert graph.link_residuals().max() < 0.01
    assert ate(graph.poses, truth) < drift_ate / 10


def test_relaxation_goes_on_improving_with_more_calls(biased_square) -> None:
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    measurements = [link_measurement(graph, link) for link in graph.links]
    errors = [ate(graph.poses, truth)]
    for _ in range(4):
        for _ in range(CALLS // 4):
            relax(graph, measurements, CORRECTION, PASSES)
        errors.append(ate(graph.poses, truth))
    assert all(later < earlier for earlier, later in zip(errors, errors[1:], strict=False))


def test_relax_without_links_or_passes_leaves_the_poses(biased_square) -> None:
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    measurements = [link_measurement(graph, link) for link in graph.links]
    before = graph.poses.copy()

    relax(graph, [], CORRECTION, PASSES)
    np.testing.assert_array_equal(graph.poses, before)
    relax(graph, measurements, CORRECTION, 0)
    np.testing.assert_array_equal(graph.poses, before)


def test_relax_of_consistent_links_leaves_the_poses() -> None:
    poses = np.array([pose(0.0, (0, 0, 0)), pose(0.5, (2, 0.5, 0.1)), pose(2.0, (3, 2, 0.3)), pose(3.0, (1, 3, 0))])
    graph = graph_of(poses, [(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)])
    measurements = [link_measurement(graph, link) for link in graph.links]

    relax(graph, measurements, CORRECTION, PASSES)

    np.testing.assert_allclose(graph.poses, poses, atol=1e-9)


def test_relax_corrects_in_place(biased_square) -> None:
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    poses = graph.poses
    relax(graph, [link_measurement(graph, link) for link in graph.links], CORRECTION, PASSES)
    assert graph.poses is poses


def test_relax_preserves_roll_and_pitch() -> None:
    """Only x, y, z and yaw are relaxed (NeuroSLAM's 4 degrees of freedom); roll and pitch stay as odometry gave."""
    rng = np.random.default_rng(3)
    count = 12
    angles = rng.uniform(-0.2, 0.2, size=(count, 2))
    truth = np.array([pose(0.4 * k, (3.0 * k, np.sin(k), 0.2 * k), roll=r, pitch=p) for k, (r, p) in enumerate(angles)])
    drifted = truth.copy()
    for k in range(1, count):  # a growing yaw and position error
        drifted[k] = turn_about_vertical(truth[k], 0.05 * k)
        drifted[k, :3, 3] += [0.1 * k, -0.05 * k, 0.02 * k]
    pairs = [(k, k + 1) for k in range(count - 1)] + [(count - 1, 0), (5, 1)]
    graph = graph_of(drifted, pairs, truth=truth)
    measurements = [link_measurement(graph, link) for link in graph.links]
    before = yaw_pitch_roll(graph.poses)

    for _ in range(20):
        relax(graph, measurements, CORRECTION, PASSES)

    after = yaw_pitch_roll(graph.poses)
    assert np.abs(after[:, 0] - before[:, 0]).max() > 0.01  # yaws were corrected...
    np.testing.assert_allclose(after[:, 1:], before[:, 1:], atol=1e-9)  # ...pitch and roll were not
    rotations = graph.poses[:, :3, :3]
    np.testing.assert_allclose(rotations @ np.swapaxes(rotations, 1, 2), np.tile(np.eye(3), (count, 1, 1)), atol=1e-9)


# A path curving left; every link but the first has a sideways (left, +y) component in its source's frame.
LEFT_CURVE = np.array(
    [pose(0.0, (0.0, 0.0, 0.0)), pose(0.5, (4.0, 1.0, 0.0)), pose(1.2, (6.0, 4.0, 0.5)), pose(1.6, (6.5, 8.0, 0.5))]
)
LEFT_CURVE_LINKS = [(0, 1), (1, 2), (2, 3), (0, 3)]


def test_a_consistent_left_curve_is_not_pulled_towards_its_mirror_image() -> None:
    """Guard against NeuroSLAM's quirk 1 (link heading stored y-mirrored, so every sweep pulls the map towards
    the mirrored path): relaxing a map that agrees with its links must leave it where it is."""
    graph = graph_of(LEFT_CURVE, LEFT_CURVE_LINKS)
    measurements = [link_measurement(graph, link) for link in graph.links]
    assert all(dy > 0.5 for _, _, _, dy, _, _ in measurements[1:])  # the links do turn left

    for _ in range(50):
        relax(graph, measurements, CORRECTION, PASSES)

    np.testing.assert_allclose(graph.poses, LEFT_CURVE, atol=1e-9)


def test_a_perturbed_left_curve_relaxes_back_to_a_left_curve() -> None:
    perturbed = LEFT_CURVE.copy()
    perturbed[1] = turn_about_vertical(perturbed[1], -0.3)
    perturbed[2, :3, 3] = [7.0, 1.0, 0.0]  # pulled off to the right
    perturbed[3, :3, 3] = [9.0, 3.0, 1.0]
    graph = graph_of(perturbed, LEFT_CURVE_LINKS, truth=LEFT_CURVE)
    measurements = [link_measurement(graph, link) for link in graph.links]

    for _ in range(200):
        relax(graph, measurements, CORRECTION, PASSES)

    np.testing.assert_allclose(graph.link_residuals(), 0.0, atol=1e-6)
    for k in range(1, 4):  # the shape of the truth, up to where the whole map sits
        np.testing.assert_allclose(
            relative_pose(graph.poses[0], graph.poses[k]), relative_pose(LEFT_CURVE[0], LEFT_CURVE[k]), atol=1e-6
        )
    assert relative_pose(graph.poses[0], graph.poses[3])[1, 3] > 5.0  # the end is to the left of the start


def test_relaxation_keeps_the_centroid(biased_square) -> None:
    """Each correction moves the two ends of a link by equal and opposite amounts: the map does not slide."""
    truth = biased_square.truth()
    graph = biased_square.graph(truth, [biased_square.loop(truth, biased_square.lap - 1, 0)])
    measurements = [link_measurement(graph, link) for link in graph.links]
    centroid = graph.poses[:, :3, 3].mean(axis=0)

    for _ in range(10):
        relax(graph, measurements, CORRECTION, PASSES)

    np.testing.assert_allclose(graph.poses[:, :3, 3].mean(axis=0), centroid, atol=1e-9)
