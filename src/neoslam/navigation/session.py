"""Guidance towards one goal during a run (`neoslam run --goal`, the live node's `--goal`, the closed-loop
benchmark): a step observer of the pipeline, which plans once the robot is localised in the map and then guides it,
a frame at a time.

Before the session has relocalised in a stored map the robot's pose is in no frame the map knows: the guidance says
so (`not_localised`). Once it is, the route is planned from where the robot is (its nearest experience) and a
`Guide` follows it, planning again when the robot leaves the route or is relocalised elsewhere (neoslam.navigation.
guidance). A goal that cannot be planned (unknown, stale, ambiguous, out of reach) makes every later frame
`unreachable`, with the reason.

An object goal must be seen to be reached: a parked car may have left since the map was made, and the map cannot
know it until the robot looks. Every frame's observations of the goal's class are placed in the map (the robot's
pose there, each moved from the surface the camera sees to the object's middle as the map's objects are); one within
`navigation.confirm_radius` of the goal object, and nearer to it than to any other object of its class in the map,
is a sighting. `navigation.sightings` frames with one see the goal object (a single far observation of a neighbour
can land on it: stereo depth is metres off at 50 m); so does the map's own record, when the route is planned, that
this session observed the goal object (before it relocalised, say: the car it has just passed, which a route of a
few metres reaches before the camera sees it again). Arriving at an object goal this session has not seen is
`missing`, not `arrived`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.errors import GoalError
from neoslam.geometry import camera_points_to_robot
from neoslam.loop.keyframes import object_centres
from neoslam.navigation.goals import Goal, ObjectQuery, parse_goal
from neoslam.navigation.guidance import Guidance, Guide
from neoslam.navigation.route import Route, RoutePlanner
from neoslam.navigation.view import pose_in_map
from neoslam.pipeline import NeoSLAM
from neoslam.types import Frame

__all__ = ["GoalGuidance", "GuidanceRecord", "GUIDANCE_COLUMNS"]


GUIDANCE_COLUMNS = (
    "frame",
    "state",
    "waypoint_experience",
    "waypoint_x",
    "waypoint_y",
    "distance_m",
    "bearing_deg",
    "remaining_m",
    "goal_distance_m",
    "off_route_m",
    "goal_seen",
)


@dataclass(frozen=True, slots=True)
class GuidanceRecord:
    """One frame's guidance as a run reports it: the guide's record and what the session adds (the frame, an object
    goal's sighting, `missing` when an object goal was reached unseen, and why a goal is unreachable)."""

    frame: int
    state: str  # Guidance's states, and `missing`
    guidance: Guidance | None
    goal_seen: bool = False
    reason: str | None = None

    def row(self) -> dict[str, object]:
        g = self.guidance
        waypoint = g.waypoint_position if g is not None and g.waypoint_position is not None else None
        bearing = g.bearing_rad if g is not None else None
        return {
            "frame": self.frame,
            "state": self.state,
            "waypoint_experience": g.experience if g is not None else None,
            "waypoint_x": None if waypoint is None else float(waypoint[0]),
            "waypoint_y": None if waypoint is None else float(waypoint[1]),
            "distance_m": g.distance_m if g is not None else None,
            "bearing_deg": None if bearing is None else float(np.degrees(bearing)),
            "remaining_m": g.remaining_m if g is not None else None,
            "goal_distance_m": g.goal_distance_m if g is not None else None,
            "off_route_m": g.off_route_m if g is not None else None,
            "goal_seen": self.goal_seen,
        }


@dataclass
class _Events:
    """When the guidance reached its milestones (frame numbers), and how often it planned again."""

    localised: int | None = None
    planned: int | None = None
    arrived: int | None = None
    replans: int = 0
    first_route_m: float | None = None


class GoalGuidance:
    """Guides a run towards `goal` (text of the goal language or a typed goal); call it as the pipeline's step
    observer, `guidance(slam, frame, pose)`; `latest` is the frame's record, `records` every frame's."""

    def __init__(self, goal: Goal | str, config: NeoSLAMConfig, stale: bool = False, keep: bool = True) -> None:
        """`stale`: a stale object may be the goal. `keep`: keep every frame's record (a long live run keeps
        only the latest)."""
        self.goal = parse_goal(goal) if isinstance(goal, str) else goal
        classes = config.perception.detector.classes
        if isinstance(self.goal, ObjectQuery) and self.goal.label not in classes:
            mapped = ", ".join(classes)
            raise GoalError(f"goal {self.goal.describe()!r}: the map holds no {self.goal.label} (it maps {mapped}: "
                            "perception.detector.classes)")  # fmt: skip
        self.config = config
        self.stale = stale
        self.keep = keep
        self.records: list[GuidanceRecord] = []
        self.latest: GuidanceRecord | None = None
        self.events = _Events()
        self.error: str | None = None  # why the goal is unreachable, once it is
        self._planner: RoutePlanner | None = None
        self._guide: Guide | None = None
        self._sightings = 0  # frames since the route was planned that saw the goal object
        self._rivals = np.zeros((0, 2))  # the map's other objects of the goal's class near it (ground plane)

    @property
    def _seen(self) -> bool:
        return self._sightings >= self.config.navigation.sightings

    @property
    def route(self) -> Route | None:
        return self._guide.route if self._guide is not None else None

    def __call__(self, slam: NeoSLAM, frame: Frame, pose: np.ndarray) -> None:
        record = self.update(slam, frame, pose)
        self.latest = record
        if self.keep:
            self.records.append(record)

    def update(self, slam: NeoSLAM, frame: Frame, pose: np.ndarray) -> GuidanceRecord:
        """The guidance of one frame, after `slam.step(frame)` returned `pose`."""
        in_map = pose_in_map(slam, pose)
        if in_map is None:
            return GuidanceRecord(frame.index, "not_localised", None)
        if self.events.localised is None:
            self.events.localised = frame.index
        if self.error is not None:
            return GuidanceRecord(frame.index, "unreachable", None, reason=self.error)
        if self._guide is None and not self._plan(slam, in_map, frame.index):
            return GuidanceRecord(frame.index, "unreachable", None, reason=self.error)
        assert self._guide is not None
        guidance = self._guide.update(in_map)
        if guidance.state == "replanned":
            self.events.replans += 1
        self._sightings += self._sighted(frame, in_map)
        state = guidance.state
        if guidance.arrived and self._is_object_goal() and not self._seen:
            state = "missing"
        elif guidance.arrived and self.events.arrived is None:
            self.events.arrived = frame.index
        return GuidanceRecord(frame.index, state, guidance, self._seen)

    def summary(self) -> dict[str, object]:
        """The guidance's figures for a run's metrics."""
        route = self.route
        latest = self.latest
        return {
            "goal": self.goal.describe(),
            "resolved": route.goal.description if route is not None else None,
            "state": latest.state if latest is not None else "not_localised",
            "reason": self.error,
            "localised_frame": self.events.localised,
            "planned_frame": self.events.planned,
            "arrived_frame": self.events.arrived,
            "replans": self.events.replans,
            "route_m": self.events.first_route_m,
            "goal_seen": self._seen,
        }

    def _plan(self, slam: NeoSLAM, pose: np.ndarray, frame_index: int) -> bool:
        """The first route, from where the robot is; False (and `error`) when the goal cannot be reached."""
        try:
            self._planner = RoutePlanner(slam, self.config)
            route = self._planner.plan(self.goal, start=pose, stale=self.stale)
        except GoalError as error:
            self.error = str(error)
            return False
        self._guide = Guide(route, self.config.navigation, replan=self._planner.replan)
        found = route.goal.object
        if found is not None and slam.session.id in found.sessions:  # the map's record: this session saw it
            self._sightings = self.config.navigation.sightings
        self._rivals = self._rivals_of(route) if found is not None else np.zeros((0, 2))
        self.events.planned = frame_index
        self.events.first_route_m = route.length_m
        return True

    def _is_object_goal(self) -> bool:
        route = self.route
        return route is not None and route.goal.kind == "object"

    def _rivals_of(self, route: Route) -> np.ndarray:
        """(k, 2) the positions of the map's other objects of the goal object's class within `rivals_within`
        confirm radii of it."""
        assert self._planner is not None and route.goal.object is not None
        found, objects = route.goal.object, self._planner.objects()
        others = (objects.labels == found.label) & (objects.ids != found.id)
        positions = objects.positions[others, :2]
        navigation = self.config.navigation
        near = np.hypot(*(positions - found.position[:2]).T) <= navigation.rivals_within * navigation.confirm_radius
        return positions[near]

    def _sighted(self, frame: Frame, pose: np.ndarray) -> bool:
        """Whether the frame saw the goal object: an observation of its class within confirm_radius of it and nearer
        to it than to any other object of its class in the map (a neighbour's observation, off by its measurement
        and the map's error, is the neighbour's)."""
        route = self.route
        if route is None or route.goal.kind != "object" or route.goal.object is None or not frame.observations:
            return False
        label = route.goal.object.label
        seen = tuple(o for o in frame.observations if o.label == label)
        if not seen:
            return False
        # the object's middle, as the map places it: stereo points lie on the surface facing the camera
        in_robot = camera_points_to_robot(object_centres(seen, self.config.keyframes.footprints))
        in_map = in_robot @ pose[:3, :3].T + pose[:3, 3]
        gaps = np.hypot(*(in_map[:, :2] - route.goal.target[:2]).T)
        theirs = np.full(len(gaps), np.inf)
        if len(self._rivals):
            theirs = np.linalg.norm(in_map[:, None, :2] - self._rivals[None], axis=2).min(axis=1)
        return bool(((gaps <= self.config.navigation.confirm_radius) & (gaps < theirs)).any())
