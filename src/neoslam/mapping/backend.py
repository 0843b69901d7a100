"""The experience map's correction back end (paper 3.6, eq. 18, and beyond it): the paper's relaxation every frame
once the map has a loop, or pose-graph optimisation at each loop link (`backend: pose-graph`); with
`object_landmarks`, the pose graph also holds the object map's objects as landmarks, solved incrementally (iSAM2)
whenever the robot leaves an experience (its observation sums are then complete).

Only the robot's part of the map is corrected: a stored session not joined yet stays as stored (neoslam.store).
Each pose-graph optimisation (with landmarks, each iSAM2 update at a loop) re-checks every loop link of that part
(`withdraw_sigmas`): the one the optimised map disagrees with most, beyond that many standard deviations, is
withdrawn and the part solved again without it, until every loop link agrees (a map that heals from a wrong
closure; neoslam.mapping.healing). Odometry links are weighted by the metres and, with `odometry_noise` given (the
noise the session estimates online, per root second), the seconds they span.
The back end keeps the links' measurements (relaxation) and the landmark solver; the experience map owns the graph.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Protocol

import numpy as np

from neoslam.config import ExperienceMapConfig
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.healing import disagreeing_link
from neoslam.mapping.landmarks import LOOP_ITERATIONS, LandmarkSolver, ObservationSource
from neoslam.mapping.parts import MapParts
from neoslam.mapping.pose_graph import OdometryNoise, PoseGraphReport, optimise_pose_graph
from neoslam.mapping.relaxation import LinkMeasurement, link_measurement, relax
from neoslam.types import Link

__all__ = ["MapBackend", "CorrectedMap"]


class CorrectedMap(Protocol):
    """What the back end reads of the experience map."""

    graph: MapGraph
    parts: MapParts

    @property
    def current(self) -> int: ...

    @property
    def visits(self) -> int: ...

    @property
    def localised(self) -> bool: ...

    @property
    def odometer(self) -> float: ...

    def visited_experiences(self) -> np.ndarray: ...


class MapBackend:
    """Corrects an experience map's graph: relaxation, pose graph, or pose graph with object landmarks."""

    def __init__(self, config: ExperienceMapConfig) -> None:
        self.config = config
        self.landmark_source: ObservationSource | None = None  # the object map, for object_landmarks
        self.odometry_noise: OdometryNoise | None = None  # per root second; None: links weighted by distance only
        self.seconds = 0.0  # wall time in the pose-graph solvers (timing only: never read by the map)
        self._measurements: list[LinkMeasurement] = []
        self._landmarks: LandmarkSolver | None = None  # built on first use, rebuilt after a restore or a join
        self._landmark_part = -1  # the part the landmark solver holds
        self._solved_visit = 0  # the visit that was current at the last landmark solve

    @property
    def uses_landmarks(self) -> bool:
        """Whether the pose graph holds the object map's objects as landmarks (experience_map.object_landmarks)."""
        return self.config.object_landmarks and self.config.backend == "pose-graph" and self.landmark_source is not None

    @property
    def landmark_solver(self) -> LandmarkSolver | None:
        """The iSAM2 solver of the robot's part with the object landmarks (None: not used, or not yet built)."""
        return self._landmarks

    def linked(self, graph: MapGraph, link: Link) -> None:
        """A link was added to the graph."""
        self._measurements.append(link_measurement(graph, link))

    def rebuild(self, graph: MapGraph) -> None:
        """The graph was replaced or moved (a restore, a join): measurements again, the landmark solver anew."""
        self._landmarks = None
        self._measurements = [link_measurement(graph, link) for link in graph.live_links()]

    def optimise(self, experience_map: CorrectedMap) -> list[int]:
        """At a loop link: the pose graph of the robot's part of the map (with landmarks, an iSAM2 update).
        Returns the loop links withdrawn (indices into graph.links)."""
        if self.config.backend != "pose-graph":
            return []
        start = time.perf_counter()
        if self.uses_landmarks:
            withdrawn = self._solve_landmarks_healed(experience_map, LOOP_ITERATIONS)
        else:
            withdrawn = self._optimise_part(experience_map.graph, _robot_part(experience_map))
        self.seconds += time.perf_counter() - start
        return withdrawn

    def correct(self, experience_map: CorrectedMap, has_loop: bool) -> None:
        """Per frame: the paper's relaxation passes once the map has a loop (`has_loop`); with object landmarks, an
        iSAM2 update whenever the robot has left an experience."""
        if self._landmarks_due(experience_map):
            start = time.perf_counter()
            self._solve_landmarks(experience_map)
            self.seconds += time.perf_counter() - start
        if self.config.backend == "relaxation" and has_loop:
            measurements = self._measurements
            parts = experience_map.parts
            if len(parts.roots()) > 1:  # the robot's part only: a stored session not joined stays as stored
                part = _robot_part(experience_map)
                measurements = [m for m in measurements if part[m[0]]]
            relax(experience_map.graph, measurements, self.config.correction_factor, self.config.correction_loops)

    def finish(self, experience_map: CorrectedMap, waiting: bool) -> list[int]:
        """The map as the last frame leaves it: the links still `waiting` optimised; with object landmarks, also
        the observations of the experience the robot is in. Returns the loop links withdrawn."""
        if self.uses_landmarks and experience_map.current >= 0:
            start = time.perf_counter()
            if waiting:
                withdrawn = self._solve_landmarks_healed(experience_map, LOOP_ITERATIONS, final=True)
            else:
                self._solve_landmarks(experience_map, final=True)
                withdrawn = []
            self.seconds += time.perf_counter() - start
            return withdrawn
        if waiting:
            return self.optimise(experience_map)
        return []

    def _optimise_part(self, graph: MapGraph, part: np.ndarray) -> list[int]:
        """The experiences in `part` by the pose graph, again after withdrawing each loop link it disagrees with."""
        withdrawn: list[int] = []
        while True:
            report = self._solve_part(graph, part)
            link = disagreeing_link(graph, report, part, self.config.withdraw_sigmas)
            if link is None:
                return withdrawn
            graph.withdrawn.append(link)
            withdrawn.append(link)

    def _solve_part(self, graph: MapGraph, part: np.ndarray) -> PoseGraphReport:
        """One pose-graph solve of the experiences in `part`, its report's link indices into graph.links."""
        if part.all():
            return optimise_pose_graph(graph, self.config, self.odometry_noise)
        nodes = np.flatnonzero(part)
        renumbered = np.full(len(part), -1)
        renumbered[nodes] = np.arange(len(nodes))  # the part's first node, its frame's anchor, becomes node 0
        indices = [index for index in graph.live() if part[graph.links[index].source]]
        links = [
            replace(graph.links[index], source=int(renumbered[graph.links[index].source]),
                    target=int(renumbered[graph.links[index].target]))
            for index in indices
        ]  # fmt: skip
        piece = MapGraph(graph.poses[nodes].copy(), links)
        report = optimise_pose_graph(piece, self.config, self.odometry_noise)
        graph.poses[nodes] = piece.poses
        loops = tuple(replace(loop, link_index=indices[loop.link_index]) for loop in report.loops)
        return replace(report, loops=loops)

    def _solve_landmarks_healed(self, experience_map: CorrectedMap, iterations: int, final: bool = False) -> list[int]:
        """At a loop: the loop links the pose graph of the robot's part (odometry and loop links, no landmarks; solved
        apart, the map stays) disagrees with withdrawn first (see _optimise_part), then the landmark solver brought up
        to date with the links left, and the factors of withdrawn links it held removed. The pose graph judges
        because a landmark solution can disagree with true loop links: views a robot back in known streets associated
        by a drifted pose before a closure recognised them hold the map where it was, and an incremental solution
        may not have converged (on simulated KITTI 00, judged by the landmark solution updated every fourth
        experience, a whole revisit's true links were withdrawn one after another). Judged first, a wrong link never
        bends the landmark solution."""
        withdrawn: list[int] = []
        if self.config.withdraw_sigmas > 0:
            graph = experience_map.graph
            judged = MapGraph(graph.poses.copy(), graph.links, list(graph.withdrawn))
            withdrawn = self._optimise_part(judged, _robot_part(experience_map))
            graph.withdrawn += withdrawn
        self._solve_landmarks(experience_map, iterations, final)
        if withdrawn:  # links the solver held from earlier loops
            assert self._landmarks is not None
            self._landmarks.withdraw(withdrawn, experience_map.graph)
        return withdrawn

    def _landmarks_due(self, experience_map: CorrectedMap) -> bool:
        """Whether the landmark solver has something to add: no solver yet, or an experience the robot left."""
        if not self.uses_landmarks or experience_map.current < 0:
            return False
        return self._landmarks is None or experience_map.visits - 1 > self._solved_visit

    def _solve_landmarks(self, experience_map: CorrectedMap, iterations: int = 0, final: bool = False) -> None:
        """Bring the landmark solver up to date: the experiences and links made since its last update and the
        observation sums of the experiences left since (with `final`, of the current one too); a new solver for
        the robot's part the first time, after a restore or a join, or when the robot's part is another."""
        assert self.landmark_source is not None
        graph, parts, visits = experience_map.graph, experience_map.parts, experience_map.visits
        part = parts.part_of(experience_map.current)
        if self._landmarks is None or self._landmark_part != part:
            self._landmarks, self._landmark_part = LandmarkSolver(self.config), part
            left = np.arange(len(graph))
        else:
            left = np.unique(experience_map.visited_experiences()[self._solved_visit : visits - 1])
        current = -1 if final else experience_map.current
        self._landmarks.odometer, self._landmarks.localised = experience_map.odometer, experience_map.localised
        self._landmarks.odometry_noise = self.odometry_noise
        self._landmarks.update(graph, parts.members(part), self.landmark_source, left, current, iterations)
        self._solved_visit = visits - 1


def _robot_part(experience_map: CorrectedMap) -> np.ndarray:
    """The experiences of the robot's part of the map (a mask over all)."""
    parts = experience_map.parts
    return parts.members(parts.part_of(experience_map.current))
