"""Guidance on a synthetic drive along a route of the hand-built ladder: waypoints advance, bearings have the right
sign, arrival comes at the route's end within the radius and not before, leaving the route or a jump of the pose
plans again, no pose is `not_localised`, and a frame costs well under a millisecond."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from tests.navigation.streets import ladder, pose_at

from neoslam.config import NavigationConfig
from neoslam.errors import NoRouteError
from neoslam.navigation import Guide, RoutePlanner

CONFIG = NavigationConfig()


@pytest.fixture
def planned():
    """A planner on the ladder and its route from (150, 0) to (50, 50), by the middle street (150 m)."""
    streets = ladder()
    planner = RoutePlanner(streets.state)
    return planner, planner.plan(f"experience {streets.at(50, 50)}", start=streets.at(150, 0))


def _drive(route, step: float = 1.0, lateral: float = 0.0) -> list[np.ndarray]:
    """Poses along the route every `step` metres, heading along it, `lateral` metres to its left."""
    points = route.positions[:, :2]
    poses = []
    for a, b in zip(points[:-1], points[1:], strict=True):
        length = float(np.linalg.norm(b - a))
        if length < 1e-6:
            continue
        yaw = float(np.arctan2(*(b - a)[::-1]))
        left = np.array([-np.sin(yaw), np.cos(yaw)]) * lateral
        poses += [pose_at(*(a + (b - a) * s / length + left), yaw) for s in np.arange(0.0, length, step)]
    return poses


def test_waypoints_advance_and_arrival_comes_at_the_route_end_within_the_radius_and_not_before(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    records = [guide.update(pose) for pose in _drive(route, lateral=1.0)]
    records.append(guide.update(route.poses[-1]))
    waypoints = [r.waypoint for r in records]
    assert waypoints == sorted(waypoints) and waypoints[-1] == len(route) - 1
    assert {r.state for r in records} == {"on_route", "arrived"}
    first = next(i for i, r in enumerate(records) if r.arrived)
    assert all(r.remaining_m > CONFIG.end_reached for r in records[:first])  # inside the radius, short of the end: on
    assert any(r.goal_distance_m <= CONFIG.arrival_radius for r in records[:first])
    assert records[first].goal_distance_m <= CONFIG.arrival_radius and records[first].remaining_m <= CONFIG.end_reached
    assert all(r.arrived and r.state == "arrived" for r in records[first:])
    remaining = [r.remaining_m for r in records]
    assert remaining[0] == pytest.approx(route.length_m, abs=0.01) and remaining[-1] == pytest.approx(0.0, abs=0.01)
    assert np.all(np.diff(remaining) <= 1e-9)
    for record in records[: first - 10]:  # the waypoint is look_ahead ahead along the route, or the next corner
        ahead = route.along_m[record.waypoint] - (route.length_m - record.remaining_m)
        assert ahead >= CONFIG.look_ahead - 1e-9 and record.distance_m <= ahead + 1.0 + 1e-9
        assert record.off_route_m == pytest.approx(1.0, abs=1e-6) or record.off_route_m < 1.0


def test_a_robot_beside_the_route_end_arrives_and_one_far_beside_it_does_not(planned):
    """At the route's end, the radius is how far beside it the robot may be."""
    planner, route = planned
    x, y = route.positions[-1][:2]  # (50, 50), the route comes from the east along the north street
    near = Guide(route, CONFIG)
    near.update(pose_at(x + 20.0, y, np.pi))
    assert near.update(pose_at(x - 2.0, y + 3.0, np.pi)).state == "arrived"  # past the end, 3.6 m from it
    far = Guide(route, CONFIG)
    far.update(pose_at(x + 20.0, y, np.pi))
    beside = far.update(pose_at(x, y + CONFIG.arrival_radius + 1.0, np.pi))
    assert beside.state == "on_route" and beside.remaining_m == pytest.approx(0.0) and not beside.arrived


def test_bearings_are_positive_to_the_left(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    x, y = route.poses[0][:2, 3]  # (150, 0); the route goes west along the south street
    facing_route = guide.update(pose_at(x, y, np.pi))
    assert abs(facing_route.bearing_rad) < 1e-6
    turned_right = guide.update(pose_at(x, y, np.pi - 0.5))  # facing a little right of the route: it is to the left
    assert turned_right.bearing_rad == pytest.approx(0.5, abs=1e-6)
    turned_left = guide.update(pose_at(x, y, np.pi + 0.5))
    assert turned_left.bearing_rad == pytest.approx(-0.5, abs=1e-6)
    # at the corner of the middle street the route turns right (north, from heading west): the waypoint is right
    corner = guide.update(pose_at(103.0, 0.0, np.pi))
    assert corner.bearing_rad < -0.3


def test_leaving_the_route_plans_again_from_where_the_robot_is(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    for pose in _drive(route)[:20]:  # 20 m west along the south street, to (131, 0)
        assert guide.update(pose).state == "on_route"
    records = [guide.update(pose_at(131.0 - 0.5 * k, -1.0 * k, -2.0)) for k in range(1, 16)]  # veering south
    states = [r.state for r in records]
    first = states.index("replanned")
    assert set(states[:first]) == {"on_route"} and records[first - 1].off_route_m <= CONFIG.off_route_distance
    away = records[first]
    assert away.reason == "off_route" and away.off_route_m < CONFIG.off_route_distance  # on the new route
    assert away.route is not route and away.route.goal.experience == route.goal.experience
    here = np.array([131.0 - 0.5 * (first + 1), -1.0 * (first + 1)])
    assert away.route.start == planner.graph.nearest(here)[0]
    assert states[first + 1 :] == ["on_route"] * (len(states) - first - 1)  # planned once, not every frame


def test_a_jump_of_the_pose_is_a_relocalisation_and_plans_again(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    guide.update(route.poses[0])
    jumped = guide.update(pose_at(100.0, 30.0, np.pi / 2))  # on the middle street, 58 m on: beyond jump_distance
    assert jumped.state == "replanned" and jumped.reason == "relocalised"
    assert jumped.route.length_m < route.length_m


def test_without_a_pose_the_robot_is_not_localised(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    record = guide.update(None)
    assert record.state == "not_localised" and record.waypoint is None and record.distance_m is None
    assert guide.update(route.poses[0]).state == "on_route"
    assert guide.update(None).state == "not_localised"
    back = guide.update(pose_at(0.0, 25.0, np.pi / 2))  # localised again, far off the route
    assert back.state == "replanned" and back.reason == "relocalised"


def test_without_a_planner_off_route_is_said_and_nothing_planned(planned):
    _, route = planned
    guide = Guide(route, CONFIG)
    assert guide.update(route.poses[0]).state == "on_route"
    record = guide.update(pose_at(150.0, -20.0, np.pi))
    assert record.state == "off_route" and record.off_route_m == pytest.approx(20.0) and guide.route is route


def test_no_route_from_where_the_robot_is_is_unreachable_until_it_moves(planned):
    _, route = planned
    calls = []

    def replan(goal, position):
        calls.append(position)
        raise NoRouteError("no route")

    guide = Guide(route, CONFIG, replan)
    assert guide.update(pose_at(150.0, -30.0, 0.0)).state == "unreachable"
    assert guide.update(pose_at(151.0, -30.0, 0.0)).state == "unreachable"
    assert len(calls) == 1  # not planned again every frame
    guide.update(pose_at(150.0, -50.0, 0.0))
    assert len(calls) == 2


def test_a_frame_costs_well_under_a_millisecond(planned):
    planner, route = planned
    guide = Guide(route, CONFIG, planner.replan)
    poses = _drive(route, step=0.5, lateral=0.5)
    times = []
    for pose in poses:
        start = time.perf_counter()
        guide.update(pose)
        times.append(time.perf_counter() - start)
    assert np.median(times) < 1e-3


def test_a_robot_off_the_route_joins_the_map_ahead_not_where_it_was_nearest(planned):
    planner, route = planned
    # 8 m south of the street between (115, 0) and (125, 0), heading west to the middle street: (120, 0) is nearest,
    # (115, 0) is 2.4 m farther and 5 m nearer the goal along the route
    again = planner.replan(route.goal, np.array([122.0, -8.0, 0.0]))
    assert planner.graph.positions[again.start, :2].tolist() == [115.0, 0.0]
    assert again.experiences[-1] == route.goal.experience and again.length_m == pytest.approx(115.0)


def test_a_point_off_the_route_is_followed_on_to_and_a_robot_passing_beside_it_arrives_abeam():
    """A point goal 3 m off the north street: the route ends at an experience near it, and the guidance leaves the
    street where it passes nearest the point (62, 50) and goes on to the point itself (the last waypoint, no
    experience). A robot driving west along the street, 0.5 m beside it, comes no nearer the point than 2.5 m and
    its projection never reaches it: it arrives once the point is abeam, not before; one driven to the point
    arrives there."""
    streets = ladder()
    planner = RoutePlanner(streets.state)
    point = np.array([62.0, 53.0])
    route = planner.plan(f"{point[0]},{point[1]}", start=streets.at(150, 0))
    assert 1.0 < np.hypot(*(point - route.positions[-1][:2])) <= CONFIG.goal_radius
    leaving = Guide(route, CONFIG).update(pose_at(62.0, 50.0, np.pi / 2))
    assert leaving.state == "on_route" and leaving.waypoint == len(route) and leaving.experience is None
    assert np.allclose(leaving.waypoint_position[:2], point) and leaving.remaining_m == pytest.approx(3.0)
    assert leaving.bearing_rad == pytest.approx(0.0, abs=1e-9)

    beside = Guide(route, CONFIG)
    states = {x: beside.update(pose_at(x, 50.5, np.pi)).state for x in np.arange(80.0, 55.0, -0.5)}
    first = max(x for x, state in states.items() if state == "arrived")
    assert point[0] - 0.5 <= first <= point[0] + 1e-9
    assert all(state == "on_route" for x, state in states.items() if x > first)

    driven = Guide(route, CONFIG)
    driven.update(pose_at(62.0, 50.0, np.pi / 2))
    arrived = driven.update(pose_at(*point, np.pi / 2))
    assert arrived.state == "arrived" and arrived.goal_distance_m == pytest.approx(0.0)


def test_a_route_that_turns_back_on_itself_is_followed_from_the_waypoint_the_robot_reached(planned):
    """A route north along x = 0 to y = 14, back south 0.5 m beside itself, then east along y = 2. A robot that
    turns round at y = 8 (as a car turns where it can) is nearer the route's way north than its way back; within
    waypoint_reached of the waypoint it was guided to, it has reached it, and it is guided on south and east to the
    end instead of back north."""
    _, planned_route = planned
    points = [(0, y) for y in range(-20, 15, 5)] + [(0, 14), (0.5, 10), (0.5, 5), (5, 2), (10, 2), (15, 2)]
    poses = np.array([pose_at(x, y, 0.0) for x, y in points])
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(np.array(points, float), axis=0).T))])
    route = dataclasses.replace(
        planned_route, experiences=np.arange(len(points)), poses=poses, along_m=along, length_m=float(along[-1])
    )
    guide = Guide(route, CONFIG)
    for y in np.arange(-20.0, 8.01, 1.0):
        guide.update(pose_at(0.0, y, np.pi / 2))
    back = [guide.update(pose_at(0.0, y, -np.pi / 2)) for y in np.arange(8.0, 2.0, -1.0)]
    assert back[-1].waypoint > points.index((0.5, 5)) and abs(back[-1].bearing_rad) < np.radians(120)
    east = [guide.update(pose_at(x, 2.0, 0.0)) for x in np.arange(0.0, 15.01, 0.5)]
    assert east[-1].state == "arrived"


def test_a_robot_going_to_an_object_between_experiences_arrives_beside_it():
    """The route to a car beside the middle of two experiences 5 m apart ends at the street point beside it: the
    robot at the experience before it has not arrived (the end is 2.5 m ahead); at the point beside the car it has."""
    streets = ladder()
    car = streets.builder.add_object("car", (62.5, -5, 0.5), {streets.at(60, 0): 3, streets.at(65, 0): 2})
    planner = RoutePlanner(streets.state)
    route = planner.plan(f"object {car}", start=streets.at(20, 0))
    guide = Guide(route, CONFIG, planner.replan)
    records = [guide.update(pose) for pose in _drive(route)]
    at_experience = guide.update(pose_at(60.0, 0.0, 0.0))
    assert not at_experience.arrived and at_experience.remaining_m == pytest.approx(2.5, abs=0.01)
    assert not any(r.arrived for r in records)
    beside = guide.update(pose_at(62.5, 0.0, 0.0))
    assert beside.arrived and beside.remaining_m == pytest.approx(0.0, abs=0.01)
    again = Guide(route, CONFIG, planner.replan)  # relocalised past the car, on the street beyond it
    again.update(pose_at(20.0, 0.0, 0.0))
    replanned = again.update(pose_at(90.0, 0.0, np.pi))
    assert replanned.state == "replanned" and replanned.route is not None
    np.testing.assert_allclose(replanned.route.goal.position[:2], [62.5, 0.0], atol=1e-9)
    assert replanned.remaining_m == pytest.approx(27.5, abs=0.01)  # back along the street to the car, not past it
