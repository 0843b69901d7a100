"""The closed-loop deliveries of benchmarks/navigation.py: the true street graph of a drive, the robot driven on it,
the controller that reads the guidance, and (slow) a tiny run of the part."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from benchmarks import navigation
from benchmarks._deliveries import FUSED_M, _removed
from benchmarks._judging import _beside
from benchmarks._robot import MAX_YAW_RATE, Robot, choose_next, explore, follow, street_ahead
from benchmarks._street_graph import SPACING_M, StreetGraph, street_graph


def _line(corners: list[tuple[float, float]], step: float = 0.5) -> np.ndarray:
    """(n, 3) positions every `step` metres along a polyline (z 0)."""
    points = []
    for (x0, y0), (x1, y1) in zip(corners[:-1], corners[1:], strict=True):
        length = float(np.hypot(x1 - x0, y1 - y0))
        for s in np.arange(0.0, length, step):
            points.append((x0 + (x1 - x0) * s / length, y0 + (y1 - y0) * s / length, 0.0))
    points.append((*corners[-1], 0.0))
    return np.array(points)


def _near(graph, x: float, y: float) -> int:
    return graph.nearest(np.array([x, y]))


def _towards(graph, node: int, direction: float) -> int:
    """The neighbour of a node whose edge points nearest to a direction."""
    gaps = [abs(np.angle(np.exp(1j * (graph.heading(node, n) - direction)))) for n in graph.neighbours[node]]
    return int(graph.neighbours[node][int(np.argmin(gaps))])


def test_a_street_driven_there_and_back_is_one_street():
    graph = street_graph(_line([(0, 0), (100, 0), (100, 2), (0, 2)]))  # back in the other lane, 2 m beside
    assert graph.positions[:, 0].max() == pytest.approx(100.0, abs=SPACING_M)
    assert len(graph) < 1.2 * 100 / SPACING_M  # the way back took the way out's nodes (all but its turn's)
    assert graph.distances(_near(graph, 0, 0))[_near(graph, 80, 0)] == pytest.approx(80.0, abs=1.0)


def test_streets_driven_across_meet_at_a_junction_and_every_street_goes_both_ways():
    # east along y = 0, round a block, then south across y = 0 at x = 50
    graph = street_graph(_line([(0, 0), (100, 0), (100, 60), (50, 60), (50, -50)]))
    junction = _near(graph, 50, 0)
    assert len(graph.neighbours[junction]) >= 3
    start, end = _near(graph, 0, 0), _near(graph, 50, -50)
    assert graph.distances(start)[end] == pytest.approx(100.0, abs=2.0)  # turning at the junction, not round
    path = graph.path(end, start)  # the other way: north then west, against the drive
    assert path[0] == end and path[-1] == start and junction in path.tolist()


def test_a_corner_taken_on_a_curve_is_a_junction_for_the_street_driven_straight_through():
    """A drive turned from x = 50 (northwards) west onto y = 0 on a 12 m curve, then drove y = 0 eastwards straight
    through: a robot on y = 0 going east can turn south there, without driving round the curve backwards."""
    radius = 12.0
    angles = np.linspace(0.0, np.pi / 2, 20)
    curve = np.column_stack([50 - radius + radius * np.cos(angles), -radius + radius * np.sin(angles), 0 * angles])
    south = _line([(50, -80), (50, -radius)])
    west = _line([(50 - radius, 0), (-20, 0), (-20, 30), (-10, 30), (-10, 0)])
    east = _line([(-10, 0), (100, 0)])
    graph = street_graph(np.concatenate([south, curve, west, east]))
    here, there = _near(graph, 52, 0), _near(graph, 50, -30)
    assert graph.distances(here)[there] < 40.0  # round the curve backwards: more than 45 m


def test_the_robot_drives_along_edges_turns_in_place_and_has_its_slope():
    positions = _line([(0, 0), (30, 0)], step=1.0)
    positions[:, 2] = positions[:, 0] * 0.1  # climbing 10 %
    graph = street_graph(positions)
    robot = Robot.at(graph, 0, 1)
    dt = 0.1
    driven = [
        robot.drive(0.8, dt, lambda node, came_from, yaw: explore(graph, node, came_from, None)) for _ in range(10)
    ]
    assert sum(driven) == pytest.approx(8.0) and robot.position[0] == pytest.approx(8.0, abs=1e-6)
    pitch = np.arcsin(-robot.pose()[2, 0])  # REP-103: climbing is a negative pitch
    assert pitch == pytest.approx(-np.arctan(0.1), abs=1e-6) and robot.pose()[2, 3] == pytest.approx(0.8, abs=1e-6)
    back = lambda node, came_from, yaw: came_from  # noqa: E731 (turn round at the next node)
    while not robot.turning:
        assert robot.drive(0.8, dt, back) <= 0.8
    turns = 0
    while robot.turning:
        assert robot.drive(0.8, dt, back) == 0.0
        turns += 1
    assert abs(turns - np.pi / (MAX_YAW_RATE * dt)) <= 1.0  # half a turn at the largest yaw rate
    assert abs(np.cos(robot.yaw) + 1.0) < 1e-9  # facing west now


def test_the_controller_follows_the_bearing_and_turns_round_only_for_a_waypoint_behind():
    # a T-junction at (50, 0): y = 0 from west to east, a street south from it
    graph = street_graph(np.concatenate([_line([(0, 0), (100, 0)]), _line([(100, 0), (100, 5), (50, 5), (50, -60)])]))
    node = _near(graph, 50, 0)
    west, east, south = (_towards(graph, node, direction) for direction in (np.pi, 0.0, -np.pi / 2))
    heading_east = 0.0
    assert follow(graph, node, west, heading_east - np.pi / 2) == south  # a waypoint to the right: turn right
    assert follow(graph, node, west, heading_east) == east
    before = _near(graph, 45, 0)
    came, ahead = _towards(graph, before, np.pi), _towards(graph, before, 0.0)
    assert follow(graph, before, came, heading_east - np.radians(100)) == ahead  # to the side: on to the turn
    assert follow(graph, before, came, heading_east + np.radians(170)) == came  # behind: turn round
    rng = np.random.default_rng(0)
    assert choose_next("not_localised", None, graph, before, came, heading_east, rng) == ahead  # explores on
    assert choose_next("on_route", np.radians(170), graph, before, came, heading_east, rng) == came
    onward = set(graph.neighbours[node].tolist()) - {west}  # east, and the south street (by a junction edge too)
    assert {explore(graph, node, west, np.random.default_rng(seed)) for seed in range(40)} == onward
    assert {east, south} <= onward


def test_the_controller_takes_the_street_that_leads_to_the_waypoint_not_the_one_that_starts_towards_it():
    """A junction at the origin: the street driven (from the south) goes on north, one turns back south-west, and
    one leaves north-east on a curve and then runs west. A waypoint due west is reached by the curved street: its
    first edge points away from the waypoint, but 10 m on it leads west."""
    positions = np.array(
        [(0, -3, 0), (0, 0, 0), (0, 3, 0), (0, 6, 0), (-2, -2, 0), (-4, -6, 0), (2, 2, 0), (1, 4.5, 0),
         (-2, 5, 0), (-6, 5, 0), (-10, 5, 0)],
        dtype=float,
    )  # fmt: skip
    edges = np.array([(0, 1), (1, 2), (2, 3), (1, 4), (4, 5), (1, 6), (6, 7), (7, 8), (8, 9), (9, 10)])
    neighbours = tuple(
        np.array(sorted({int(b) for a, b in edges if a == n} | {int(a) for a, b in edges if b == n})) for n in range(11)
    )
    graph = StreetGraph(positions, edges, neighbours)
    assert np.degrees(street_ahead(graph, 1, 6)) > 110  # it leaves at 45 degrees and leads north-west to west
    assert follow(graph, 1, 0, np.pi) == 6
    assert follow(graph, 1, 0, -np.radians(120)) == 4  # a waypoint south-west: the street that goes there


def test_an_object_between_two_streets_is_beside_both():
    """The judge's arrival points of an object: the nearest street point, and another street's nearly as near."""
    graph = street_graph(_line([(0, 0), (100, 0), (100, 100)]))
    mapped = SimpleNamespace(streets=graph)
    between = _beside(mapped, np.array([80.0, 20.0, 0.0]))  # 20 m from both streets
    assert sorted(map(tuple, between[:, :2].round())) == [(80.0, 0.0), (100.0, 20.0)]
    kerb = _beside(mapped, np.array([40.0, 5.0, 0.0]))
    assert kerb[:, :2].round().tolist() == [[40.0, 0.0]]


def test_a_removed_goal_takes_out_the_unmapped_car_of_its_class_the_map_fused_with_it():
    """World objects: the goal car (0), an unmapped car 3.4 m from it (1: the map made one object of the two), a
    mapped car as near (2), an unmapped person beside it (3) and an unmapped car beyond FUSED_M (4)."""
    positions = np.array([[0, 0, 0], [3.4, 0, 0], [0, 3.4, 0], [1, 1, 0], [FUSED_M + 1, 0, 0]], dtype=float)
    world = SimpleNamespace(positions=positions, labels=np.array(["car", "car", "car", "person", "car"]))
    mapped = SimpleNamespace(world=world, object_match=np.array([0, 2, -1]))
    assert _removed(mapped, 0).tolist() == [0, 1]
    assert _removed(mapped, 2).tolist() == [2]  # the unmapped car is the goal's, nearer it and fused into it


@pytest.mark.slow  # maps the block route and drives two deliveries and a removed goal: a minute or two
def test_the_deliveries_part_runs_and_writes_its_tables(tmp_path: Path, capsys) -> None:
    out = tmp_path / "navigation.json"
    argv = ["--quick", "--parts", "deliveries", "--maps", "block", "--deliveries", "2", "--removed", "1"]
    navigation.main([*argv, "--workers", "1", "--out", str(out)])
    result = json.loads(out.read_text())
    tables = {"delivery_maps", "deliveries", "deliveries_by_goal", "deliveries_by_direction", "delivery_failures"}
    assert set(result["tables"]) == tables
    rows = result["figures"]["deliveries"]["rows"]
    assert len(rows) == 3 and [r["removed"] for r in rows] == [False, False, True]
    total = result["tables"]["deliveries"]["rows"][-1]
    assert total["map"] == "total" and total["deliveries"] == 2 and total["removed"] == 1
    assert all(r["why"] is None or isinstance(r["why"], str) for r in rows)
    assert "## Deliveries" in capsys.readouterr().out
