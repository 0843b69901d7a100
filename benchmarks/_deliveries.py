"""Closed-loop deliveries in the simulator (benchmarks/navigation.py, part `deliveries`): a robot starts on a mapped
street with no prior pose, relocalises in the map, and drives by the guidance alone until it says the robot arrived.

A delivery is planned from a seed (`plan_deliveries`): a start node on the true street graph and the direction it faces,
and a goal of the goal language. The mix (GOAL_MIX): an object by id that a world object stands for, a class query
(`nearest car`, the class drawn as often as the map holds it), an experience, a point on the streets (in the map's frame
as the map draws that spot: placed from its nearest experience, `MappedDrive.drawn_on_map`) and `start of session 1`
(the map's start: `start` alone is where the delivery's own session started). A removed-goal delivery names an object by
id whose world object is taken out of the world before the robot starts, with any object of its class beside it that no
map object stands for (within FUSED_M: the map made one object of the two, and the goal has not left while one of them
stands there; the nearest mapped one's, when several are).

`run_delivery` drives it: a new session `NeoSLAM(config, stored=map)` (nothing written to disk) with a
`GoalGuidance`; each frame the robot (benchmarks._robot) moves on the street graph from the guidance of the last
frame, its odometry is the true motion with the per-step noise of the `vo` profile (neoslam.sim.odometry.noisy_step),
its observations the world's objects detected from where it truly is (DetectionSimulator, converted as the dataset
reader converts them: neoslam.datasets.simulated.simulated_observations), then `slam.step(frame)` and the guidance.
At an object goal it has not seen, the guidance says `looking` and the robot turns in place to the object. It ends
when the guidance says `arrived`, `missing` or `unreachable`, or at the frame limit (a timeout): three
times the true shortest street path from the start to the goal plus EXPLORE_BUDGET_M, at the step of a frame.
Judging is benchmarks._judging's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from benchmarks._delivery_maps import MATCH_RADIUS_M, MappedDrive
from benchmarks._robot import LOOKING, STOPPING, Robot, choose_next
from neoslam.datasets.simulated import simulated_observations
from neoslam.geometry import integrate_body_velocities
from neoslam.navigation.session import GoalGuidance
from neoslam.navigation.view import pose_in_map
from neoslam.pipeline import NeoSLAM
from neoslam.sim.detections import DetectionSimulator
from neoslam.sim.odometry import noisy_step
from neoslam.sim.world import World
from neoslam.types import Frame

__all__ = ["EXPLORE_BUDGET_M", "GOAL_MIX", "Delivery", "DeliveryPlan", "plan_deliveries", "run_delivery"]

GOAL_MIX = {"object": 0.3, "class": 0.2, "experience": 0.2, "point": 0.2, "start": 0.1}
EXPLORE_BUDGET_M = 500.0  # beyond three times the shortest path, for relocalising and for a wrong turn or two
TURN_FRAMES = 100  # beyond that, frames for turns in place
MIN_DELIVERY_M = 50.0  # a goal nearer than this by street to the start is drawn again
START_TRIES = 20
# An unmatched world object of its class this near a removed goal went into the goal's map object.
FUSED_M = 2 * MATCH_RADIUS_M


@dataclass(frozen=True)
class DeliveryPlan:
    """One delivery: where the robot starts (a street node and the neighbour it faces), the goal, its true target."""

    map: str
    index: int
    seed: int
    start: int
    towards: int
    kind: str  # a GOAL_MIX kind, or "removed"
    goal: str
    target: tuple[float, float, float] | None  # the goal's true position (world frame); a class query: None
    removed: int = -1  # the world object taken out before it starts (removed-goal deliveries)


@dataclass
class Delivery:
    """What happened: the guidance's last state, the true positions and distances driven, frame by frame."""

    plan: DeliveryPlan
    state: str
    reason: str | None
    frames: int
    poses: np.ndarray  # (frames, 4, 4) true poses T_world_robot
    estimates: np.ndarray  # (frames, 4, 4) the pose estimates T_map_robot (NaN until localised)
    driven: np.ndarray  # (frames,) true distance driven up to each frame, m
    localised: int | None
    planned: int | None
    resolved: tuple[int, ...] | None  # what the goal resolved to (an object goal: the map object's id)
    resolved_kind: str | None
    resolved_target: np.ndarray | None  # (3,) what it resolved to, map frame (an object: the map's position of it)
    frame_ms: list[float]
    limit: int

    @property
    def positions(self) -> np.ndarray:
        """(frames, 3) true positions, world frame."""
        return self.poses[:, :3, 3]


def _goal(kind: str, mapped: MappedDrive, rng: np.random.Generator) -> tuple[str, np.ndarray | None, int]:
    """A goal of one kind: its text, its true position (None for a class query) and its world object (or -1)."""
    if kind in ("object", "removed"):
        matched = np.flatnonzero(mapped.object_match >= 0)
        row = int(rng.choice(matched))
        world_object = int(mapped.object_match[row])
        return f"object {mapped.object_ids[row]}", mapped.world.positions[world_object], world_object
    if kind == "class":
        label = str(rng.choice(mapped.object_labels[mapped.object_match >= 0]))
        return f"nearest {label}", None, -1
    if kind == "experience":
        experience = int(rng.integers(len(mapped.experience_truth)))
        return f"experience {experience}", mapped.experience_truth[experience], -1
    if kind == "point":
        point = mapped.streets.positions[int(rng.integers(len(mapped.streets)))]
        x, y, _ = mapped.drawn_on_map(point)
        return f"{x:.2f},{y:.2f}", point, -1
    return "start of session 1", mapped.experience_truth[0], -1  # "start" alone: the delivery session's own


def _start(mapped: MappedDrive, target: np.ndarray | None, rng: np.random.Generator) -> tuple[int, int]:
    """A start node (at least MIN_DELIVERY_M by street from the target, when it has one) and the node it faces."""
    streets = mapped.streets
    goal_node = None if target is None else streets.nearest(target)
    distances = None if goal_node is None else streets.distances(goal_node)
    for _ in range(START_TRIES):
        node = int(rng.integers(len(streets)))
        if distances is None or distances[node] >= MIN_DELIVERY_M:
            break
    return node, int(rng.choice(streets.neighbours[node]))


def plan_deliveries(mapped: MappedDrive, count: int, removed: int, seed: int, map_index: int) -> list[DeliveryPlan]:
    """`count` deliveries with goals of the GOAL_MIX and `removed` removed-goal deliveries on one map, seeded."""
    kinds = list(GOAL_MIX)
    plans = []
    for index in range(count + removed):
        plan_seed = int(np.random.SeedSequence([seed, map_index, index]).generate_state(1)[0])
        rng = np.random.default_rng(plan_seed)
        kind = "removed" if index >= count else str(rng.choice(kinds, p=list(GOAL_MIX.values())))
        goal, target, world_object = _goal(kind, mapped, rng)
        start, towards = _start(mapped, target, rng)
        plans.append(
            DeliveryPlan(
                map=mapped.name,
                index=index,
                seed=plan_seed,
                start=start,
                towards=towards,
                kind=kind,
                goal=goal,
                target=None if target is None else tuple(float(v) for v in target),
                removed=world_object if kind == "removed" else -1,
            )
        )
    return plans


def _removed(mapped: MappedDrive, world_object: int) -> np.ndarray:
    """The world objects a removed-goal delivery takes out: the goal's, and those of its class within FUSED_M of it
    that no map object stands for and whose nearest mapped object of their class is the goal's."""
    world = mapped.world
    labels, planar = np.asarray(world.labels), world.positions[:, :2]
    everything = np.arange(len(labels))
    matched = np.flatnonzero(np.isin(everything, mapped.object_match) & (labels == labels[world_object]))
    taken = [world_object]
    for other in np.flatnonzero((labels == labels[world_object]) & ~np.isin(everything, matched)):
        gaps = np.hypot(*(planar[matched] - planar[other]).T)
        if gaps.min() <= FUSED_M and matched[np.argmin(gaps)] == world_object:
            taken.append(int(other))
    return np.array(sorted(taken))


def _without(world: World, indices: np.ndarray) -> World:
    """The world with static objects taken out."""
    keep = ~np.isin(np.arange(len(world)), indices)
    if world.traffic is not None:
        raise ValueError("a removed goal is taken out of a static world only")
    return replace(
        world,
        labels=world.labels[keep],
        positions=world.positions[keep],
        sizes=world.sizes[keep],
        yaws=world.yaws[keep],
        velocities=world.velocities[keep],
        textures=world.textures[keep],
    )


def frame_limit(mapped: MappedDrive, plan: DeliveryPlan) -> int:
    """The frames a delivery may take: three times the true shortest street path to its target (a class query: to
    the farthest street node) plus EXPLORE_BUDGET_M, at a frame's step, and TURN_FRAMES."""
    streets = mapped.streets
    distances = streets.distances(plan.start)
    farthest = float(distances[np.isfinite(distances)].max())
    shortest = farthest if plan.target is None else float(distances[streets.nearest(np.asarray(plan.target))])
    step = mapped.speed * mapped.frame_period
    return int(np.ceil((3.0 * shortest + EXPLORE_BUDGET_M) / step)) + TURN_FRAMES


def _streams(seed: int) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The odometry, detection and exploration random streams of a delivery."""
    odometry, detection, explore = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    return odometry, detection, explore


def run_delivery(mapped: MappedDrive, plan: DeliveryPlan) -> Delivery:
    """Drive one delivery (see the module)."""
    config = mapped.config
    simulator = config.simulator
    world = mapped.world if plan.removed < 0 else _without(mapped.world, _removed(mapped, plan.removed))
    detector = DetectionSimulator(world, simulator.camera, simulator.detection)
    classes = config.perception.detector.classes
    odometry_rng, detection_rng, explore_rng = _streams(plan.seed)
    slam = NeoSLAM(config, stored=mapped.state, session_name=f"delivery {plan.index}")
    guidance = GoalGuidance(plan.goal, config, keep=False)
    streets, dt = mapped.streets, mapped.frame_period
    step_m = mapped.speed * dt
    robot = Robot.at(streets, plan.start, plan.towards)
    pose, odometry = robot.pose(), np.eye(4)
    linear, angular = np.zeros(3), np.zeros(3)
    poses, estimates, driven, frame_ms = [], [], [0.0], []
    limit = frame_limit(mapped, plan)

    def choose(node: int, came_from: int, yaw: float) -> int:
        latest = guidance.latest
        state = latest.state if latest is not None else "not_localised"
        bearing = latest.guidance.bearing_rad if latest is not None and latest.guidance is not None else None
        return choose_next(state, bearing, streets, node, came_from, yaw, explore_rng)

    for index in range(limit):
        if index:
            latest = guidance.latest
            if latest is not None and latest.state in STOPPING:
                break
            previous = pose
            if latest is not None and latest.state == LOOKING and latest.guidance is not None:
                robot.look(robot.yaw + (latest.guidance.bearing_rad or 0.0), dt)
                driven.append(driven[-1])
            else:
                driven.append(driven[-1] + robot.drive(step_m, dt, choose))
            pose = robot.pose()
            linear, angular = noisy_step(previous, pose, dt, simulator.odometry, odometry_rng)
            odometry = _integrated(odometry, linear, angular, dt)
        detections = detector.detect(pose, index * dt, detection_rng)
        frame = Frame(index, index * dt, odometry, linear, angular, simulated_observations(detections, classes))
        started = time.perf_counter()
        estimate = slam.step(frame)
        guidance(slam, frame, estimate)
        frame_ms.append(1e3 * (time.perf_counter() - started))
        poses.append(pose.copy())
        estimates.append(estimate.copy() if pose_in_map(slam, estimate) is not None else np.full((4, 4), np.nan))
    latest = guidance.latest
    route = guidance.route
    return Delivery(
        plan=plan,
        state=latest.state if latest is not None else "not_localised",
        reason=guidance.error,
        frames=len(poses),
        poses=np.array(poses),
        estimates=np.array(estimates),
        driven=np.array(driven[: len(poses)]),
        localised=guidance.events.localised,
        planned=guidance.events.planned,
        resolved=None if route is None else route.goal.ids,
        resolved_kind=None if route is None else route.goal.kind,
        resolved_target=None if route is None else np.array(route.goal.target, dtype=float),
        frame_ms=frame_ms,
        limit=limit,
    )


def _integrated(odometry: np.ndarray, linear: np.ndarray, angular: np.ndarray, dt: float) -> np.ndarray:
    """The odometry pose after one step of body velocities (as the dataset reader integrates them)."""
    velocities = np.zeros((2, 3)), np.zeros((2, 3))
    velocities[0][1], velocities[1][1] = linear, angular
    return integrate_body_velocities(*velocities, np.array([0.0, dt]), start=odometry)[1]
