"""MapGraph: nodes are experience poses, links relative poses between them; residuals say how far a link is off."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.geometry import invert_pose, make_pose, relative_pose
from neoslam.mapping.graph import MapGraph
from neoslam.types import Link


def pose(yaw: float, translation, roll: float = 0.0, pitch: float = 0.0) -> np.ndarray:
    return make_pose(Rotation.from_euler("ZYX", [yaw, pitch, roll]), np.asarray(translation, dtype=float))


POSES = np.array(
    [
        pose(0.0, (0.0, 0.0, 0.0)),
        pose(0.5, (2.0, 1.0, 0.2), roll=0.05),
        pose(1.4, (3.0, 4.0, -0.3), pitch=-0.1),
    ]
)


def consistent_graph() -> MapGraph:
    graph = MapGraph()
    for p in POSES:
        graph.add_node(p)
    for source, target in ((0, 1), (1, 2)):
        graph.add_link(Link(source, target, relative_pose(POSES[source], POSES[target]), "odometry", 2.0))
    graph.add_link(Link(2, 0, relative_pose(POSES[2], POSES[0]), "loop", 0.0))
    return graph


def test_add_node_returns_consecutive_indices_and_copies_nothing_shared() -> None:
    graph = MapGraph()
    assert len(graph) == 0
    first = POSES[0].copy()
    assert graph.add_node(first) == 0
    assert graph.add_node(POSES[1]) == 1
    first[0, 3] = 99.0  # the caller's array changing later does not move the node
    assert len(graph) == 2
    assert graph.poses.shape == (2, 4, 4)
    np.testing.assert_array_equal(graph.poses, POSES[:2])


def test_add_link_keeps_links_in_order() -> None:
    graph = consistent_graph()
    assert [(k.source, k.target, k.kind) for k in graph.links] == [
        (0, 1, "odometry"),
        (1, 2, "odometry"),
        (2, 0, "loop"),
    ]


@pytest.mark.parametrize(("source", "target"), [(0, 3), (3, 0), (-1, 0), (0, -1), (5, 7)])
def test_a_link_to_a_missing_node_raises(source: int, target: int) -> None:
    graph = consistent_graph()
    before = list(graph.links)
    with pytest.raises(IndexError):
        graph.add_link(Link(source, target, np.eye(4), "loop", 0.0))
    assert graph.links == before


def test_a_link_on_an_empty_graph_raises() -> None:
    with pytest.raises(IndexError):
        MapGraph().add_link(Link(0, 0, np.eye(4), "odometry", 0.0))


def test_residuals_are_zero_for_consistent_links() -> None:
    graph = consistent_graph()
    residuals = graph.link_residuals()
    assert residuals.shape == (3,)
    np.testing.assert_allclose(residuals, 0.0, atol=1e-12)


def test_residuals_of_an_empty_graph() -> None:
    assert MapGraph().link_residuals().shape == (0,)
    graph = MapGraph()
    graph.add_node(np.eye(4))
    assert graph.link_residuals().shape == (0,)


def test_residual_of_a_perturbed_link_is_its_offset() -> None:
    """An offset in the link's translation (any direction, source frame) is the residual, the others stay 0."""
    graph = consistent_graph()
    offset = np.array([0.3, -0.4, 1.2])  # |offset| = 1.3
    good = graph.links[1]
    bad = good.relative.copy()
    bad[:3, 3] += offset
    graph.links[1] = Link(good.source, good.target, bad, good.kind, good.distance_m)

    residuals = graph.link_residuals()

    np.testing.assert_allclose(residuals, [0.0, 1.3, 0.0], atol=1e-12)


def test_residual_ignores_a_rotation_only_error() -> None:
    """The residual is the target's translation error: a link whose rotation alone is off still puts it right."""
    graph = consistent_graph()
    good = graph.links[0]
    turned = good.relative @ pose(0.3, (0.0, 0.0, 0.0))
    graph.links[0] = Link(good.source, good.target, turned, good.kind, good.distance_m)
    np.testing.assert_allclose(graph.link_residuals(), 0.0, atol=1e-12)


def test_residual_of_a_moved_node() -> None:
    graph = consistent_graph()
    graph.poses[2, :3, 3] += [0.0, 0.0, 0.5]
    np.testing.assert_allclose(graph.link_residuals(), [0.0, 0.5, 0.5], atol=1e-12)


def test_relative_is_the_pose_of_target_in_source() -> None:
    graph = consistent_graph()
    for source in range(3):
        for target in range(3):
            expected = invert_pose(POSES[source]) @ POSES[target]
            np.testing.assert_allclose(graph.relative(source, target), expected, atol=1e-12)
            np.testing.assert_allclose(graph.poses[source] @ graph.relative(source, target), POSES[target], atol=1e-12)
    np.testing.assert_allclose(graph.relative(1, 1), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(graph.relative(0, 2) @ graph.relative(2, 0), np.eye(4), atol=1e-12)
