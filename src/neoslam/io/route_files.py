"""A route's files (`neoslam route`): route.csv, a row per waypoint, and route.json, the route as a GeoJSON-like
FeatureCollection. Coordinates are the map's frame in metres (x, y, z; REP-103, z up), not WGS84 longitude and
latitude: a GeoJSON reader takes them as planar coordinates. Values are written rounded, so the same route gives
the same bytes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.geometry import yaw_of
from neoslam.io.tables import write_table
from neoslam.navigation import ObjectStatus, Route
from neoslam.navigation.session import GUIDANCE_COLUMNS, GuidanceRecord

__all__ = ["ROUTE_COLUMNS", "route_features", "write_guidance_csv", "write_route_csv", "write_route_json"]

ROUTE_COLUMNS = ("waypoint", "experience", "x", "y", "z", "yaw", "distance_m")
_METRES = 4  # decimals of a distance or coordinate: 0.1 mm
_RADIANS = 6


def _metres(value: float) -> float:
    return round(float(value), _METRES) + 0.0  # + 0.0: no "-0.0"


def _point(position: np.ndarray) -> list[float]:
    return [_metres(v) for v in position[:3]]


def write_route_csv(path: Path, route: Route) -> None:
    """One row per waypoint, start first: its index, experience, map-frame position (m), yaw (rad, about z) and
    distance along the route (m)."""
    yaws = yaw_of(route.poses)
    rows = [
        [index, int(experience), *(f"{v:.{_METRES}f}" for v in position), f"{yaw:.{_RADIANS}f}", f"{along:.{_METRES}f}"]
        for index, (experience, position, yaw, along) in enumerate(
            zip(route.experiences, route.positions, yaws, route.along_m, strict=True)
        )
    ]
    write_table(path, ROUTE_COLUMNS, rows)


def route_features(route: Route) -> dict[str, Any]:
    """The route as a FeatureCollection: a LineString of the line a robot follows (the waypoints, to where the route
    ends: `Route.path`) and Point features for the start and the goal (its target, what the goal stands for, with
    the experience the route ends at)."""
    goal = route.goal
    found = goal.object
    goal_properties: dict[str, Any] = {
        "role": "goal",
        "goal": goal.text,
        "kind": goal.kind,
        "description": goal.description,
        "ids": list(goal.ids),
        "experience": goal.experience,
        "route_end": _point(goal.position),
        "offset_m": _metres(goal.offset_m),
    }
    if found is not None:
        goal_properties["object"] = _object_properties(found)
    line = {
        "type": "Feature",
        "geometry": {"type": "LineString", "coordinates": [_point(p) for p in route.path]},
        "properties": {
            "role": "route",
            "experiences": [int(e) for e in route.experiences],
            "length_m": _metres(route.length_m),
            "expected_time_s": None if route.expected_time_s is None else round(route.expected_time_s, 3),
        },
    }
    start = {
        "type": "Feature",
        "geometry": {"type": "Point", "coordinates": _point(route.positions[0])},
        "properties": {"role": "start", "experience": route.start},
    }
    target = {"type": "Feature", "geometry": {"type": "Point", "coordinates": _point(goal.target)}}
    return {
        "type": "FeatureCollection",
        "properties": {
            "frame": "map",
            "units": "m",
            "note": "x, y, z in the NeoSLAM map's frame (metres, z up), not WGS84 longitude and latitude",
        },
        "features": [line, start, target | {"properties": goal_properties}],
    }


def _object_properties(found: ObjectStatus) -> dict[str, Any]:
    return {
        "id": found.id,
        "label": found.label,
        "observations": found.observations,
        "last_seen": {
            "session": found.last_seen_session,
            "frame": found.last_seen_frame,
            "experience": found.last_seen_experience,
        },
        "misses": found.misses,
        "stale": found.stale,
    }


def write_route_json(path: Path, route: Route) -> None:
    path.write_text(json.dumps(route_features(route), allow_nan=False) + "\n")


def _cell(value: object) -> object:
    """A guidance cell: rounded metres and degrees, empty for none, booleans as 0 and 1."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float):
        return f"{_metres(value):.{_METRES}f}"
    return value


def write_guidance_csv(path: Path, records: list[GuidanceRecord]) -> None:
    """A run's guidance (`neoslam run --goal`), a row per frame: its state (not_localised, on_route, off_route,
    replanned, arrived, looking, missing, unreachable), the next waypoint (experience, x, y in the map frame; while
    looking, the goal object), the distance and bearing to it (m, degrees in the robot frame, positive left), the
    distance left along the route, straight to the goal and from the route, and whether an object goal was seen."""
    rows = [[_cell(value) for value in record.row().values()] for record in records]
    write_table(path, GUIDANCE_COLUMNS, rows)
