"""`neoslam route`: a route on a stored map to a goal of the goal language (neoslam.navigation.goals), written as a
folder: route.csv (a row per waypoint), route.json (GeoJSON-like, map frame) and route.png (the route over the map).

The map is opened read-only, with the config it was made with (as `neoslam run --map` opens it: the sections that
shape a map must match) and left exactly as it was. A bad goal, an empty map, no route: one line naming the map
and the goal.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from neoslam.config import NeoSLAMConfig
from neoslam.errors import GoalError, InputError
from neoslam.io.atomic import atomic_directory, check_target
from neoslam.io.route_files import write_route_csv, write_route_json
from neoslam.navigation import Goal, Route, RoutePlanner, parse_goal
from neoslam.store.map_file import MapFile
from neoslam.types import MapState
from neoslam.viz.route_plots import plot_route

__all__ = ["RouteReport", "route_on_map"]


@dataclass(frozen=True)
class RouteReport:
    """What `neoslam route` planned and how long it took."""

    route: Route
    out: Path
    graph_ms: float  # building the navigation graph (links, sparse matrix, KD-tree)
    planning_ms: float  # the plan: start, goal (with the objects' staleness for an object goal), Dijkstra, path
    objects: int  # objects in the map (seen min_observations times)
    stale_objects: int


def route_on_map(
    map_path: Path,
    goal: str,
    out: Path,
    config: NeoSLAMConfig,
    start: str | None = None,
    stale: bool = False,
    overwrite: bool = False,
    read: Sequence[Path | None] = (),
) -> RouteReport:
    """Plan a route on the map file from `start` (default: the experience made last) to `goal` (`stale`: a stale
    object may be the goal) and write the route folder `out`. `read` names further files read (a config file)."""
    inputs = [map_path, *read]
    check_target(out, overwrite, inputs)
    wanted = _parsed(map_path, goal)
    origin = None if start is None else _parsed(map_path, start)
    state = _load(map_path, config)
    began = time.perf_counter()
    planner = RoutePlanner(state, config)
    planner.graph.matrix, planner.graph.tree  # noqa: B018 (built now, so the plan's time is the plan's alone)
    planned = time.perf_counter()
    try:
        route = planner.plan(wanted, origin, stale)
    except GoalError as error:
        raise type(error)(f"{map_path}: {error}") from None
    done = time.perf_counter()
    objects = planner.objects()
    graph = planner.graph
    with atomic_directory(out, overwrite, inputs) as staging:
        write_route_csv(staging / "route.csv", route)
        write_route_json(staging / "route.json", route)
        plot_route(staging / "route.png", graph.positions, graph.pairs, route, objects.statuses())
    return RouteReport(
        route=route,
        out=out,
        graph_ms=1e3 * (planned - began),
        planning_ms=1e3 * (done - planned),
        objects=len(objects),
        stale_objects=int(objects.stale.sum()),
    )


def _parsed(map_path: Path, text: str) -> Goal:
    try:
        return parse_goal(text)
    except GoalError as error:
        raise GoalError(f"{map_path}: {error}") from None


def _load(map_path: Path, config: NeoSLAMConfig) -> MapState:
    """The map, read-only; an empty one is refused."""
    with MapFile.open(map_path, config, read_only=True) as map_file:
        state = map_file.load()
    if not state.experiences:
        raise InputError(map_path, "empty map: it holds no experience to plan a route on")
    return state
