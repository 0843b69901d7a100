"""Routes on the experience map: from where the robot is (or any place of the map) to a goal of the goal language,
over the map's links both ways, shortest by length (or expected time: `navigation.cost`).

`plan_route(map, goal)` plans once: it reads the map, builds its navigation graph and plans. `RoutePlanner` keeps
the graph for many plans on one map (a benchmark, guidance's re-plans) and follows a running NeoSLAM's map with
`refresh()`. A route on a running NeoSLAM starts by default from the experience the robot is in (once its session
is in the map's frame); on a stored map from the experience made last, unless `start` names another place.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from neoslam.config import NavigationConfig, NeoSLAMConfig
from neoslam.errors import GoalError, NoRouteError
from neoslam.navigation.goals import Goal, parse_goal
from neoslam.navigation.graph import NavigationGraph, ShortestPaths
from neoslam.navigation.resolution import MapGoals, ResolvedGoal, street_beside
from neoslam.navigation.staleness import MapObjects, map_objects
from neoslam.navigation.view import MapSource, MapView, map_view
from neoslam.pipeline import NeoSLAM

__all__ = ["Route", "RoutePlanner", "Start", "leg_to", "plan_route", "route_finish"]

# Where a route starts: None (the robot's experience, or a stored map's last), an experience id, a goal (text or
# typed) naming a place, or a position (3,) or pose (4, 4) in the map's frame (its nearest experience).
Start = int | str | Goal | np.ndarray | None
_TINY = 1e-12  # a segment shorter than this (squared, m^2) is a point
_JOINED_M = 0.01  # points this close are one


@dataclass(frozen=True)
class Route:
    """A route over the experience map, start first. Poses are the experiences' corrected poses T_map_robot (map
    frame); `along_m` the distance along the route at each of them (0 at the start); `length_m` to where it ends:
    its last experience, or the point it goes on to (an object's street point, a point goal: `route_finish`);
    `path` the line a robot follows there, which ends at that point (cut where the route passes it)."""

    experiences: np.ndarray  # (m,) int
    poses: np.ndarray  # (m, 4, 4)
    along_m: np.ndarray  # (m,)
    length_m: float
    expected_time_s: float | None  # None: no experience on it recorded a speed (the time would be a guess)
    goal: ResolvedGoal
    start: int  # the experience it starts from
    path: np.ndarray  # (k, 3) map frame

    def __len__(self) -> int:
        return len(self.experiences)

    @property
    def positions(self) -> np.ndarray:
        """(m, 3) the waypoints' positions."""
        return self.poses[:, :3, 3]


class RoutePlanner:
    """Plans routes on one map (a `MapState` or a running `NeoSLAM`), keeping its navigation graph between plans."""

    def __init__(self, source: MapSource, config: NeoSLAMConfig | None = None) -> None:
        """`config`: its `navigation` section and `object_map.min_observations` (default: a running NeoSLAM's own,
        else the defaults)."""
        self.source = source
        if config is None:
            config = source.config if isinstance(source, NeoSLAM) else NeoSLAMConfig()
        self.config = config
        self.view: MapView = map_view(source)
        self.graph = NavigationGraph.build(self.view, config.navigation)
        self._objects: MapObjects | None = None
        self.goals = MapGoals(self.view, self.graph, config.navigation, self.objects)

    def refresh(self) -> bool:
        """Read the map again (a running NeoSLAM's grows and is corrected): new experiences and links, moved poses,
        objects; the graph's matrix and tree are rebuilt when next used, only if something changed. Returns
        whether the graph changed."""
        self.view = map_view(self.source)
        changed = self.graph.update(self.view)
        self._objects = None  # objects gain observations every frame
        self.goals = MapGoals(self.view, self.graph, self.config.navigation, self.objects)
        return changed

    def objects(self) -> MapObjects:
        """The map's objects with their staleness (computed once per refresh; `.statuses()` lists them)."""
        if self._objects is None:
            min_observations = self.config.object_map.min_observations
            self._objects = map_objects(self.view, self.graph, self.config.navigation, min_observations)
        return self._objects

    def start_of(self, start: Start = None) -> int:
        """The experience a route starts from (see `Start`)."""
        self._require_experiences()
        if start is None:
            if not isinstance(self.source, NeoSLAM):
                return len(self.graph) - 1  # a stored map: the experience made last
            if not self.view.localised or self.view.current is None:
                raise GoalError("the robot is not localised in the map yet: its session has not relocalised in it")
            return self.view.current
        if isinstance(start, np.ndarray):
            point = start[:3, 3] if start.shape == (4, 4) else start
            return self.graph.nearest(point)[0]
        if isinstance(start, int | np.integer) and not isinstance(start, bool):
            if not 0 <= start < len(self.graph):
                raise GoalError(f"start experience {start}: the map has experiences 0 to {len(self.graph) - 1}")
            return int(start)
        return self.goals.start_experience(parse_goal(start) if isinstance(start, str) else start)

    def plan(self, goal: Goal | str, start: Start = None, stale: bool = False) -> Route:
        """The shortest route from `start` to `goal` (text of the goal language or a typed goal) on the map as it is
        (a running NeoSLAM's read again first); `stale` allows a stale object as the goal. A position start whose
        nearest experience lies in a part of the map with no route to the goal starts at the nearest experience of
        another part within `off_route_distance` that has one (see _starts). GoalError (NoRouteError when no route
        reaches it) naming the goal otherwise."""
        goal = parse_goal(goal) if isinstance(goal, str) else goal
        if isinstance(self.source, NeoSLAM):
            self.refresh()
        self._require_experiences()
        *others, last = self._starts(start)
        for begin in others:
            try:
                return self._planned(goal, begin, stale)
            except NoRouteError:
                continue  # the goal lies in another part of the map: try the next part beside the start
        return self._planned(goal, last, stale)

    def _planned(self, goal: Goal, start: int, stale: bool) -> Route:
        paths = self.graph.shortest_paths(start)
        return self._route(paths, self.goals.resolve(goal, paths, stale))

    def _starts(self, start: Start) -> list[int]:
        """The experiences a route may start from, in the order tried: the start's own; for a position, then the
        nearest experience of each other part of the map within `off_route_distance` of it, nearest first. A robot
        that has just relocalised is in the map's frame, but the experiences it made since it started are linked to
        the map only once a closure ties them to it: its route starts at the map beside it."""
        first = self.start_of(start)
        if not isinstance(start, np.ndarray):
            return [first]
        point = start[:3, 3] if start.shape == (4, 4) else start
        near = self.graph.within(point, self.config.navigation.off_route_distance)
        near = near[np.argsort(np.linalg.norm(self.graph.positions[near, :2] - point[:2], axis=1), kind="stable")]
        parts = self.graph.components
        starts, seen = [first], {int(parts[first])}
        for experience in near.tolist():
            if int(parts[experience]) not in seen:
                seen.add(int(parts[experience]))
                starts.append(experience)
        return starts

    def replan(self, goal: ResolvedGoal, position: np.ndarray) -> Route:
        """A route to a goal resolved before from where the robot is (`position`, map frame), on the map as it is
        now (guidance plans again with it when the robot left the route or was relocalised). The robot joins the
        map at the experience within `off_route_distance` of it (none: its nearest) whose straight distance plus
        route to the goal is least, so a robot that has passed an experience joins ahead of it, not back there:
        one Dijkstra from the goal (the links go both ways)."""
        if isinstance(self.source, NeoSLAM):
            self.refresh()
        self._require_experiences()
        end = goal.experience
        paths = self.graph.shortest_paths(end)
        here = np.asarray(position, dtype=float)
        joins = self.graph.within(here, self.config.navigation.off_route_distance)
        if len(joins) == 0:
            joins = np.array([self.graph.nearest(here)[0]])
        approach = np.linalg.norm(self.graph.positions[joins, :2] - here[:2], axis=1)
        if self.config.navigation.cost == "time":
            approach = approach / self.config.navigation.expected_speed
        costs = paths.costs[joins] + approach
        if not np.isfinite(costs).any():
            raise NoRouteError(
                f"goal {goal.text!r}: no route from experience {joins[0]} to experience {end} (they lie in parts of "
                "the map never linked)"
            )
        start = int(joins[int(np.argmin(costs))])
        position_now = self.graph.positions[end].copy()
        if goal.kind == "object":
            position_now = street_beside(self.graph, end, goal.target)[0]
        moved = goal.target if goal.kind in ("point", "object") else position_now  # an experience moves with the map
        return self._along(paths.path(start)[::-1], dataclasses.replace(goal, position=position_now, target=moved))

    def _route(self, paths: ShortestPaths, goal: ResolvedGoal) -> Route:
        if not paths.reachable(goal.experience):
            raise NoRouteError(
                f"goal {goal.text!r}: no route from experience {paths.start} to experience {goal.experience} "
                "(they lie in parts of the map never linked)"
            )
        return self._along(paths.path(goal.experience), goal)

    def _along(self, path: np.ndarray, goal: ResolvedGoal) -> Route:
        """The route along a path of experiences, start first; its length to where it ends (route_finish)."""
        steps = (path[:-1], path[1:])
        along = np.concatenate([[0.0], np.cumsum(self.graph.lengths(*steps))])
        expected = float(self.graph.times(*steps).sum()) if self.graph.known_speed(path) else None
        poses = np.array(self.view.poses[path], dtype=float)
        points, length = poses[:, :3, 3].copy(), float(along[-1])
        navigation = self.config.navigation
        finish = route_finish(goal, points[-1], navigation)
        if finish is not None:
            points, cut_along, _ = leg_to(finish, points, along, np.arange(len(path)), navigation.goal_radius)
            length = float(cut_along[-1])
        return Route(path, poses, along, length, expected, goal, int(path[0]), points)

    def _require_experiences(self) -> None:
        if len(self.graph) == 0:
            raise GoalError("the map is empty: it holds no experience to plan a route on")


def plan_route(
    source: MapSource, goal: Goal | str, start: Start = None, config: NeoSLAMConfig | None = None, stale: bool = False
) -> Route:
    """The shortest route on a map (a `MapState` or a running `NeoSLAM`) from `start` to `goal`; see RoutePlanner."""
    return RoutePlanner(source, config).plan(goal, start, stale)


def route_finish(goal: ResolvedGoal, last: np.ndarray, config: NavigationConfig) -> np.ndarray | None:
    """Where a route goes on to from its last experience (`last`, its position), None when it ends there: the street
    point beside an object goal (on a link of the experience), or a point goal's own position when it lies within
    goal_radius (the experience may be half the spacing of experiences away, or past it)."""
    if goal.kind == "object":
        finish = np.asarray(goal.position, dtype=float)
        gap, bound = float(np.hypot(*(finish[:2] - last[:2]))), np.inf  # on a link: the street, however long
    elif goal.kind == "point":
        finish, gap, bound = np.asarray(goal.target, dtype=float), goal.offset_m, config.goal_radius
    else:
        return None
    return finish if _JOINED_M < gap <= bound else None


def leg_to(
    finish: np.ndarray, points: np.ndarray, along: np.ndarray, index: np.ndarray, within: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The route's points (n, 3), distances along it and waypoint indices (`index`, -1: a point of its own), cut
    where its last `within` metres pass nearest to `finish` and going on from there straight to it: a route that
    passes beside a point goal to end at an experience beyond it does not drive past the point and back."""
    cut, at, along_at, gap = len(points) - 1, points[-1], float(along[-1]), np.inf
    first = max(int(np.searchsorted(along, along[-1] - within, side="left")) - 1, 0)
    for k in range(first, len(points) - 1):  # a few segments: experiences are metres apart
        step = points[k + 1] - points[k]
        squared = float(step[:2] @ step[:2])
        t = float(np.clip((finish[:2] - points[k, :2]) @ step[:2] / max(squared, _TINY), 0.0, 1.0))
        here = points[k] + t * step
        distance = float(np.hypot(*(here[:2] - finish[:2])))
        if distance <= gap:  # the later of equals: the route's end when it is as near
            cut, at, along_at, gap = k, here, float(along[k] + t * (along[k + 1] - along[k])), distance
    kept = slice(0, cut + 1)
    points, along, index = points[kept], along[kept], index[kept]
    if np.hypot(*(at[:2] - points[-1, :2])) > _JOINED_M:  # cut inside a segment: its own point
        points, along, index = np.concatenate([points, at[None]]), np.append(along, along_at), np.append(index, -1)
    leg = float(np.hypot(*(finish[:2] - points[-1, :2])))
    if leg <= _JOINED_M:  # the route passes through it
        return points, along, index
    return np.concatenate([points, finish[None, :3]]), np.append(along, along[-1] + leg), np.append(index, -1)
