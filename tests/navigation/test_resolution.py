"""Goals of each kind resolved on the hand-built ladder of streets: which experience the route ends at, what the goal
stands for, and one GoalError naming the goal for an unknown id, a class the map lacks, an ambiguous `the`, a point
off the map, a stale object not asked for."""

from __future__ import annotations

import numpy as np
import pytest
from tests.navigation.streets import ladder

from neoslam.config import NeoSLAMConfig
from neoslam.errors import GoalError, NoRouteError
from neoslam.navigation import RoutePlanner, plan_route


@pytest.fixture
def streets():
    return ladder()


def test_an_experience_and_a_keyframe_are_where_the_route_ends(streets):
    route = plan_route(streets.state, "experience 30", start=0)
    goal = route.goal
    assert (goal.kind, goal.experience, goal.ids, goal.text) == ("experience", 30, (30,), "experience 30")
    np.testing.assert_array_equal(goal.position, streets.state.experience_poses[30, :3, 3])
    np.testing.assert_array_equal(goal.target, goal.position)
    keyframe = plan_route(streets.state, "keyframe 8", start=0).goal
    assert (keyframe.kind, keyframe.experience, keyframe.ids) == ("keyframe", streets.at(200, 25), (8,))
    assert "experience" in keyframe.description


def test_a_point_is_reached_from_the_nearest_experience_on_the_way(streets):
    goal = plan_route(streets.state, "x=152 y=3", start=0).goal
    assert goal.kind == "point" and goal.ids == ()
    np.testing.assert_allclose(goal.target, [152.0, 3.0, 0.0])  # z: the nearest experience's
    assert goal.experience == streets.at(150, 0)  # both 150 and 155 are within reach: the route is shorter to 150
    assert goal.offset_m == pytest.approx(np.hypot(2.0, 3.0))
    with pytest.raises(GoalError, match=r"'500.0,500.0': .* m from the nearest experience"):
        plan_route(streets.state, "500,500", start=0)


def test_start_is_where_the_latest_session_started(streets):
    later = streets.builder.drive([(0, 60), (0, 100)], session=2, after=streets.at(0, 50))
    state = streets.state
    assert plan_route(state, "start", start=5).goal.experience == later[0]
    first = plan_route(state, "start of session 1", start=5).goal
    assert (first.kind, first.experience, first.ids) == ("start", 0, (1,))
    with pytest.raises(GoalError, match="session 3 made no experience"):
        plan_route(state, "start of session 3", start=5)


def test_an_object_by_id_and_the_nearest_of_a_class_by_route(streets):
    state = streets.state
    truck = plan_route(state, "object 0", start=0).goal
    assert (truck.kind, truck.ids) == ("object", (0,))
    np.testing.assert_allclose(truck.target, [160.0, -5.0, 0.5])
    assert truck.experience == streets.at(160, 0) and truck.object.label == "truck"
    # Two trucks: (160, -5) on the south street and (40, 55) on the north one, which is nearer by route from
    # (100, 45), the north end of the middle street, though both are about 60 m away in a straight line.
    north = plan_route(state, "truck", start=streets.at(100, 45)).goal
    assert north.ids == (1,) and "nearest by route of 2" in north.description
    south = plan_route(state, "nearest truck", start=streets.at(100, 5)).goal
    assert south.ids == (0,)
    assert plan_route(state, "the person", start=0).goal.ids == (4,)


def test_filters_pick_among_objects_of_a_class(streets):
    state = streets.state
    # truck 0 is seen 5 times from two experiences, truck 1 4 times; car 2 and car 3 5 times each
    assert plan_route(state, "truck seen 5+ times", start=streets.at(100, 5)).goal.ids == (0,)
    with pytest.raises(GoalError, match="none of the map's 2 truck objects passes its filters"):
        plan_route(state, "truck seen 6+ times", start=0)
    streets.builder.drive([(0, 60), (20, 60)], session=2, after=streets.at(0, 50))
    streets.builder.objects[3][2][len(streets.builder.poses) - 1] = 3  # car 3 seen from session 2 too
    assert plan_route(streets.state, "car in session 2", start=0).goal.ids == (3,)


@pytest.mark.parametrize(
    ("goal", "problem"),
    [
        ("experience 999", "'experience 999': no such experience; the map has experiences 0 to"),
        ("keyframe 99", "'keyframe 99': no such keyframe"),
        ("object 99", "'object 99': no such object"),
        ("plane", "'nearest plane': no plane in the map (its classes: car, person, truck)"),
        ("the truck", "'the truck': ambiguous, 2 truck objects match (objects 0, 1)"),
        ("the car", "say 'nearest car' or 'object 2'"),
    ],
)
def test_a_goal_the_map_cannot_resolve_is_one_error_naming_it(streets, goal, problem):
    with pytest.raises(GoalError) as refused:
        plan_route(streets.state, goal, start=0)
    assert problem in str(refused.value) and "\n" not in str(refused.value)


def test_an_object_seen_too_few_times_is_not_in_the_map(streets):
    streets.builder.add_object("car", (60, -5, 0.5), {streets.at(60, 0): 2})  # min_observations: 3
    with pytest.raises(GoalError, match="'object 5': not in the map"):
        plan_route(streets.state, "object 5", start=0)


def test_a_stale_object_is_a_goal_only_when_asked_for(streets):
    view = {"field_of_view_deg": 80.0, "view_min_range": 3.0}
    config = NeoSLAMConfig(navigation={"stale_after_misses": 2, **view})
    # a later drive east along the south street, past truck 0 at (160, -5) without seeing it
    streets.builder.drive([(130, -1), (175, -1)], session=2, after=streets.at(125, 0))
    state = streets.state
    with pytest.raises(GoalError, match="'object 0': is stale: last seen session 1"):
        plan_route(state, "object 0", start=0, config=config)
    assert plan_route(state, "truck", start=streets.at(100, 5), config=config).goal.ids == (1,)  # the fresh one
    with pytest.raises(GoalError, match="every match is stale .*say 'stale truck'"):
        plan_route(state, "truck seen 5+ times", start=0, config=config)
    assert plan_route(state, "stale object 0", start=0, config=config).goal.object.stale
    assert plan_route(state, "object 0", start=0, config=config, stale=True).goal.ids == (0,)
    stale_truck = plan_route(state, "stale truck", start=streets.at(100, 5), config=config).goal
    assert stale_truck.ids == (0,) and "stale" in stale_truck.description


def test_no_route_to_an_object_in_a_part_never_linked(streets):
    apart = streets.builder.drive([(1000, 0), (1100, 0)], session=2)
    streets.builder.add_object("bus", (1050, -5, 0.5), {apart[10]: 4})
    with pytest.raises(NoRouteError, match="'nearest bus': no route from experience 0"):
        plan_route(streets.state, "bus", start=0)


def test_a_start_can_be_any_place_that_names_one(streets):
    planner = RoutePlanner(streets.state)
    assert planner.start_of("object 0") == streets.at(160, 0)
    assert planner.start_of("the person") == streets.at(105, 25) or planner.start_of("the person") in streets.middle
    assert planner.start_of("keyframe 7") == streets.at(60, 0)
    with pytest.raises(GoalError, match="start 'nearest truck': 2 objects match"):
        planner.start_of("truck")


def test_a_route_to_an_object_ends_on_the_street_beside_it(streets):
    """Experiences are 5 m apart: an object beside the middle of two ends the route at the street point beside it,
    on the link between them, whichever way the robot comes: the route is planned to the experience it reaches first
    and goes on along the link, its length to that point (an object abeam of an experience ends there)."""
    builder = streets.builder
    between = builder.add_object("car", (62.5, -5, 0.5), {streets.at(60, 0): 3, streets.at(65, 0): 2})
    route = plan_route(streets.state, f"object {between}", start=streets.at(20, 0))
    goal = route.goal
    assert goal.experience == streets.at(60, 0)
    np.testing.assert_allclose(goal.position[:2], [62.5, 0.0], atol=1e-9)
    assert goal.offset_m == pytest.approx(5.0)
    assert route.length_m == pytest.approx(route.along_m[-1] + 2.5)
    np.testing.assert_allclose(route.path[-1, :2], [62.5, 0.0], atol=1e-9)  # the line a robot follows ends there
    assert np.hypot(*np.diff(route.path[:, :2], axis=0).T).sum() == pytest.approx(route.length_m)
    east = plan_route(streets.state, f"object {between}", start=streets.at(150, 0))  # the other way: from 65
    assert east.goal.experience == streets.at(65, 0) and east.length_m == pytest.approx(east.along_m[-1] + 2.5)
    np.testing.assert_allclose(east.goal.position[:2], [62.5, 0.0], atol=1e-9)
    abeam = plan_route(streets.state, "object 3", start=streets.at(20, 0)).goal  # the car at (120, -5)
    np.testing.assert_allclose(abeam.position, streets.state.experience_poses[abeam.experience, :3, 3])
