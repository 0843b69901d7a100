"""The navigation graph: links both ways, each pair once, weighted by corrected length (at least MIN_LINK_M);
following a growing, corrected map without reading it all again."""

from __future__ import annotations

import numpy as np
import pytest
from tests.navigation.streets import MapBuilder

from neoslam.config import NavigationConfig
from neoslam.navigation import NavigationGraph, map_view
from neoslam.navigation.graph import MIN_LINK_M

CONFIG = NavigationConfig()


def _graph(builder: MapBuilder) -> NavigationGraph:
    return NavigationGraph.build(map_view(builder.state()), CONFIG)


def test_links_are_both_ways_once_each_weighted_by_the_corrected_distance():
    builder = MapBuilder()
    street = builder.drive([(0, 0), (20, 0)])  # 5 experiences, 4 odometry links
    builder.link(street[3], street[2])  # a loop link over an odometry link: the same road
    again = builder.place(20, 0.0)
    builder.link(street[-1], again)  # a street driven again: one place, two experiences
    graph = _graph(builder)
    assert graph.pairs.tolist() == [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]]
    matrix = graph.matrix.toarray()
    np.testing.assert_allclose(matrix, matrix.T)
    assert matrix[0, 1] == pytest.approx(5.0) and matrix[4, 5] == MIN_LINK_M
    assert graph.shortest_paths(5).path(0).tolist() == [5, 4, 3, 2, 1, 0]


def test_nearest_within_and_parts():
    builder = MapBuilder()
    builder.drive([(0, 0), (20, 0)])
    builder.drive([(500, 0), (510, 0)], session=2)
    graph = _graph(builder)
    assert graph.nearest(np.array([6.0, 1.0])) == (1, pytest.approx(np.hypot(1.0, 1.0)))
    assert graph.within(np.array([10.0, 0.0]), 5.0).tolist() == [1, 2, 3]
    assert graph.components.tolist() == [0] * 5 + [1] * 3
    assert not graph.shortest_paths(0).reachable(6)


def test_a_growing_and_corrected_map_is_followed():
    builder = MapBuilder()
    street = builder.drive([(0, 0), (20, 0)])
    state = builder.state()
    graph = NavigationGraph.build(map_view(state), CONFIG)
    before = graph.matrix
    assert not graph.update(map_view(state)) and graph.matrix is before  # nothing changed: nothing rebuilt
    state.links.append(builder.links[0].__class__(street[0], street[4], np.eye(4), "loop", 0.0))
    assert graph.update(map_view(state)) and graph.matrix is not before
    assert graph.shortest_paths(0).costs[4] == pytest.approx(20.0)  # the loop link weighs the corrected distance
    state.experience_poses[4, 0, 3] = 30.0  # a correction moves the last experience
    assert graph.update(map_view(state))
    assert graph.shortest_paths(0).costs[4] == pytest.approx(30.0)
    assert graph.nearest(np.array([29.0, 0.0]))[0] == 4
