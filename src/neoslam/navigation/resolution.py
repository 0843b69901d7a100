"""Goals resolved against a map: which experience a route ends at, and what position the goal stands for.

An experience, a keyframe's experience and a session's start are experiences of the map: the route ends there. A point
or an object is a target off the links: the route ends at an experience within `navigation.goal_radius` of it, the one
nearest to it unless another saves a long detour (route plus LEG_WEIGHT times the straight distance, least), or at its
nearest experience when none is that close. A route to an object ends at the point of the street beside it, on a link
of that experience (experiences are metres apart: the robot stops beside the object, not at the experience before or
after it): it is planned to the link's end it reaches first, and goes on along the link.
An object query ranks every object that passes its filters by route plus straight distance to it and takes the nearest
(ties: the lowest id); `the CLASS` takes the only one. Stale objects (see staleness) are left out unless the goal or
the caller allows them. The experiences near every object are found once per map (one KD-tree query), so a query over
thousands of objects costs a few array operations after Dijkstra.

Every refusal is one GoalError naming the goal and the problem: an unknown id, a class the map does not hold, an
ambiguous `the`, only stale candidates, a point off the map; NoRouteError when no route reaches it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from neoslam.config import NavigationConfig
from neoslam.errors import GoalError, NoRouteError
from neoslam.navigation.goals import ExperienceGoal, Goal, KeyframeGoal, ObjectGoal, ObjectQuery, PointGoal, StartGoal
from neoslam.navigation.graph import NavigationGraph, ShortestPaths
from neoslam.navigation.staleness import MapObjects, ObjectStatus
from neoslam.navigation.view import MapView

__all__ = ["LEG_WEIGHT", "GoalKind", "MapGoals", "ResolvedGoal", "street_beside"]

GoalKind = Literal["experience", "keyframe", "point", "start", "object"]
_LISTED = 5  # ids named in an error line at most
# A metre between a route's end and its target costs as much as this many along the route: the route ends next to
# the target unless a stop a metre farther saves a detour of more than this (at 1, it would stop short, where the
# straight line to the target cuts the corner).
LEG_WEIGHT = 10.0
_TINY = 1e-12  # a link shorter than this (squared, m^2) is a point


@dataclass(frozen=True)
class ResolvedGoal:
    """A goal as the map resolved it. `position` is where the route ends: its last experience's corrected position,
    or for an object the point of that experience's links nearest to it (the street beside it; guidance goes on along
    the link to it, and from the experience to a point goal's target within goal_radius of it); `target` what the goal
    stands for (the object, the point, or the experience itself)."""

    kind: GoalKind
    text: str  # the goal as asked, in its canonical form
    description: str  # what it resolved to, for a person
    ids: tuple[int, ...]  # what it names: (experience,), (keyframe,), (object,), (session,); a point: ()
    experience: int  # where the route ends
    position: np.ndarray  # (3,)
    target: np.ndarray  # (3,)
    object: ObjectStatus | None = None  # an object goal's object

    @property
    def offset_m(self) -> float:
        """Ground-plane distance from the route's end to the target."""
        return float(np.linalg.norm(self.target[:2] - self.position[:2]))


@dataclass(frozen=True)
class _Reach:
    """Targets and the experiences they are reached from, flattened: pair i joins target `owner[i]` (increasing)
    and experience `experience[i]`, `leg[i]` metres apart in the ground plane."""

    owner: np.ndarray
    experience: np.ndarray
    leg: np.ndarray

    def of(self, chosen: np.ndarray) -> _Reach:
        """The pairs of the chosen targets (a boolean mask over the targets)."""
        kept = chosen[self.owner]
        return _Reach(self.owner[kept], self.experience[kept], self.leg[kept])


class MapGoals:
    """Resolves goals against one map: its view, navigation graph and objects (computed when first asked)."""

    def __init__(
        self, view: MapView, graph: NavigationGraph, config: NavigationConfig, objects: Callable[[], MapObjects]
    ) -> None:
        self.view, self.graph, self.config = view, graph, config
        self._objects = objects
        self._object_reach: _Reach | None = None

    # Places that need no route to be found: starts

    def start_experience(self, goal: Goal) -> int:
        """The experience a route starts from, for a goal used as a start (an object query must name one object)."""
        if isinstance(goal, ObjectQuery):
            rows = self._query_rows(goal, allow_stale=True)
            if len(rows) > 1:
                listed = ", ".join(str(i) for i in self._objects().ids[rows[:_LISTED]])
                raise GoalError(f"start {goal.describe()!r}: {len(rows)} objects match ({listed}); name one")
            return self.graph.nearest(self._objects().positions[rows[0]])[0]
        if isinstance(goal, ObjectGoal):
            return self.graph.nearest(self._object(goal, allow_stale=True).position)[0]
        if isinstance(goal, PointGoal):
            return self.graph.nearest(self._point(goal))[0]
        return self._experience_of(goal)[0]

    # Goals, with the routes from the start

    def resolve(self, goal: Goal, paths: ShortestPaths, allow_stale: bool = False) -> ResolvedGoal:
        """The goal against the map, with the routes from the start (which rank the candidates)."""
        text = goal.describe()
        if isinstance(goal, ObjectGoal):
            found = self._object(goal, allow_stale or goal.stale)
            return self._at_object(text, found, paths, f"{found.label} {found.id}")
        if isinstance(goal, ObjectQuery):
            return self._nearest_object(goal, paths, allow_stale or goal.stale)
        if isinstance(goal, PointGoal):
            target = self._point(goal)
            experience = self._stop(self._reach(target[None]), paths, text)[0]
            description = f"point ({target[0]:.1f}, {target[1]:.1f}), reached from experience {experience}"
            return self._resolved("point", text, description, (), experience, target)
        experience, description, ids = self._experience_of(goal)
        return self._resolved(_kind(goal), text, description, ids, experience, self.graph.positions[experience])

    def _resolved(self, kind, text, description, ids, experience, target, found=None, position=None) -> ResolvedGoal:
        position = self.graph.positions[experience].copy() if position is None else position
        return ResolvedGoal(kind, text, description, ids, int(experience), position, np.asarray(target), found)

    def _experience_of(self, goal: Goal) -> tuple[int, str, tuple[int, ...]]:
        """An experience goal, a keyframe's experience or a session's start: (experience, description, ids)."""
        text = goal.describe()
        n = len(self.graph)
        if isinstance(goal, ExperienceGoal):
            if goal.id >= n:
                raise GoalError(f"goal {text!r}: no such experience; the map has experiences 0 to {n - 1}")
            return goal.id, text, (goal.id,)
        if isinstance(goal, KeyframeGoal):
            experience = self.view.keyframe_experience.get(goal.id)
            if experience is None or experience >= n:
                raise GoalError(f"goal {text!r}: no such keyframe in the map (a keyframe seen again is not stored)")
            return experience, f"{text} (experience {experience})", (goal.id,)
        assert isinstance(goal, StartGoal)
        sessions = self.graph.sessions
        session = int(sessions.max()) if goal.session is None else goal.session
        made = np.flatnonzero(sessions == session)
        if len(made) == 0:
            known = sorted({int(s) for s in sessions})
            raise GoalError(f"goal {text!r}: session {session} made no experience (sessions with some: {known})")
        experience = int(made[0])
        return experience, f"start of session {session} (experience {experience})", (session,)

    # Targets off the links: points and objects

    def _point(self, goal: PointGoal) -> np.ndarray:
        nearest, distance = self.graph.nearest(np.array([goal.x, goal.y]))
        if distance > self.config.max_goal_distance:
            raise GoalError(
                f"goal {goal.describe()!r}: {distance:.1f} m from the nearest experience, farther than "
                f"navigation.max_goal_distance ({self.config.max_goal_distance:g} m): the map does not go there"
            )
        z = self.graph.positions[nearest, 2] if goal.z is None else goal.z
        return np.array([goal.x, goal.y, z])

    def _reach(self, targets: np.ndarray) -> _Reach:
        """The experiences within goal_radius of each target (none that close: its nearest), one KD-tree query."""
        nearby = self.graph.tree.query_ball_point(targets[:, :2], self.config.goal_radius)
        nearest = np.atleast_1d(self.graph.tree.query(targets[:, :2])[1]) if len(targets) else np.zeros(0, int)
        found = [np.sort(near) if len(near) else nearest[i : i + 1] for i, near in enumerate(nearby)]
        owner = np.repeat(np.arange(len(targets)), [len(near) for near in found])
        experience = np.concatenate(found) if found else np.zeros(0, dtype=int)
        leg = np.linalg.norm(self.graph.positions[experience, :2] - targets[owner, :2], axis=1)
        return _Reach(owner, experience, leg)

    def _stop(self, reach: _Reach, paths: ShortestPaths, text: str) -> tuple[int, int, float]:
        """Where the route to the nearest of the targets ends: (experience, target, cost). Each target's stop is its
        reachable experience with the least route plus LEG_WEIGHT times straight distance: next to the target, short
        of a long detour. The targets rank by route plus straight distance (as time at expected_speed with cost:
        time); ties go to the lowest target, then the lowest experience id."""
        leg = reach.leg / self.config.expected_speed if self.config.cost == "time" else reach.leg
        route = paths.costs[reach.experience]
        stops = _first_least(reach.owner, route + LEG_WEIGHT * leg)  # the pairs hold each target's ids increasing
        stops = stops[np.isfinite(route[stops])]
        if len(stops) == 0:
            raise NoRouteError(
                f"goal {text!r}: no route from experience {paths.start} reaches it (it lies in a part of the map "
                "never linked to the start)"
            )
        best = stops[int(np.argmin(route[stops] + leg[stops]))]
        return int(reach.experience[best]), int(reach.owner[best]), float(route[best] + leg[best])

    # Objects

    def _object(self, goal: ObjectGoal, allow_stale: bool) -> ObjectStatus:
        objects = self._objects()
        row = objects.row(goal.id)
        text = goal.describe()
        if row is None:
            total = len(self.view.objects.labels)
            if goal.id >= total:
                raise GoalError(f"goal {text!r}: no such object; the map's object ids run from 0 to {total - 1}")
            raise GoalError(f"goal {text!r}: not in the map (merged into another, forgotten, or seen too few times)")
        found = objects.status(row)
        if found.stale and not allow_stale:
            raise GoalError(f"goal {text!r}: {_stale_note(found)}; say 'stale {text}' (--stale) to go there anyway")
        return found

    def _at_object(self, text: str, found: ObjectStatus, paths: ShortestPaths, what: str, row=None) -> ResolvedGoal:
        if row is None:
            reach = self._reach(found.position[None])
        else:
            chosen = np.zeros(len(self._objects()), dtype=bool)
            chosen[row] = True
            reach = self._objects_reach().of(chosen)
        experience = self._stop(reach, paths, text)[0]
        beside, other = street_beside(self.graph, experience, found.position)
        if other >= 0 and paths.predecessors[experience] == other:
            experience = other  # the route passes the object on its way to the stop: it ends before, and goes on
        seen = f"seen {found.observations} times, last {found.last_seen()}" + (", stale" if found.stale else "")
        ids = (found.id,)
        return self._resolved("object", text, f"{what} ({seen})", ids, experience, found.position, found, beside)

    def _objects_reach(self) -> _Reach:
        if self._object_reach is None:
            self._object_reach = self._reach(self._objects().positions)
        return self._object_reach

    def _query_rows(self, query: ObjectQuery, allow_stale: bool) -> np.ndarray:
        """The rows of the objects a query names, increasing; GoalError when none is left."""
        text = query.describe()
        objects = self._objects()
        labelled = objects.keys == query.label
        if not labelled.any():
            classes = sorted({str(label) for label in objects.labels})
            held = f"its classes: {', '.join(classes)}" if classes else "it holds no objects"
            raise GoalError(f"goal {text!r}: no {query.label} in the map ({held})")
        kept = labelled.copy()
        if query.min_observations is not None:
            kept &= objects.observations >= query.min_observations
        if query.session is not None:
            kept &= objects.seen_in(query.session)
        if not kept.any():
            count = int(labelled.sum())
            raise GoalError(f"goal {text!r}: none of the map's {count} {query.label} objects passes its filters")
        fresh = kept if allow_stale else kept & ~objects.stale
        if not fresh.any():
            notes = "; ".join(f"object {o.id} {_stale_note(o)}" for o in map(objects.status, np.flatnonzero(kept)[:2]))
            raise GoalError(f"goal {text!r}: every match is stale ({notes}); say 'stale {query.label}' (--stale)")
        return np.flatnonzero(fresh)

    def _nearest_object(self, query: ObjectQuery, paths: ShortestPaths, allow_stale: bool) -> ResolvedGoal:
        text = query.describe()
        rows = self._query_rows(query, allow_stale)
        objects = self._objects()
        if query.unique and len(rows) > 1:
            listed = ", ".join(str(i) for i in objects.ids[rows[:_LISTED]]) + (", ..." if len(rows) > _LISTED else "")
            raise GoalError(
                f"goal {text!r}: ambiguous, {len(rows)} {query.label} objects match (objects {listed}); say "
                f"'nearest {query.label}' or 'object {objects.ids[rows[0]]}'"
            )
        chosen = np.zeros(len(objects), dtype=bool)
        chosen[rows] = True
        row = self._stop(self._objects_reach().of(chosen), paths, text)[1]
        found = objects.status(row)
        what = f"{found.label} {found.id}"
        if len(rows) > 1:
            what += f", the nearest by route of {len(rows)}"
        return self._at_object(text, found, paths, what, row)


def street_beside(graph: NavigationGraph, experience: int, target: np.ndarray) -> tuple[np.ndarray, int]:
    """The point of the links of `experience` nearest to `target` in the ground plane, and the experience at the
    link's other end (the experience itself and -1 when no link passes nearer): where the street passes an object,
    which experiences metres apart straddle."""
    pairs = graph.pairs
    ends = np.concatenate([pairs[pairs[:, 0] == experience, 1], pairs[pairs[:, 1] == experience, 0]])
    start = graph.positions[experience]
    steps = graph.positions[ends] - start
    squared = np.einsum("ij,ij->i", steps[:, :2], steps[:, :2])
    t = np.clip((target[:2] - start[:2]) @ steps[:, :2].T / np.maximum(squared, _TINY), 0.0, 1.0)
    points = np.vstack([start, start + t[:, None] * steps])
    nearest = int(np.argmin(np.hypot(*(points[:, :2] - target[:2]).T)))
    return points[nearest].copy(), int(ends[nearest - 1]) if nearest else -1


def _first_least(groups: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per run of equal `groups` (increasing), the index of its first least value: no sort, a few passes."""
    starts = np.flatnonzero(np.r_[True, groups[1:] != groups[:-1]])
    least = np.repeat(np.minimum.reduceat(values, starts), np.diff(np.r_[starts, len(groups)]))
    candidates = np.flatnonzero(values == least)
    return candidates[np.r_[True, groups[candidates][1:] != groups[candidates][:-1]]]


def _kind(goal: Goal) -> GoalKind:
    return (
        "experience" if isinstance(goal, ExperienceGoal) else "keyframe" if isinstance(goal, KeyframeGoal) else "start"
    )


def _stale_note(found: ObjectStatus) -> str:
    return f"is stale: last seen {found.last_seen()}, missed from {found.misses} experiences since"
