"""A robot driven on the true street graph by guidance alone (benchmarks/navigation.py, part `deliveries`).

`Robot` is where the robot truly is: on an edge of the street graph (from one node to the next), heading along it.
Each frame it drives a step of the drive's typical length along its edges; at each node it comes to, a chooser names
the next node. A turn sharper than SNAP_TURN_RAD stops it at the node and turns it in place at MAX_YAW_RATE (a U-turn
takes a few frames), so that odometry and the camera see a turn, not a jump of heading.

The controller (`choose_next`) reads only the guidance of the last frame: before the robot is localised it explores
(drives on along the street; where the street forks, a seeded choice, never back where it came from unless it is a dead
end); once a route is planned it takes the street whose direction, in the world, best matches the guidance's bearing to
the next waypoint turned into the world by the robot's true heading (the bearing is in the robot's frame: no map
knowledge is needed to follow it; a street's direction is from the node to where the street is STREET_AHEAD_M on, as a
driver sees where a street leads), and turns round only for a waypoint nearly behind it. `looking` (at an object goal
not yet seen) turns it in place towards the guidance's bearing, as a robot turns its camera to the object. `arrived`,
`missing` and `unreachable` stop the robot."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks._street_graph import StreetGraph

__all__ = [
    "FOLLOWING",
    "LOOKING",
    "MAX_YAW_RATE",
    "SNAP_TURN_RAD",
    "STOPPING",
    "STREET_AHEAD_M",
    "U_TURN_CONE_RAD",
    "Robot",
    "choose_next",
    "explore",
    "follow",
    "street_ahead",
]

SNAP_TURN_RAD = np.radians(25.0)  # a turn at a node up to this is taken while driving (a street's curve)
MAX_YAW_RATE = np.radians(90.0)  # rad/s of a turn in place (a U-turn takes two seconds)
U_TURN_CONE_RAD = np.radians(60.0)  # the robot turns round only for a waypoint this close to straight behind it
# The controller judges a street by where it leads over this much: a driver sees a junction's streets, not their
# first metre (a street that leaves a junction on a curve first points away from where it goes).
STREET_AHEAD_M = 10.0
STOPPING = frozenset({"arrived", "missing", "unreachable"})  # the guidance states that end a delivery
LOOKING = "looking"  # the guidance state that turns the robot in place towards its bearing
FOLLOWING = frozenset({"on_route", "replanned", "off_route"})  # the states with a bearing to follow

Chooser = Callable[[int, int, float], int]  # (node reached, node came from, true yaw) -> next node


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


@dataclass
class Robot:
    """The robot's true state on the street graph: on the edge `source` -> `target`, `along` metres from `source`,
    heading `yaw` (world frame, rad); `turning` while it turns in place at `source` onto the edge."""

    graph: StreetGraph
    source: int
    target: int
    along: float = 0.0
    yaw: float = 0.0
    turning: bool = False

    @classmethod
    def at(cls, graph: StreetGraph, node: int, towards: int) -> Robot:
        """A robot standing at `node`, facing along the edge to `towards`."""
        return cls(graph, node, towards, 0.0, graph.heading(node, towards))

    @property
    def position(self) -> np.ndarray:
        """(3,) true position, world frame: on the edge, height interpolated."""
        a, b = self.graph.positions[self.source], self.graph.positions[self.target]
        share = self.along / max(self.graph.length(self.source, self.target), 1e-9)
        return a + min(share, 1.0) * (b - a)

    def pose(self) -> np.ndarray:
        """(4, 4) true pose T_world_robot: heading along the edge, pitched with its slope (REP-103: climbing is a
        negative pitch), no roll."""
        a, b = self.graph.positions[self.source], self.graph.positions[self.target]
        run = max(self.graph.length(self.source, self.target), 1e-9)
        pitch = -np.arctan((b[2] - a[2]) / run)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("ZYX", [self.yaw, pitch, 0.0]).as_matrix()
        pose[:3, 3] = self.position
        return pose

    def drive(self, step_m: float, dt: float, choose: Chooser) -> float:
        """One frame: turn in place (when turning) or drive `step_m` along the edges, asking `choose` at each node
        reached; returns the distance driven."""
        if self.turning:
            self._turn(dt)
            return 0.0
        driven = 0.0
        while driven < step_m:
            left = self.graph.length(self.source, self.target) - self.along
            if step_m - driven < left:
                self.along += step_m - driven
                return step_m
            driven += left
            if not self._next_edge(choose(self.target, self.source, self.yaw)):
                return driven  # a sharp turn: it goes on from the node in the next frames
        return driven

    def look(self, direction: float, dt: float) -> None:
        """One frame turning in place towards `direction` (world yaw, rad) at MAX_YAW_RATE; before it drives on, it
        turns back onto its edge."""
        turn = _wrap(direction - self.yaw)
        largest = MAX_YAW_RATE * dt
        self.yaw = direction if abs(turn) <= largest else _wrap(self.yaw + np.sign(turn) * largest)
        self.turning = True

    def _next_edge(self, following: int) -> bool:
        """Onto the edge from the node reached to `following`; False when that needs a turn in place first."""
        node = self.target
        self.source, self.target, self.along = node, following, 0.0
        heading = self.graph.heading(node, following)
        if abs(_wrap(heading - self.yaw)) <= SNAP_TURN_RAD:
            self.yaw = heading
            return True
        self.turning = True
        return False

    def _turn(self, dt: float) -> None:
        heading = self.graph.heading(self.source, self.target)
        turn = _wrap(heading - self.yaw)
        largest = MAX_YAW_RATE * dt
        if abs(turn) <= largest:
            self.yaw, self.turning = heading, False
        else:
            self.yaw = _wrap(self.yaw + np.sign(turn) * largest)


def street_ahead(graph: StreetGraph, node: int, first: int, reach_m: float = STREET_AHEAD_M) -> float:
    """World yaw (rad) from `node` to where the street that leaves it towards `first` is `reach_m` on, taking at
    each later node the way on that turns least (a dead end: where it ends)."""
    previous, current = node, first
    travelled = graph.length(node, first)
    while travelled < reach_m:
        onward = [int(n) for n in graph.neighbours[current] if n != previous]
        if not onward:
            break
        heading = graph.heading(previous, current)
        following = min(onward, key=lambda n: (abs(_wrap(graph.heading(current, n) - heading)), n))
        travelled += graph.length(current, following)
        previous, current = current, following
    offset = graph.positions[current] - graph.positions[node]
    return float(np.arctan2(offset[1], offset[0]))


def follow(graph: StreetGraph, node: int, came_from: int, direction: float) -> int:
    """The neighbour of `node` whose street leads nearest to `direction` (world yaw, rad; `street_ahead`; ties: the
    lowest id), going back where it came from only when `direction` points back within U_TURN_CONE_RAD: a waypoint
    off to the side of a street with no turn here is reached by driving on to the turn, not by turning round."""
    neighbours = [int(n) for n in graph.neighbours[node]]
    leads = [street_ahead(graph, node, n) for n in neighbours]
    gaps = [abs(_wrap(lead - direction)) for lead in leads]
    best = neighbours[int(np.argmin(gaps))]
    onward = [(gap, n) for gap, n in zip(gaps, neighbours, strict=True) if n != came_from]
    if best != came_from or not onward:
        return best
    back = gaps[neighbours.index(came_from)]
    return best if back <= U_TURN_CONE_RAD else min(onward)[1]


def explore(graph: StreetGraph, node: int, came_from: int, rng: np.random.Generator) -> int:
    """Drive on: a seeded choice among the neighbours other than the one it came from (a dead end: back)."""
    onward = [int(n) for n in graph.neighbours[node] if n != came_from]
    if not onward:
        return came_from
    return onward[int(rng.integers(len(onward)))] if len(onward) > 1 else onward[0]


def choose_next(
    state: str, bearing: float | None, graph: StreetGraph, node: int, came_from: int, yaw: float, rng
) -> int:
    """The controller's choice at a node, from the last guidance's state and bearing (robot frame, rad) and the
    robot's true heading: follow the bearing on a route, explore otherwise."""
    if state in FOLLOWING and bearing is not None:
        return follow(graph, node, came_from, yaw + bearing)
    return explore(graph, node, came_from, rng)
