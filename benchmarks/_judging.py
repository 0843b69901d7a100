"""Deliveries judged by ground truth (benchmarks/navigation.py, part `deliveries`); the SLAM path never sees it.

- The goal's arrival point: a place (an experience, `start of session 1`) is where the mapping drive truly was when it
  made that experience; a point is the street point it was drawn at (its map coordinates are that point through
  T_world_map, so the map's own error counts against the delivery); an object is the street node nearest to the world
  object it stands for (objects stand up to 27 m off the street in the `real` profile: a robot on the street stops
  beside them), or the nearest node of another street within TIE_M as near (an object between two streets is beside
  both). A class query's object is the one the guidance resolved it to: the world object the map object
  stands for (see benchmarks._delivery_maps; an object the delivery's own session added to the map, the nearest world
  object of its class within MATCH_RADIUS_M of its map position through T_world_map).
- Success: the guidance said `arrived` and the robot's true position is within ARRIVAL_M of the arrival point (in the
  ground plane). A removed goal's success: `missing` or `unreachable`, never `arrived`.
- A wrong object: an object goal arrived at farther than ARRIVAL_M from its arrival point and within ARRIVAL_M of the
  arrival point of another world object of the goal's class, or resolved to a map object that stands for no world
  object. (The nearest world object of the class to where the robot stops is often a car across the street, 4 m off
  it, while the goal stands 18 m off the other side: `nearest_is_other` counts that reading apart.)
- Route ratio: the true distance driven from the frame the route was first planned to the stop, over the true
  shortest street path from the robot's position then (its nearest street node) to the arrival point's nearest
  street node; for arrivals whose shortest path is at least MIN_RATIO_PATH_M.
"""

from __future__ import annotations

import statistics
from typing import Any

import numpy as np

from benchmarks._deliveries import Delivery, DeliveryPlan, run_delivery
from benchmarks._delivery_maps import MATCH_RADIUS_M, MappedDrive
from benchmarks._robot import STOPPING
from neoslam.geometry import yaw_of

__all__ = ["ARRIVAL_M", "FAILURE_COLUMNS", "SUMMARY_COLUMNS", "failures", "judge", "judged", "summary"]

ARRIVAL_M = 5.0
LOST_M, LOST_DEG = 10.0, 20.0  # a pose estimate this far off the truth is said in a failure's why
TIE_M = 2.0  # an object's other street this much farther than its nearest is beside it too
MIN_RATIO_PATH_M = 20.0  # a shorter route's ratio says little (the robot stops within ARRIVAL_M of its end)
SUMMARY_COLUMNS = [
    "map",
    "deliveries",
    "arrived_5m",
    "success_pct",
    "wrong_objects",
    "removed",
    "removed_reported",
    "timeouts",
    "unreachable",
    "missing",
    "pose_off",
    "route_ratio_median",
    "route_ratio_p90",
    "relocalisation_m_median",
    "frames_median",
    "ms_per_frame",
]
FAILURE_COLUMNS = ["map", "delivery", "kind", "goal", "state", "distance_m", "frames", "why"]


def _object_of(mapped: MappedDrive, delivery: Delivery) -> int:
    """The world object an object goal stands for (-1: none)."""
    plan = delivery.plan
    if plan.kind in ("object", "removed"):
        return plan.removed if plan.removed >= 0 else mapped.match_of(int(plan.goal.split()[-1]))
    if delivery.resolved_kind != "object" or not delivery.resolved:
        return -1
    matched = mapped.match_of(delivery.resolved[0])
    if matched >= 0 or delivery.resolved_target is None:
        return matched
    label = plan.goal.split()[-1]
    where = mapped.world_from_map[:3, :3] @ delivery.resolved_target + mapped.world_from_map[:3, 3]
    same = np.flatnonzero(mapped.world.labels == label)
    gaps = np.hypot(*(mapped.world.positions[same, :2] - where[:2]).T)
    return int(same[np.argmin(gaps)]) if len(same) and gaps.min() <= MATCH_RADIUS_M else -1


def _arrival_point(mapped: MappedDrive, delivery: Delivery, world_object: int) -> np.ndarray | None:
    """The goal's arrival point nearest to where the robot stopped (None: an object goal that stands for none)."""
    plan = delivery.plan
    if plan.kind not in ("object", "removed", "class"):
        return np.asarray(plan.target, dtype=float)
    if world_object < 0:
        return None
    points = _beside(mapped, mapped.world.positions[world_object])
    stop = delivery.positions[-1]
    return points[int(np.argmin(np.hypot(*(points[:, :2] - stop[:2]).T)))]


def _beside(mapped: MappedDrive, target: np.ndarray) -> np.ndarray:
    """(k, 3) the street points beside an object: the nearest street node, and the nearest node of every other street
    nearly as near (within TIE_M; a node no farther from it than its neighbours), for an object between streets."""
    streets = mapped.streets
    distance = np.hypot(*(streets.positions[:, :2] - target[:2]).T)
    near = np.flatnonzero(distance <= distance.min() + TIE_M)
    nearest = [n for n in near if all(distance[n] <= distance[k] for k in streets.neighbours[n])]
    return streets.positions[nearest]


def _at_another(mapped: MappedDrive, stop: np.ndarray, world_object: int) -> tuple[bool, bool]:
    """Whether the stop is within ARRIVAL_M of another same-class object's arrival point, and whether the nearest
    object of the class to the stop is another one."""
    world = mapped.world
    same = np.flatnonzero(world.labels == world.labels[world_object])
    others = same[same != world_object]
    points = mapped.streets.positions[mapped.streets.nearest_nodes(world.positions[others])]
    at_another = bool(len(others)) and bool((np.hypot(*(points[:, :2] - stop[:2]).T) <= ARRIVAL_M).any())
    nearest = same[np.argmin(np.hypot(*(world.positions[same, :2] - stop[:2]).T))]
    return at_another, bool(nearest != world_object)


def _route_ratio(mapped: MappedDrive, delivery: Delivery, arrival: np.ndarray | None) -> float | None:
    if delivery.state != "arrived" or delivery.planned is None or arrival is None:
        return None
    streets = mapped.streets
    start = streets.nearest(delivery.positions[delivery.planned])
    shortest = float(streets.distances(start)[streets.nearest(arrival)])
    if not shortest >= MIN_RATIO_PATH_M:
        return None
    return float(delivery.driven[-1] - delivery.driven[delivery.planned]) / shortest


def _estimate_errors(mapped: MappedDrive, delivery: Delivery) -> tuple[float | None, float | None]:
    """The largest ground-plane position error (m) and heading error (degrees) of the robot's pose estimate, through
    T_world_map, over the frames it was localised (None: never)."""
    localised = np.isfinite(delivery.estimates[:, 0, 0])
    if not localised.any():
        return None, None
    estimates = mapped.world_from_map @ delivery.estimates[localised]
    truth = delivery.poses[localised]
    position = np.hypot(*(estimates[:, :2, 3] - truth[:, :2, 3]).T)
    heading = np.angle(np.exp(1j * (yaw_of(estimates) - yaw_of(truth))))
    return float(position.max()), float(np.degrees(np.abs(heading).max()))


def _against_the_map(mapped: MappedDrive, delivery: Delivery) -> bool:
    """Whether the robot drove against the direction the mapping drive took there, when it localised (or at its
    last frame, never localised): the street seen from its other side."""
    frame = delivery.localised if delivery.localised is not None else delivery.frames - 1
    here = delivery.poses[frame]
    nearest = int(np.argmin(np.linalg.norm(mapped.truth.positions[:, :2] - here[:2, 3], axis=1)))
    turn = np.angle(np.exp(1j * (yaw_of(here[None])[0] - yaw_of(mapped.truth.poses[nearest][None])[0])))
    return bool(abs(turn) > np.pi / 2)


def judge(mapped: MappedDrive, delivery: Delivery) -> dict[str, Any]:
    """One delivery's row: what happened and whether it succeeded (see the module)."""
    plan = delivery.plan
    stop = delivery.positions[-1]
    world_object = _object_of(mapped, delivery) if plan.kind in ("object", "removed", "class") else -1
    arrival = _arrival_point(mapped, delivery, world_object)
    distance = None if arrival is None else float(np.hypot(*(stop[:2] - arrival[:2])))
    arrived = delivery.state == "arrived"
    within = arrived and distance is not None and distance <= ARRIVAL_M
    removed = plan.kind == "removed"
    wrong = nearest_other = False
    if arrived and plan.kind in ("object", "class") and not removed:
        if world_object < 0:
            wrong = True
        else:
            at_another, nearest_other = _at_another(mapped, stop, world_object)
            wrong = not within and at_another
    success = delivery.state in ("missing", "unreachable") if removed else within
    position_error, heading_error = _estimate_errors(mapped, delivery)
    row = {
        "map": plan.map,
        "delivery": plan.index,
        "kind": plan.kind,
        "goal": plan.goal,
        "state": delivery.state,
        "success": success,
        "arrived": arrived,
        "within": within,
        "distance_m": distance,
        "wrong_object": wrong,
        "nearest_is_other": nearest_other,
        "removed": removed,
        "timeout": delivery.state not in STOPPING,
        "route_ratio": _route_ratio(mapped, delivery, arrival),
        "relocalisation_m": None if delivery.localised is None else float(delivery.driven[delivery.localised]),
        "frames": delivery.frames,
        "seconds": delivery.frames * mapped.frame_period,
        "driven_m": float(delivery.driven[-1]),
        "ms_per_frame": statistics.median(delivery.frame_ms) if delivery.frame_ms else None,
        "estimate_error_m": position_error,
        "heading_error_deg": heading_error,
        "against_map": _against_the_map(mapped, delivery),
        "reason": delivery.reason,
    }
    return row | {"why": None if success else _why(row, world_object)}


def _why(row: dict[str, Any], world_object: int) -> str:
    """What went wrong, with the pose estimate's largest error when it was off (LOST_M or LOST_DEG) and whether the
    robot relocalised driving against the mapped direction."""
    why = _what(row, world_object)
    position, heading = row["estimate_error_m"], row["heading_error_deg"]
    if _off(row):
        why += f"; pose estimate off by up to {position:.3g} m, {heading:.0f} deg"
    return why + ("; relocalised against the mapped direction" if row["against_map"] else "")


def _what(row: dict[str, Any], world_object: int) -> str:
    state, distance = row["state"], row["distance_m"]
    far = "" if distance is None else f", {distance:.1f} m from the goal"
    if row["removed"]:
        return f"removed goal {state}{far}"
    if row["timeout"]:
        return "never relocalised (timeout)" if state == "not_localised" else f"timeout ({state}{far})"
    if state == "arrived":
        if row["kind"] in ("object", "class") and world_object < 0:
            return "arrived at a map object that stands for no world object"
        return f"arrived {distance:.1f} m from the goal" + (" (at another object of its class)" * row["wrong_object"])
    if state == "missing":
        return f"goal object not sighted, reported missing{far}"
    return f"{state}: {row['reason'] or 'no route from where the robot was'}{far}"


def _off(row: dict[str, Any]) -> bool:
    """Whether the pose estimate was off by more than LOST_M or LOST_DEG at some localised frame."""
    position, heading = row["estimate_error_m"], row["heading_error_deg"]
    return position is not None and (position > LOST_M or heading > LOST_DEG)


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def _p90(values: list[float]) -> float | None:
    return float(np.percentile(values, 90)) if values else None


def summary(rows: list[dict[str, Any]], name: str) -> dict[str, Any]:
    """A table row over deliveries: counts, success share (of the deliveries to goals that stand), medians."""
    goals = [r for r in rows if not r["removed"]]
    removed = [r for r in rows if r["removed"]]
    arrived = sum(r["within"] for r in goals)
    ratios = [r["route_ratio"] for r in goals if r["route_ratio"] is not None]
    return {
        "map": name,
        "deliveries": len(goals),
        "arrived_5m": arrived,
        "success_pct": 100.0 * arrived / len(goals) if goals else None,
        "wrong_objects": sum(r["wrong_object"] for r in goals),
        "removed": len(removed),
        "removed_reported": sum(r["success"] for r in removed),
        "timeouts": sum(r["timeout"] for r in rows),
        "unreachable": sum(r["state"] == "unreachable" for r in goals),
        "missing": sum(r["state"] == "missing" for r in goals),
        "pose_off": sum(_off(r) for r in rows),
        "route_ratio_median": _median(ratios),
        "route_ratio_p90": _p90(ratios),
        "relocalisation_m_median": _median([r["relocalisation_m"] for r in rows if r["relocalisation_m"] is not None]),
        "frames_median": _median([r["frames"] for r in rows]),
        "ms_per_frame": _median([r["ms_per_frame"] for r in rows if r["ms_per_frame"] is not None]),
    }


def failures(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The deliveries that did not succeed, each with why."""
    return [r for r in rows if not r["success"]]


def judged(mapped: MappedDrive, plans: list[DeliveryPlan]) -> list[dict[str, Any]]:
    """Drive and judge deliveries on one map, in order (a worker's task)."""
    return [judge(mapped, run_delivery(mapped, plan)) for plan in plans]
