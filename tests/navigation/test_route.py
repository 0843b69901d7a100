"""Routes on hand-built maps: the shortest way both ways, loop links taken, parts of the map never linked refused,
and Dijkstra's length against a brute-force search of every simple path on small random maps."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.navigation.streets import SPEED, MapBuilder, ladder

from neoslam.config import NeoSLAMConfig
from neoslam.errors import GoalError, NoRouteError
from neoslam.navigation import RoutePlanner, plan_route
from neoslam.navigation.graph import MIN_LINK_M
from neoslam.store.map_file import MapFile


def _steps(route) -> set[tuple[int, int]]:
    return {tuple(sorted(pair)) for pair in zip(route.experiences[:-1], route.experiences[1:], strict=True)}


def test_the_shortest_route_takes_the_cross_street_both_ways():
    streets = ladder()
    state = streets.state
    a, b = streets.at(150, 0), streets.at(50, 50)
    there = plan_route(state, f"experience {b}", start=a)
    back = plan_route(state, f"experience {a}", start=b)
    assert there.length_m == pytest.approx(150.0) and back.length_m == pytest.approx(150.0)  # around: 250 m
    assert set(streets.middle) <= set(there.experiences.tolist())
    assert there.experiences.tolist() == back.experiences.tolist()[::-1]
    assert there.experiences[0] == a and there.experiences[-1] == b and there.start == a
    np.testing.assert_allclose(there.along_m[[0, -1]], [0.0, 150.0])
    assert np.all(np.diff(there.along_m) > 0)
    np.testing.assert_array_equal(there.poses, state.experience_poses[there.experiences])


def test_a_loop_link_is_a_road_too():
    streets = ladder()
    last = streets.perimeter[-1]  # at (0, 5), linked by a loop closure to the start (0, 0)
    route = plan_route(streets.state, f"experience {streets.at(10, 0)}", start=last)
    assert route.length_m == pytest.approx(15.0)  # the loop link's 5 m, then 10 m; around the block: 485 m
    assert (streets.perimeter[0], last) in _steps(route)


def test_expected_time_follows_the_recorded_speeds_and_the_cost_can_be_time():
    streets = ladder()
    route = plan_route(streets.state, "experience 10", start=0)
    assert route.expected_time_s == pytest.approx(route.length_m / SPEED)
    builder = MapBuilder()
    slow_and_short = builder.drive([(0, 0), (50, 0)], speed=0.0)  # no speed recorded: expected_speed (8 m/s)
    fast_and_long = builder.drive([(0, 0), (0, 20), (50, 20), (50, 0)], after=None, speed=40.0)
    builder.link(slow_and_short[0], fast_and_long[0])
    builder.link(fast_and_long[-1], slow_and_short[-1])
    state = builder.state()
    goal = f"experience {slow_and_short[-1]}"
    assert plan_route(state, goal, start=0).length_m == pytest.approx(50.0)
    timed = NeoSLAMConfig(navigation={"cost": "time"})
    fastest = plan_route(state, goal, start=0, config=timed)
    # the two loop links join experiences at one place: MIN_LINK_M each
    assert fastest.length_m == pytest.approx(90.0, abs=0.01) and fastest.expected_time_s == pytest.approx(
        90.0 / 40.0, abs=1e-3
    )
    stopped = builder.drive([(300, 0), (320, 0)], after=None, speed=0.0)
    assert plan_route(builder.state(), f"experience {stopped[-1]}", start=stopped[0]).expected_time_s is None


def test_parts_of_the_map_never_linked_have_no_route_between_them():
    streets = ladder()
    apart = streets.builder.drive([(1000, 0), (1100, 0)], session=2)
    with pytest.raises(NoRouteError, match="no route from experience .* to experience 0"):
        plan_route(streets.state, "experience 0", start=apart[-1])
    route = plan_route(streets.state, f"experience {apart[0]}", start=apart[-1])  # within its own part: fine
    assert route.length_m == pytest.approx(100.0)


def test_a_position_on_experiences_not_linked_yet_starts_at_the_map_beside_it():
    """A robot just relocalised is in the map's frame, but its own newest experiences are not linked to the map yet:
    a route from its position starts at the nearest experience beside it that reaches the goal."""
    streets = ladder()
    own = streets.builder.drive([(148, 2), (152, 2)], session=2, after=None)  # in the map's frame, not linked
    state = streets.builder.state()
    robot = state.experience_poses[own[-1]]
    planner = RoutePlanner(state)
    assert planner.start_of(robot) == own[-1]
    route = planner.plan("experience 0", start=robot)
    assert route.start == streets.at(150, 0) and route.experiences[-1] == 0
    assert planner.plan(f"experience {own[0]}", start=robot).start == own[-1]  # its own part reaches its own
    streets.builder.drive([(1000, 0), (1010, 0)], session=3)  # another part, with no map beside it
    with pytest.raises(NoRouteError, match="no route from experience"):
        RoutePlanner(streets.builder.state()).plan("experience 0", start=np.array([1000.0, 0.0, 0.0]))


def test_a_route_to_where_the_robot_is_is_one_waypoint():
    route = plan_route(ladder().state, "experience 12", start=12)
    assert len(route) == 1 and route.length_m == 0.0 and route.expected_time_s == 0.0


def test_the_default_start_of_a_stored_map_is_its_last_experience_and_others_are_checked():
    streets = ladder()
    state = streets.state
    assert plan_route(state, "experience 0").start == len(state.experiences) - 1
    planner = RoutePlanner(state)
    assert planner.start_of(np.array([150.0, 1.0, 0.0])) == streets.at(150, 0)
    assert planner.start_of(state.experience_poses[7]) == 7
    assert planner.start_of("start") == 0
    with pytest.raises(GoalError, match="start experience 9999"):
        planner.start_of(9999)
    with pytest.raises(GoalError, match="empty"):
        plan_route(MapBuilder().state(), "start")


def test_a_planner_plans_many_routes_on_one_graph():
    planner = RoutePlanner(ladder().state)
    lengths = [planner.plan(f"experience {goal}", start=0).length_m for goal in (5, 10, 20)]
    assert lengths == pytest.approx([25.0, 50.0, 100.0])


# Dijkstra against brute force on small random maps


def _brute_force(positions: np.ndarray, edges: set[tuple[int, int]], start: int, goal: int) -> float:
    """The shortest simple path's length, trying every ordering of the nodes between (inf: none)."""
    if start == goal:
        return 0.0
    others = [n for n in range(len(positions)) if n not in (start, goal)]
    best = np.inf
    for size in range(len(others) + 1):
        for middle in itertools.permutations(others, size):
            path = (start, *middle, goal)
            steps = list(zip(path[:-1], path[1:], strict=True))
            if all(tuple(sorted(step)) in edges for step in steps):
                length = sum(max(float(np.linalg.norm(positions[a] - positions[b])), MIN_LINK_M) for a, b in steps)
                best = min(best, length)
    return best


@st.composite
def _small_maps(draw):
    n = draw(st.integers(2, 6))
    coordinate = st.floats(-50, 50, allow_nan=False, allow_infinity=False)
    positions = np.array([[draw(coordinate), draw(coordinate), 0.0] for _ in range(n)])
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    chosen = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=len(pairs))) if pairs else []
    directions = draw(st.lists(st.booleans(), min_size=len(chosen), max_size=len(chosen)))
    kinds = draw(st.lists(st.sampled_from(["odometry", "loop"]), min_size=len(chosen), max_size=len(chosen)))
    start, goal = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
    return positions, chosen, directions, kinds, start, goal


@settings(max_examples=60, deadline=None)
@given(_small_maps())
def test_dijkstra_equals_a_brute_force_search(small_map):
    positions, chosen, directions, kinds, start, goal = small_map
    builder = MapBuilder()
    for x, y, _ in positions:
        builder.place(x, y)
    for (a, b), flipped, kind in zip(chosen, directions, kinds, strict=True):
        builder.link(*((b, a) if flipped else (a, b)), kind)
    expected = _brute_force(positions, set(chosen), start, goal)
    if np.isinf(expected):
        with pytest.raises(NoRouteError):
            plan_route(builder.state(), f"experience {goal}", start=start)
        return
    route = plan_route(builder.state(), f"experience {goal}", start=start)
    assert route.length_m == pytest.approx(expected, rel=1e-9, abs=1e-9)
    assert route.experiences[0] == start and route.experiences[-1] == goal


def test_the_docs_python_example_runs(tmp_path, monkeypatch):
    """docs/navigation.md's example, on the ladder of streets saved as town.db."""
    streets = ladder()
    streets.builder.keyframes = {}
    with MapFile.create(tmp_path / "town.db", NeoSLAMConfig()) as map_file:
        map_file.commit(streets.state)
    page = (Path(__file__).resolve().parents[2] / "docs" / "navigation.md").read_text()
    code = re.search(r"## Python API\n\n```python\n(.*?)```", page, re.S)
    assert code, "docs/navigation.md has no Python example under its Python API heading"
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {}
    exec(compile(code.group(1), "navigation.md", "exec"), namespace)
    assert namespace["guidance"].arrived and namespace["route"].goal.kind == "object"
