"""Navigation on the map: how fast routes are planned and guidance is given, on maps laid from the real KITTI
ground-truth trajectories (the map of a good run: an experience every 5 m at the true pose, loop links where a
drive comes back, objects along the streets; benchmarks/_navigation_maps.py), and closed-loop deliveries in the
simulator.

(speed) Planning on maps of 1,000, 5,000 and 20,000 experiences: the one-off work on a map (its navigation graph:
links, sparse matrix and KD-tree; its objects and their staleness), then `RoutePlanner.plan` from random start
experiences to goals of each kind of the goal language (an experience, a point near the streets, the start, an
object by id, the nearest car), median and 95th percentile, and `plan_route` whole (reading the map, building the
graph, planning) once per goal. Guidance on the largest map: a drive along routes of 1 to 5 km at a metre a frame,
half a metre of lateral jitter, with a detour 25 m off the route and back; the time of `Guide.update` per frame
(median, 95th percentile, largest) and of the frames that planned again. Targets: planning 10 ms or less (median)
at 20,000 experiences, guidance 1 ms or less a frame.

(deliveries) Simulated drives (KITTI 00 and 05 ground truth, the built-in town route; `vo` odometry, `real`
detection) are mapped by NeoSLAM (benchmarks._delivery_maps); then, on each map, deliveries: a robot starts on a
mapped street with no prior pose, relocalises as a new session of the map and drives on the true street graph
(benchmarks._street_graph) by the guidance alone (benchmarks._robot), with the noisy odometry of the profile and the
world's objects detected from where it truly is, until the guidance says it arrived (benchmarks._deliveries). Goals:
objects by id, `nearest CLASS`, experiences, points on the streets, the start of the map; and objects taken out of
the world before the delivery starts, which must be reported missing or unreachable. Judged by ground truth only
(benchmarks._judging): arrival within 5 m of the goal, wrong objects, route length against the true shortest street
path, time, relocalisation. Targets: 99 % of deliveries arrive within 5 m, no wrong object, every removed goal
refused, route length at most 1.15 times the shortest (median).

    python -m benchmarks.navigation [--quick] [--parts speed deliveries] [--sizes 1000 5000 20000] [--plans 100]
                                    [--seed 1] [--maps 00 05 town] [--deliveries 30] [--removed 5] [--workers N]

Parts are the functions in PARTS (name -> part(run) -> figures), each with its own tables. A run of some of the
parts only, without --out, writes `navigation-PART.json` (the parts' names joined), so that the stored result of
the run of every part keeps its tables."""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from benchmarks import harness
from benchmarks._deliveries import GOAL_MIX, plan_deliveries
from benchmarks._delivery_maps import MappedDrive, map_drive, map_names
from benchmarks._judging import FAILURE_COLUMNS, SUMMARY_COLUMNS, failures, judged, summary
from benchmarks._navigation_maps import Drive, kitti_map, load_drives
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import make_pose
from neoslam.navigation import Guide, Route, RoutePlanner, plan_route
from neoslam.types import MapState

SIZES = [1000, 5000, 20000]
QUICK_SIZES = [1000, 5000]
PLANS, QUICK_PLANS = 100, 20  # per goal kind and map size
GUIDED_ROUTES, QUICK_GUIDED_ROUTES = 5, 2
ROUTE_LENGTHS_M = (1000.0, 5000.0)  # guided routes are this long
FRAME_STEP_M = 1.0  # the guided drive moves this far a frame (10 m/s at KITTI's 10 Hz)
JITTER_M = 0.5  # lateral std of the guided drive about the route
DETOUR_M, DETOUR_FRAMES = 25.0, 25  # the detour: this far off the route, over this many frames out (and back)
ONE_SHOT_PLANS = 3  # plan_route whole, per goal kind
GOAL_KINDS = ("experience", "point", "start", "object", "class")
POINT_SPREAD_M = 5.0  # a point goal lies this far (at most, each axis) from an experience
MAPS, QUICK_MAPS = ["00", "05", "town"], ["town"]  # deliveries: the drives mapped
DELIVERIES, QUICK_DELIVERIES = 30, 2  # a map
REMOVED, QUICK_REMOVED = 5, 1  # deliveries to a removed goal, a map
DIRECTIONS = {False: "with the map", True: "against the map"}  # deliveries: the way it drove when it relocalised
DELIVERIES_PER_TASK = 10  # a worker's task: this many deliveries on one map (a worker takes seconds to start)


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def _goal(kind: str, state: MapState, fresh_objects: np.ndarray, rng: np.random.Generator) -> str:
    """A random goal of one kind of the goal language on the map."""
    n = len(state.experiences)
    if kind == "experience":
        return f"experience {rng.integers(n)}"
    if kind == "point":
        x, y = state.experience_poses[rng.integers(n), :2, 3] + rng.uniform(-POINT_SPREAD_M, POINT_SPREAD_M, 2)
        return f"{x:.2f},{y:.2f}"
    if kind == "start":
        return "start"
    if kind == "object":
        return f"object {rng.choice(fresh_objects)}"
    return "nearest car"


def _timed(call: Callable[[], object]) -> float:
    start = time.perf_counter()
    call()
    return 1e3 * (time.perf_counter() - start)


def _planning(state: MapState, plans: int, rng: np.random.Generator) -> dict:
    """One map size: the one-off work, then every goal kind from random starts."""
    config = NeoSLAMConfig()
    planner: RoutePlanner | None = None

    def build() -> None:
        nonlocal planner
        planner = RoutePlanner(state, config)
        planner.graph.matrix, planner.graph.tree  # noqa: B018 (built now, as a first plan would)

    graph_ms = _timed(build)
    assert planner is not None
    objects_ms = _timed(planner.objects)
    objects = planner.objects()
    fresh = objects.ids[~objects.stale]
    n = len(state.experiences)
    times: dict[str, list[float]] = {kind: [] for kind in GOAL_KINDS}
    for kind in GOAL_KINDS:
        planner.plan(_goal(kind, state, fresh, rng), start=0)  # warm: the objects' reach, first calls
        for _ in range(plans):
            goal, start = _goal(kind, state, fresh, rng), int(rng.integers(n))
            times[kind].append(_timed(lambda goal=goal, start=start: planner.plan(goal, start=start)))
    one_shot = [
        _timed(lambda kind=kind: plan_route(state, _goal(kind, state, fresh, rng), start=0, config=config))
        for kind in GOAL_KINDS
        for _ in range(ONE_SHOT_PLANS)
    ]
    every = [t for kind in GOAL_KINDS for t in times[kind]]
    return {
        "experiences": n,
        "links": len(state.links),
        "objects": len(objects),
        "stale": int(objects.stale.sum()),
        "graph_ms": graph_ms,
        "objects_ms": objects_ms,
        "plan_ms_median": statistics.median(every),
        "plan_ms_p95": _percentile(every, 95),
        **{f"{kind}_ms": statistics.median(times[kind]) for kind in GOAL_KINDS},
        "plan_route_ms": statistics.median(one_shot),
    }


def _drive(route: Route, rng: np.random.Generator) -> list[np.ndarray]:
    """Poses along the route a frame apart with lateral jitter, heading along it, and the detour at a third of the
    way: out to DETOUR_M on the left over DETOUR_FRAMES frames, and back."""
    points = route.positions[:, :2]
    poses: list[np.ndarray] = []
    detour_at = route.length_m / 3
    travelled = 0.0
    for a, b in zip(points[:-1], points[1:], strict=True):
        length = float(np.linalg.norm(b - a))
        if length < 1e-6:
            continue
        yaw = float(np.arctan2(b[1] - a[1], b[0] - a[0]))
        left = np.array([-np.sin(yaw), np.cos(yaw)])
        for s in np.arange(0.0, length, FRAME_STEP_M):
            here = a + (b - a) * s / length
            if travelled <= detour_at < travelled + FRAME_STEP_M:
                away = np.linspace(0.0, DETOUR_M, DETOUR_FRAMES)
                poses += [_pose(here + left * d, yaw + np.pi / 2) for d in np.concatenate([away, away[::-1]])]
            poses.append(_pose(here + left * rng.normal(0.0, JITTER_M), yaw))
            travelled += FRAME_STEP_M
    return poses


def _pose(xy: np.ndarray, yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return make_pose(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([xy[0], xy[1], 0.0]))


def _long_route(planner: RoutePlanner, rng: np.random.Generator) -> Route:
    """A route between random experiences, 1 to 5 km long."""
    n = len(planner.graph)
    while True:
        route = planner.plan(f"experience {rng.integers(n)}", start=int(rng.integers(n)))
        if ROUTE_LENGTHS_M[0] <= route.length_m <= ROUTE_LENGTHS_M[1]:
            return route


def _guidance(state: MapState, routes: int, rng: np.random.Generator) -> list[dict]:
    config = NeoSLAMConfig()
    planner = RoutePlanner(state, config)
    rows = []
    for _ in range(routes):
        route = _long_route(planner, rng)
        guide = Guide(route, config.navigation, planner.replan)
        frames, replans = [], []
        for pose in _drive(route, rng):
            start = time.perf_counter()
            record = guide.update(pose)
            elapsed = 1e3 * (time.perf_counter() - start)
            (replans if record.state == "replanned" else frames).append(elapsed)
        rows.append(
            {
                "route_m": route.length_m,
                "waypoints": len(route),
                "frames": len(frames) + len(replans),
                "replans": len(replans),
                "frame_ms_median": statistics.median(frames),
                "frame_ms_p95": _percentile(frames, 95),
                "frame_ms_max": max(frames),
                "replan_ms_median": statistics.median(replans) if replans else float("nan"),
            }
        )
    return rows


def run_speed(run: harness.Run) -> dict:
    args = run.args
    sizes = args.sizes or (QUICK_SIZES if run.quick else SIZES)
    plans = args.plans or (QUICK_PLANS if run.quick else PLANS)
    rng = np.random.default_rng(args.seed)
    drives: list[Drive] = load_drives()
    maps = {size: kitti_map(drives, size, seed=args.seed) for size in sizes}
    planning = [_planning(maps[size], plans, rng) for size in sizes]
    columns = ["experiences", "links", "objects", "stale", "graph_ms", "objects_ms", "plan_ms_median", "plan_ms_p95"]
    columns += [f"{kind}_ms" for kind in GOAL_KINDS] + ["plan_route_ms"]
    run.table("planning", planning, columns, title=f"## Planning, ms ({plans} plans a goal kind and map size)")
    largest = max(sizes)
    guided = _guidance(maps[largest], QUICK_GUIDED_ROUTES if run.quick else GUIDED_ROUTES, rng)
    columns = ["route_m", "waypoints", "frames", "replans", "frame_ms_median", "frame_ms_p95", "frame_ms_max"]
    columns += ["replan_ms_median"]
    run.table("guidance", guided, columns, title=f"## Guidance per frame, ms ({largest:,} experiences)")
    return {
        "map_sizes": sizes,
        "plan_ms_median": planning[-1]["plan_ms_median"],  # at the largest map
        "guidance_ms_median": statistics.median(r["frame_ms_median"] for r in guided),
        "planning": planning,
        "guidance": guided,
    }


def _pooled(task: Callable, jobs: list[tuple], workers: int) -> list:
    """task(*job) for each job: in this process with one worker, else each job in a fresh worker process."""
    if workers <= 1:
        return [task(*job) for job in jobs]
    with harness.pool(workers) as pool:
        return pool.starmap(task, jobs, chunksize=1)


def _map_row(mapped: MappedDrive) -> dict:
    return {
        "map": mapped.name,
        "frames": len(mapped.truth),
        "experiences": len(mapped.state.experiences),
        "goal_objects": len(mapped.object_ids),
        "matched": int((mapped.object_match >= 0).sum()),
        "streets_m": float(mapped.streets.matrix.sum() / 2),
        "speed_m_s": mapped.speed,
        "mapping_s": mapped.mapping_s,
    }


def run_deliveries(run: harness.Run) -> dict:
    """Part `deliveries`: map each drive, then drive the deliveries on it by the guidance alone (see the module)."""
    args = run.args
    names = args.maps or (QUICK_MAPS if run.quick else MAPS)
    count = args.deliveries if args.deliveries is not None else (QUICK_DELIVERIES if run.quick else DELIVERIES)
    removed = args.removed if args.removed is not None else (QUICK_REMOVED if run.quick else REMOVED)
    maps = _pooled(map_drive, [(name, args.seed) for name in names], min(args.workers, len(names)))
    run.table("delivery_maps", [_map_row(m) for m in maps], list(_map_row(maps[0])), title="## Maps (simulated)")
    jobs = []
    for index, mapped in enumerate(maps):
        plans = plan_deliveries(mapped, count, removed, args.seed, index)
        jobs += [(mapped, plans[k : k + DELIVERIES_PER_TASK]) for k in range(0, len(plans), DELIVERIES_PER_TASK)]
    rows = [row for rows in _pooled(judged, jobs, args.workers) for row in rows]
    table = [summary([r for r in rows if r["map"] == m.name], m.name) for m in maps] + [summary(rows, "total")]
    title = f"## Deliveries ({count} a map and {removed} to removed goals; simulated, vo odometry, real detection)"
    run.table("deliveries", table, SUMMARY_COLUMNS, title=title)
    kinds = [summary([r for r in rows if r["kind"] == kind], kind) for kind in [*GOAL_MIX, "removed"]]
    run.table("deliveries_by_goal", kinds, ["map", *SUMMARY_COLUMNS[1:]], title="## By kind of goal (all maps)")
    ways = [summary([r for r in rows if r["against_map"] == against], way) for against, way in DIRECTIONS.items()]
    title = "## By the direction the robot drove when it relocalised, against the mapping drive's there (all maps)"
    run.table("deliveries_by_direction", ways, ["map", *SUMMARY_COLUMNS[1:]], title=title)
    run.table("delivery_failures", failures(rows), FAILURE_COLUMNS, title="## Failures")
    return {"maps": names, "deliveries_per_map": count, "removed_per_map": removed, "summary": table,
            "by_goal": kinds, "by_direction": ways, "rows": rows}  # fmt: skip


PARTS: dict[str, Callable[[harness.Run], dict]] = {"speed": run_speed, "deliveries": run_deliveries}
QUICK = f"maps of {', '.join(f'{s:,}' for s in QUICK_SIZES)} experiences, {QUICK_PLANS} plans a goal kind, "
QUICK += f"{QUICK_GUIDED_ROUTES} guided routes; {QUICK_DELIVERIES} deliveries and {QUICK_REMOVED} to a removed goal "
QUICK += f"on {', '.join(QUICK_MAPS)}"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--parts", nargs="+", choices=list(PARTS), default=list(PARTS), help="parts to run")
    parser.add_argument("--sizes", nargs="+", type=int, help=f"map sizes, experiences (default {SIZES})")
    parser.add_argument("--plans", type=int, help=f"plans a goal kind and map size (default {PLANS})")
    parser.add_argument("--seed", type=int, default=1, help="seed of the objects, goals, starts and drives")
    parser.add_argument("--maps", nargs="+", choices=map_names(), help=f"deliveries: maps (default {MAPS})")
    parser.add_argument("--deliveries", type=int, help=f"deliveries a map (default {DELIVERIES})")
    parser.add_argument("--removed", type=int, help=f"deliveries to a removed goal a map (default {REMOVED})")


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    if run.args.out is None and set(run.args.parts) != set(PARTS):  # keep the stored result of every part
        name = "-".join([run.name, *run.args.parts])
        run.args.out = harness.RESULTS / f"{name}{'.quick' if run.quick else ''}.json"
    figures = {part: PARTS[part](run) for part in run.args.parts}
    run.finish(figures)


if __name__ == "__main__":
    main()
