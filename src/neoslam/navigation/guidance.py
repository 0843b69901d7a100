"""Guidance along a route, frame by frame: where the next waypoint is (distance and bearing from the robot), how far
is left, whether the robot has arrived, and a new route when it left this one or was relocalised elsewhere
(OpenRatSLAM's range and bearing to the next sub-goal). Pure logic: poses in, records out, no I/O.

Each frame the robot's position is projected onto the route's segments in the ground plane, searched only near where
it was (from the segment before the last one to `jump_distance + off_route_distance + look_ahead` metres ahead), so a
frame costs the same on a route of 10 or 10,000 waypoints. The next waypoint is the first route experience at least
`look_ahead` metres ahead of that projection along the route; waypoints only advance, and a robot within
`waypoint_reached` of its next waypoint (not the end) has reached it (the projection moves on to it). The route is
planned again to the same goal (RoutePlanner.replan: from where the robot joins the map) when the robot is farther
than `off_route_distance` from it, when its pose jumped by more than `jump_distance` since the previous frame (it was
relocalised, or the map was corrected), or when it comes back localised off the route; never on other frames. A route
planned again starts with the straight way from where the robot is to the route's first experience, so a robot off the
map is planned for again only once it has gone another `off_route_distance` astray. A point goal off the route's last
experience, within `goal_radius` of it, is followed on to in a straight last leg, and so is the street point beside an
object goal (on a link of the route's last experience): that point is then the route's end. The robot has arrived once
it has reached the route's end within `arrival_radius` of it: its projection is within `end_reached` of the end, or
within `arrival_radius` of it with the end abeam or behind the robot (a pose estimate beside the route passes the end
without its projection reaching it). A robot that stops when told it arrived stops there, not on the rim of the radius
as it comes near; the radius is how far beside the end it may be (a pose estimate off the route, a goal off the
links). It stays arrived until `follow` gives it a new route.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from neoslam.config import NavigationConfig
from neoslam.errors import GoalError
from neoslam.navigation.resolution import ResolvedGoal
from neoslam.navigation.route import Route, leg_to, route_finish

__all__ = ["Guidance", "GuidanceState", "Guide", "Replan"]

GuidanceState = Literal["not_localised", "on_route", "off_route", "replanned", "arrived", "unreachable"]
Replan = Callable[[ResolvedGoal, np.ndarray], Route]  # (goal, position in the map frame) -> a new route to it
_TINY = 1e-12  # a segment shorter than this (squared, m^2) is a point
_JOINED_M = 0.01  # a robot this close to a new route's start is on it (no approach segment)


@dataclass(frozen=True, slots=True)
class Guidance:
    """One frame's guidance. `state`: not_localised (no pose in the map's frame: nothing else is known),
    on_route, off_route (farther than off_route_distance and no planner to re-plan with), replanned (a new route
    this frame, `reason` says why), arrived, unreachable (no route from where the robot is; tried again once it has
    moved off_route_distance). Distances in metres in the ground plane; the bearing in radians in the robot frame
    (REP-103: x forward, y left; positive: the waypoint is to the left)."""

    state: GuidanceState
    route: Route | None  # the route followed (a new one after a re-plan)
    waypoint: int | None = None  # index of the next waypoint in route.experiences (len(route): a point goal's own)
    experience: int | None = None  # its experience (None: a point goal's own position, beyond the route's end)
    waypoint_position: np.ndarray | None = None  # (3,) map frame
    distance_m: float | None = None  # to the waypoint
    bearing_rad: float | None = None  # to the waypoint
    remaining_m: float | None = None  # along the route from the robot's projection to its end (and its approach)
    goal_distance_m: float | None = None  # straight to where the robot is guided (the route's end or the point)
    off_route_m: float | None = None  # from the route
    arrived: bool = False
    reason: Literal["off_route", "relocalised"] | None = None  # why a replanned route was planned


@dataclass
class _Progress:
    segment: int = 0  # the route segment the robot was last projected on
    along_m: float = 0.0  # its projection's distance along the route
    waypoint: int = 0


class Guide:
    """Follows one route for a robot, a pose a frame (see the module)."""

    def __init__(self, route: Route, config: NavigationConfig, replan: Replan | None = None) -> None:
        """`replan(goal, position)`: a new route to `goal` from a position in the map frame (RoutePlanner.replan);
        None: the robot off the route is told so (state off_route) and no route is planned."""
        self.config = config
        self._replan = replan
        self._window_m = config.jump_distance + config.off_route_distance + config.look_ahead
        self.follow(route)

    @property
    def route(self) -> Route:
        return self._route

    def follow(self, route: Route, origin: np.ndarray | None = None) -> None:
        """Guide along a new route from its start (not arrived). `origin`: where the robot is, off the route's
        start (a re-plan from a place the map does not hold): the way from there to the route's start is followed
        as its first segment, so the robot is on it."""
        self._route = route
        points = np.asarray(route.positions, dtype=float)
        along = np.asarray(route.along_m, dtype=float)
        index = np.arange(len(route))  # each internal point's waypoint in the route; -1: none (a point of its own)
        finish = route_finish(route.goal, points[-1], self.config)
        if finish is not None:
            points, along, index = leg_to(finish, points, along, index, self.config.goal_radius)
        self._offset = 0  # internal points before the route's first waypoint
        if origin is not None and np.hypot(*(points[0, :2] - origin[:2])) > _JOINED_M:
            approach = float(np.hypot(*(points[0, :2] - origin[:2])))
            points = np.concatenate([[[origin[0], origin[1], points[0, 2]]], points])
            along = np.concatenate([[0.0], along + approach])
            index = np.concatenate([[-1], index])
            self._offset = 1
        self._points = np.ascontiguousarray(points[:, :2])
        self._positions, self._along, self._index = points, along, index
        self._progress = _Progress(waypoint=self._offset)
        self._previous: np.ndarray | None = None  # the last localised position (ground plane)
        self._arrived = False
        self._failed_at: np.ndarray | None = None  # where the last re-plan found no route

    @property
    def _goal(self) -> np.ndarray:
        """(3,) where the robot is guided to: the route's end, or a point goal's own position."""
        return self._positions[-1]

    def update(self, pose: np.ndarray | None) -> Guidance:
        """Guidance for the robot at `pose` (T_map_robot, 4x4, map frame), or None when it is not localised."""
        if pose is None:
            self._previous = None
            return Guidance("not_localised", self._route, arrived=self._arrived)
        here = np.asarray(pose[:2, 3], dtype=float)
        previous, self._previous = self._previous, here
        if self._failed_at is not None:
            if np.hypot(*(here - self._failed_at)) < self.config.off_route_distance:
                return Guidance("unreachable", None, arrived=False)
            return self._planned_again(pose, "off_route")
        jumped = previous is not None and np.hypot(*(here - previous)) > self.config.jump_distance
        off, segment, along = self._project(here, whole=previous is None or jumped)
        away = off > self.config.off_route_distance
        if not self._arrived and (jumped or away) and self._replan is not None:
            return self._planned_again(pose, "relocalised" if jumped or previous is None else "off_route")
        self._progress.segment, self._progress.along_m = segment, along
        self._reach_waypoint(here)
        return self._guidance(pose, "off_route" if away else "on_route", off)

    def _reach_waypoint(self, here: np.ndarray) -> None:
        """Within `waypoint_reached` of the next waypoint, the robot is there: its progress moves on to it (where a
        route turns back on itself, the projection finds the way there, nearer, and the waypoint is never passed).
        Not the route's end: arrival there is `_at_end`'s, nearer than this."""
        point = self._progress.waypoint
        if point >= len(self._points) - 1 or self._along[point] <= self._progress.along_m:
            return
        if np.hypot(*(self._points[point] - here)) <= self.config.waypoint_reached:
            self._progress.along_m = float(self._along[point])
            self._progress.segment = point

    def _planned_again(self, pose: np.ndarray, reason: Literal["off_route", "relocalised"]) -> Guidance:
        assert self._replan is not None
        try:
            route = self._replan(self._route.goal, np.asarray(pose[:3, 3], dtype=float))
        except GoalError:
            self._failed_at = np.asarray(pose[:2, 3], dtype=float)
            return Guidance("unreachable", None, arrived=False)
        here = np.asarray(pose[:2, 3], dtype=float)
        self.follow(route, origin=here)
        self._previous = here
        off, self._progress.segment, self._progress.along_m = self._project(here, whole=True)
        return self._guidance(pose, "replanned", off, reason)

    def _project(self, here: np.ndarray, whole: bool) -> tuple[float, int, float]:
        """The robot's distance from the route, the segment it is nearest and its distance along the route there;
        searched over the segments near the last projection, or over `whole` route."""
        points, along = self._points, self._along
        if len(points) == 1:
            return float(np.hypot(*(here - points[0]))), 0, 0.0
        last = len(points) - 1  # segments 0 .. last - 1
        if whole:
            low, high = 0, last
        else:
            low = max(self._progress.segment - 1, 0)
            high = int(np.searchsorted(along, self._progress.along_m + self._window_m, side="right"))
            high = min(max(high, low + 1), last)
        start, end = points[low:high], points[low + 1 : high + 1]
        step = end - start
        squared = np.einsum("ij,ij->i", step, step)
        t = np.clip(np.einsum("ij,ij->i", here - start, step) / np.maximum(squared, _TINY), 0.0, 1.0)
        gaps = np.hypot(*(start + t[:, None] * step - here).T)
        nearest = int(np.argmin(gaps))
        segment = low + nearest
        distance_along = along[segment] + t[nearest] * (along[segment + 1] - along[segment])
        return float(gaps[nearest]), segment, float(distance_along)

    def _at_end(self, pose: np.ndarray) -> bool:
        """Whether the robot has reached the route's end: projected within `end_reached` of it, or within
        `arrival_radius` of it along the route with the end abeam or behind (it passes the end beside the route, a
        pose estimate off the links, and comes no nearer by driving on)."""
        left = self._along[-1] - self._progress.along_m
        if left <= self.config.end_reached:
            return True
        ahead = float(pose[:3, 0] @ (self._goal - pose[:3, 3]))  # along the robot's x axis (REP-103: forward)
        return left <= self.config.arrival_radius and ahead <= 0.0

    def _guidance(
        self,
        pose: np.ndarray,
        state: GuidanceState,
        off: float,
        reason: Literal["off_route", "relocalised"] | None = None,
    ) -> Guidance:
        route, config = self._route, self.config
        goal_distance = float(np.hypot(*(pose[:2, 3] - self._goal[:2])))
        if goal_distance <= config.arrival_radius and self._at_end(pose):
            self._arrived = True
        ahead = int(np.searchsorted(self._along, self._progress.along_m + config.look_ahead, side="left"))
        point = max(self._progress.waypoint, min(ahead, len(self._along) - 1))  # an internal point: a waypoint
        self._progress.waypoint = point
        waypoint = int(self._index[point])
        on_route = waypoint >= 0
        target = self._positions[point]
        in_robot = pose[:3, :3].T @ (target - pose[:3, 3])
        return Guidance(
            state="arrived" if self._arrived else state,
            route=route,
            waypoint=waypoint if on_route else len(route),
            experience=int(route.experiences[waypoint]) if on_route else None,
            waypoint_position=target,
            distance_m=float(np.hypot(*(target[:2] - pose[:2, 3]))),
            bearing_rad=float(np.arctan2(in_robot[1], in_robot[0])),
            remaining_m=float(self._along[-1] - self._progress.along_m),
            goal_distance_m=goal_distance,
            off_route_m=off,
            arrived=self._arrived,
            reason=reason,
        )
