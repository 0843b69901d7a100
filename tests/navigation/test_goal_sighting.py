"""An object goal is reached only once the running session has seen it: in a frame since the route was planned (an
observation nearer to it than to another object of its class), or in the map's own record of the object when the
route is planned (the session's observations joined it before it relocalised). A hand-built map stands in for the
running system: GoalGuidance reads its session and plans on it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from tests.navigation.streets import ladder

from neoslam.config import NeoSLAMConfig
from neoslam.geometry import invert_pose, robot_points_to_camera
from neoslam.navigation.session import GoalGuidance
from neoslam.types import Frame, MapState, ObjectObservation, SessionRecord


@dataclass
class _Running(MapState):
    """A map with the running session a NeoSLAM has: session 2, relocalised at its frame 5."""

    session: SessionRecord = SessionRecord(2, "later", 10, 5)


def _running(state: MapState) -> _Running:
    return _Running(**{f.name: getattr(state, f.name) for f in dataclasses.fields(MapState)})


def _frame(
    index: int, robot: np.ndarray | None = None, seen: tuple[tuple[str, tuple[float, float]], ...] = ()
) -> Frame:
    """A frame whose observations are objects (label, (x, y) in the map) seen from the robot's pose."""
    observations = []
    for label, (x, y) in seen:
        local = invert_pose(robot) @ np.array([x, y, 0.5, 1.0])
        centre = robot_points_to_camera(local[None, :3])[0]
        box = np.array([100.0, 100.0, 140.0, 130.0])
        observations.append(ObjectObservation(label, 0.9, box, box - [20.0, 0, 20.0, 0], centre, np.zeros((16, 16))))
    return Frame(index, 0.1 * index, np.eye(4), np.zeros(3), np.zeros(3), tuple(observations))


def test_an_object_this_session_saw_before_it_relocalised_is_reached_one_it_never_saw_is_missing():
    streets = ladder()
    builder = streets.builder
    own = builder.drive([(140, 2), (150, 2)], session=2, after=None)  # the later session's experiences
    builder.link(own[0], streets.at(140, 0))
    seen_now = builder.add_object("car", (150, -5, 0.5), {own[-1]: 3, streets.at(150, 0): 2})
    seen_before = builder.add_object("car", (60, -5, 0.5), {streets.at(60, 0): 3, streets.at(55, 0): 2})
    state = _running(builder.state())
    config = NeoSLAMConfig()
    for goal, expected in ((seen_now, "arrived"), (seen_before, "missing")):
        robot = state.experience_poses[streets.at(150 if goal == seen_now else 60, 0)]  # at the goal: no frame sees it
        guidance = GoalGuidance(f"object {goal}", config)
        guidance(state, _frame(5), robot)
        assert guidance.latest is not None and guidance.latest.state == expected
        assert guidance.summary()["goal_seen"] is (expected == "arrived")


def test_an_observation_nearer_another_object_of_the_class_is_that_one():
    """A car 3 m from the goal car: its observation, 2.2 m from the goal and 0.8 m from it, is no sighting of the
    goal (the goal car may have left); one nearer the goal is, once `navigation.sightings` frames have it. The robot
    sees them from the side: a stereo point on the near surface, whose object's middle is half a car's width (0.9 m)
    farther."""
    streets = ladder()
    builder = streets.builder
    seen_from = {streets.at(60, 0): 3, streets.at(55, 0): 2}
    goal = builder.add_object("car", (60, -5, 0.5), seen_from)
    builder.add_object("car", (60, -8, 0.5), seen_from)
    state = _running(builder.state())
    robot = state.experience_poses[streets.at(60, 0)]
    for seen, expected in (((60.0, -6.3), "missing"), ((60.0, -4.2), "arrived")):
        guidance = GoalGuidance(f"object {goal}", NeoSLAMConfig())
        states = []
        for index in range(5, 5 + NeoSLAMConfig().navigation.sightings):
            guidance(state, _frame(index, robot, (("car", seen),)), robot)
            assert guidance.latest is not None
            states.append(guidance.latest.state)
        needed = NeoSLAMConfig().navigation.sightings
        assert states == ["missing"] * (needed - 1) + [expected]  # a frame alone does not see it
