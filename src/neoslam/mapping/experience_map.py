"""The object experience map (paper 3.6, eq. 15-18): experiences of the cells' state, linked by odometry and by
loop closures, corrected by relaxation (the paper) or pose-graph optimisation (beyond it).

An experience exp = [P_gc, P_hdc, Xr, KF] (eq. 16) is made for every new keyframe (a new template, NeuroSLAM's rule)
and when the decoded cells have moved more than S_max from the current experience's (eq. 17: stretches without
objects still get experiences). Each new experience is linked to the previous one by the odometric displacement.
A loop closure is accepted only when the recognised experience's grid-cell state is within
`gc_distance_threshold` cells of the current one (the paper's second guard); it then links the two experiences
with the metric transform of the object fit and triggers the correction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import ExperienceMapConfig
from neoslam.geometry import invert_pose
from neoslam.mapping.graph import Link, MapGraph
from neoslam.mapping.pose_graph import optimise_pose_graph
from neoslam.mapping.relaxation import LinkMeasurement, link_measurement, relax
from neoslam.types import Experience, LoopClosure, Trajectory

__all__ = ["CellState", "ExperienceMap"]


def _circular(a: np.ndarray, b: np.ndarray, dims: np.ndarray) -> np.ndarray:
    d = np.abs(np.asarray(a, float) - np.asarray(b, float)) % dims
    return np.minimum(d, dims - d)


@dataclass(frozen=True)
class CellState:
    """Decoded grid-cell centre (cells) and head-direction cell (cells) at one frame."""

    grid: np.ndarray
    head_direction: float


class ExperienceMap:
    """Experiences, their links and the map correction."""

    def __init__(self, config: ExperienceMapConfig, grid_dims: tuple[int, ...], head_direction_cells: int) -> None:
        self.config = config
        self.grid_dims = np.asarray(grid_dims, dtype=float)
        self.head_direction_cells = float(head_direction_cells)
        self.experiences: list[Experience] = []
        self.graph = MapGraph()
        self._measurements: list[LinkMeasurement] = []
        self._odometry_poses: list[np.ndarray] = []  # each experience's odometry pose, to place frames between
        self._by_keyframe: dict[int, int] = {}
        self._frame_experience: list[int] = []  # the current experience of every frame
        self._travelled_since = 0.0
        self.rejected_closures: list[LoopClosure] = []
        self.accepted_closures: list[LoopClosure] = []

    @property
    def current(self) -> int:
        return len(self.experiences) - 1

    def similarity(self, cells: CellState, experience: Experience) -> float:
        """S of eq. 17: μ_gc |P_gc − P_gc,i| + μ_hdc |P_hdc − P_hdc,i|, circular distances in cells."""
        grid = np.linalg.norm(_circular(cells.grid, experience.grid_cell, self.grid_dims))
        heading = float(_circular(cells.head_direction, experience.head_direction, self.head_direction_cells))
        return self.config.mu_gc * grid + self.config.mu_hdc * heading

    def step(self, frame_index: int, odometry_pose: np.ndarray, velocities, cells: CellState, travelled_m: float,
             keyframe_id: int | None) -> None:  # fmt: skip
        """Record one frame: a new experience for a new keyframe, or when the cells left the current one."""
        self._travelled_since += travelled_m
        new_template = keyframe_id is not None
        if not self.experiences or new_template or self._cells_moved_on(cells):
            self._create(frame_index, odometry_pose, velocities, cells, keyframe_id)
        self._frame_experience.append(self.current)

    def _cells_moved_on(self, cells: CellState) -> bool:
        return self.similarity(cells, self.experiences[-1]) > self.config.similarity_threshold

    def _create(self, frame_index, odometry_pose, velocities, cells: CellState, keyframe_id) -> None:
        previous = self.current
        experience = Experience(
            id=len(self.experiences),
            frame_index=frame_index,
            grid_cell=np.asarray(cells.grid, float).copy(),
            head_direction=float(cells.head_direction),
            pose=odometry_pose.copy(),
            linear_velocity=np.asarray(velocities[0]),
            angular_velocity=np.asarray(velocities[1]),
            keyframe_id=keyframe_id,
        )
        if previous >= 0:  # place it where the odometry says, relative to the corrected previous experience
            relative = invert_pose(self._odometry_poses[previous]) @ odometry_pose
            self.graph.add_node(self.graph.poses[previous] @ relative)
            self._link(Link(previous, experience.id, relative, "odometry", self._travelled_since))
        else:
            self.graph.add_node(odometry_pose.copy())
        self.experiences.append(experience)
        self._odometry_poses.append(odometry_pose.copy())
        if keyframe_id is not None:
            self._by_keyframe[keyframe_id] = experience.id
        self._travelled_since = 0.0

    def _link(self, link: Link) -> None:
        self.graph.add_link(link)
        self._measurements.append(link_measurement(self.graph, link))

    def close_loop(self, closure: LoopClosure, cells: CellState) -> bool:
        """Link the experiences of a closure's keyframes if the cells agree (paper: about seven bins); returns
        whether the closure was accepted into the map."""
        stored = self._by_keyframe.get(closure.match_keyframe)
        query = self._by_keyframe.get(closure.query_keyframe)
        if stored is None or query is None:
            return False
        distance = np.linalg.norm(_circular(cells.grid, self.experiences[stored].grid_cell, self.grid_dims))
        if distance > self.config.gc_distance_threshold:
            self.rejected_closures.append(closure)
            return False
        self._link(Link(stored, query, closure.relative_pose, "loop", 0.0))
        self.accepted_closures.append(closure)
        if self.config.backend == "pose-graph":
            optimise_pose_graph(self.graph, self.config)
        return True

    def correct(self) -> None:
        """Per frame: the paper's relaxation passes, once the map has a loop to relax."""
        if self.config.backend == "relaxation" and self.accepted_closures:
            relax(self.graph, self._measurements, self.config.correction_factor, self.config.correction_loops)

    def corrected_points(self, keyframe_id: int, points: np.ndarray) -> np.ndarray:
        """World points of a keyframe (odometry frame when it was made) in the corrected map."""
        experience = self._by_keyframe[keyframe_id]
        correction = self.graph.poses[experience] @ invert_pose(self._odometry_poses[experience])
        return points @ correction[:3, :3].T + correction[:3, 3]

    def anchor(self, odometry_pose: np.ndarray) -> tuple[int, np.ndarray]:
        """The current experience and the robot's pose in its frame (from the odometry since it was made)."""
        return self.current, invert_pose(self._odometry_poses[self.current]) @ odometry_pose

    def current_pose(self, odometry_pose: np.ndarray) -> np.ndarray:
        """The corrected pose of a frame of the current experience, from its odometry pose."""
        anchor = self._odometry_poses[self.current]
        return self.graph.poses[self.current] @ invert_pose(anchor) @ odometry_pose

    def trajectory(self, timestamps: np.ndarray, odometry_poses: np.ndarray) -> Trajectory:
        """A pose for every frame: its experience's corrected pose, moved on by the odometry since."""
        owner = np.asarray(self._frame_experience, dtype=int)
        anchors = np.asarray(self._odometry_poses).reshape(-1, 4, 4)[owner]
        poses = self.graph.poses[owner] @ invert_pose(anchors) @ odometry_poses
        return Trajectory(np.asarray(timestamps), poses)
