"""Guidance towards one goal during a run (`neoslam run --goal`, the live node's `--goal`, the closed-loop
benchmark): a step observer of the pipeline, which plans once the robot is localised in the map and then guides it,
a frame at a time.

Before the session has relocalised in a stored map the robot's pose is in no frame the map knows: the guidance says
so (`not_localised`). Once it is, the route is planned from where the robot is (its nearest experience) and a
`Guide` follows it, planning again when the robot leaves the route or is relocalised elsewhere (neoslam.navigation.
guidance). A goal that cannot be planned (unknown, stale, ambiguous, out of reach) makes every later frame
`unreachable`, with the reason.

An object goal must be seen to be reached: a parked car may have left since the map was made, and the map cannot know
it until the robot looks. Every frame's observations of the goal's class are placed in the map (the robot's pose
there, each moved from the surface the camera sees to the object's middle as the map's objects are); one within
`navigation.confirm_radius` of the goal object, and nearer to it than to any other object of its class in the map by
`navigation.sighting_margin` of its depth's std (a far view, metres off along its ray, of a car beside a goal that
left must not land on the goal; a car seen only from far, behind a row of others, must still be seen; the margin grows
with the goal's own std in the map, which a few far views place metres off), is a sighting. A neighbour that no
stretch of experiences around the goal's ever saw is taken for a copy of it (`navigation.copy_gap`: one car two passes
placed metres apart), not a rival. `navigation.sightings` frames with one see the goal object (a single far
observation of a neighbour can land on it: stereo depth is metres off at 50 m); so does the map's own record, when the
route is planned, that this session observed the goal object (before it relocalised, say: the car it has just passed,
which a route of a few metres reaches before the camera sees it again); so do the last `navigation.recall_frames`
frames before the session relocalised, placed in the map by the odometry from them once it has. A robot that reaches
an object goal this session has not seen is asked to look at it (`looking`: the bearing and distance are to the
object, for a robot to turn to it) for up to `navigation.look_time` seconds: the object seen then, it has `arrived`;
not seen, it is `missing` (the car has left).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.errors import GoalError
from neoslam.geometry import camera_points_to_robot
from neoslam.loop.keyframes import object_centres
from neoslam.mapping.object_map import depth_sigmas
from neoslam.navigation.goals import Goal, ObjectQuery, parse_goal
from neoslam.navigation.guidance import Guidance, Guide
from neoslam.navigation.route import Route, RoutePlanner
from neoslam.navigation.staleness import MapObjects
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
    goal's sighting, `looking` and then `missing` when an object goal was reached unseen, and why a goal is
    unreachable)."""

    frame: int
    state: str  # Guidance's states, `looking` and `missing`
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


@dataclass(frozen=True, slots=True)
class _Recalled:
    """A frame's observed objects, kept until the session is in the map's frame: their middles in the robot frame (as
    the map places objects: stereo points lie on the surface facing the camera) and the odometry pose then."""

    odometry_pose: np.ndarray  # (4, 4)
    labels: tuple[str, ...]
    centres: np.ndarray  # (k, 3) robot frame
    sigmas: np.ndarray  # (k,) each centre's std along its viewing ray, m

    @classmethod
    def of(cls, frame: Frame, config: NeoSLAMConfig) -> _Recalled:
        """The frame's observations, placed as the object map places them, with their depth's std."""
        observations = frame.observations
        if not observations:
            return cls(frame.odometry_pose, (), np.zeros((0, 3)), np.zeros(0))
        centres = camera_points_to_robot(object_centres(observations, config.keyframes.footprints))
        sigmas = depth_sigmas(observations, config.object_map)
        return cls(frame.odometry_pose, tuple(o.label for o in observations), centres, sigmas)


@dataclass
class _Events:
    """When the guidance reached its milestones (frame numbers), and how often it planned again."""

    localised: int | None = None
    planned: int | None = None
    arrived: int | None = None
    looking_since: float | None = None  # the time the robot reached an object goal it had not seen
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
        self._goal_sigma = 0.0  # the std of the goal object's position in the map, m
        self._recalled: deque[_Recalled] = deque(maxlen=config.navigation.recall_frames)  # before relocalising

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
            self._remember(frame)
            return GuidanceRecord(frame.index, "not_localised", None)
        if self.events.localised is None:
            self.events.localised = frame.index
        if self.error is not None:
            return GuidanceRecord(frame.index, "unreachable", None, reason=self.error)
        if self._guide is None and not self._plan(slam, in_map, frame):
            return GuidanceRecord(frame.index, "unreachable", None, reason=self.error)
        assert self._guide is not None
        guidance = self._guide.update(in_map)
        if guidance.state == "replanned":
            self.events.replans += 1
        self._sightings += self._sighted(frame, in_map)
        if guidance.arrived and self._is_object_goal() and not self._seen:
            return self._looking(frame, in_map, guidance)
        if guidance.arrived and self.events.arrived is None:
            self.events.arrived = frame.index
        return GuidanceRecord(frame.index, guidance.state, guidance, self._seen)

    def _looking(self, frame: Frame, pose: np.ndarray, guidance: Guidance) -> GuidanceRecord:
        """At an object goal not yet seen: the bearing to the object, to look at it, until look_time has passed."""
        if self.events.looking_since is None:
            self.events.looking_since = frame.timestamp
        if frame.timestamp - self.events.looking_since >= self.config.navigation.look_time:
            return GuidanceRecord(frame.index, "missing", guidance, False)
        route = self.route
        assert route is not None
        target = np.asarray(route.goal.target, dtype=float)
        in_robot = pose[:3, :3].T @ (target - pose[:3, 3])
        towards = replace(
            guidance,
            waypoint_position=target,
            distance_m=float(np.hypot(*(target[:2] - pose[:2, 3]))),
            bearing_rad=float(np.arctan2(in_robot[1], in_robot[0])),
        )
        return GuidanceRecord(frame.index, "looking", towards, False)

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

    def _plan(self, slam: NeoSLAM, pose: np.ndarray, frame: Frame) -> bool:
        """The first route, from where the robot is; False (and `error`) when the goal cannot be reached."""
        try:
            self._planner = RoutePlanner(slam, self.config)
            route = self._planner.plan(self.goal, start=pose, stale=self.stale)
        except GoalError as error:
            self.error = str(error)
            return False
        self._guide = Guide(route, self.config.navigation, replan=self._planner.replan)
        found = route.goal.object
        if found is not None:
            self._rivals, self._goal_sigma = self._rivals_of(route)
        if found is not None and slam.session.id in found.sessions:  # the map's record: this session saw it
            self._sightings = self.config.navigation.sightings
        self._sightings += self._recall(frame, pose)
        self.events.planned = frame.index
        self.events.first_route_m = route.length_m
        return True

    def _is_object_goal(self) -> bool:
        route = self.route
        return route is not None and route.goal.kind == "object"

    def _rivals_of(self, route: Route) -> tuple[np.ndarray, float]:
        """(k, 2) the positions of the map's other objects of the goal object's class within `rivals_within`
        confirm radii of it, but for its copies (`copy_gap`), and the std of the goal's own position."""
        assert self._planner is not None and route.goal.object is not None
        found, objects = route.goal.object, self._planner.objects()
        goal_row = objects.row(found.id)
        assert goal_row is not None
        navigation = self.config.navigation
        others = np.flatnonzero((objects.labels == found.label) & (objects.ids != found.id))
        near = np.hypot(*(objects.positions[others, :2] - found.position[:2]).T)
        others = others[near <= navigation.rivals_within * navigation.confirm_radius]
        rivals = [row for row in others if not self._copies(objects, goal_row, row)]
        return objects.positions[rivals, :2].reshape(-1, 2), float(objects.sigmas[goal_row])

    def _copies(self, objects: MapObjects, goal_row: int, row: int) -> bool:
        """Whether the object of `row` is a copy of the goal's: no experience within copy_gap ids of one that saw
        the goal saw it. Two cars side by side are seen from the same stretch of a pass; one car that two passes
        placed metres apart is seen by each pass as one of the two."""
        gap = self.config.navigation.copy_gap
        mine, theirs = objects.experiences_of(goal_row), objects.experiences_of(row)
        if gap == 0 or len(mine) == 0 or len(theirs) == 0:
            return False
        at = np.searchsorted(mine, theirs)
        before, after = mine[np.maximum(at - 1, 0)], mine[np.minimum(at, len(mine) - 1)]
        return bool(np.minimum(np.abs(theirs - before), np.abs(theirs - after)).min() > gap)

    def _remember(self, frame: Frame) -> None:
        """Keep a frame's observations from before the session relocalised (the last `recall_frames`)."""
        self._recalled.append(_Recalled.of(frame, self.config))

    def _recall(self, frame: Frame, pose: np.ndarray) -> int:
        """The frames before the session relocalised that saw the goal object, placed in the map by the odometry
        from them to this frame (`pose`, the first in the map's frame)."""
        to_map = pose @ np.linalg.inv(frame.odometry_pose)  # T_map_odometry
        found = 0
        for seen in self._recalled:
            found += self._sees(seen, to_map @ seen.odometry_pose)
        self._recalled.clear()
        return found

    def _sighted(self, frame: Frame, pose: np.ndarray) -> bool:
        """Whether the frame (its robot at `pose` in the map) saw the goal object."""
        if not frame.observations or not self._is_object_goal():
            return False
        return self._sees(_Recalled.of(frame, self.config), pose)

    def _sees(self, seen: _Recalled, pose: np.ndarray) -> bool:
        """Whether the objects `seen` (robot frame, each the middle of an observed object), seen from `pose` in the
        map, include the goal object: one of its class within confirm_radius of it and nearer to it than to any
        other object of its class in the map by sighting_margin of its depth's std (a neighbour's observation, off
        by its measurement and the map's error, is the neighbour's, and one that could be either is neither)."""
        route = self.route
        if route is None or route.goal.kind != "object" or route.goal.object is None:
            return False
        mine = np.array([label == route.goal.object.label for label in seen.labels], dtype=bool)
        if not mine.any():
            return False
        in_map = seen.centres[mine] @ pose[:3, :3].T + pose[:3, 3]
        gaps = np.hypot(*(in_map[:, :2] - route.goal.target[:2]).T)
        theirs = np.full(len(gaps), np.inf)
        if len(self._rivals):
            theirs = np.linalg.norm(in_map[:, None, :2] - self._rivals[None], axis=2).min(axis=1)
        navigation = self.config.navigation
        spread = np.hypot(seen.sigmas[mine], self._goal_sigma)  # the observation's and the goal's own
        clear = gaps + navigation.sighting_margin * spread < theirs
        return bool(((gaps <= navigation.confirm_radius) & clear).any())
