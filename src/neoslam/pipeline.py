"""NeoSLAM: `step(frame)` reads as the paper's steps; `run(frames)` drives it with a progress bar.

Built so far: path integration in the head-direction and grid cells (paper 3.3, NeuroSLAM), the object-vector
cells learning their firing field from the object vectors the robot observes (3.4), and the object map. The
estimate is still the odometry: object keyframes, loop closure and the experience map (3.2, 3.5, 3.6) plug in here
without changing the CLI.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from neoslam.cells import GridCells, HeadDirectionCells, ObjectVectorCells, circular_difference
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import planar_motion, transform_points
from neoslam.io.frames import camera_points_to_robot
from neoslam.mapping.object_map import MapObject, ObjectMap
from neoslam.types import Frame, LoopClosure, Trajectory

__all__ = ["NeoSLAM", "RunResult", "run", "object_vectors"]


@dataclass(frozen=True)
class RunResult:
    estimate: Trajectory  # corrected trajectory, one pose per input frame
    odometry: Trajectory
    cell_states: np.ndarray  # (n, 4) decoded grid cells unwrapped to metres (x, y, z) and head direction (rad)
    objects: list[MapObject]
    loop_closures: list[LoopClosure]
    object_vector_cells: ObjectVectorCells
    frame_times_s: np.ndarray  # wall time of each step


def object_vectors(pose: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m, horizontal) and allocentric direction (rad) from the robot to each observed object (eq. 11)."""
    if not frame.observations:
        return np.empty(0), np.empty(0)
    in_robot = camera_points_to_robot(np.array([o.center_camera for o in frame.observations]))
    offsets = transform_points(pose, in_robot) - pose[:3, 3]
    return np.hypot(offsets[:, 0], offsets[:, 1]), np.arctan2(offsets[:, 1], offsets[:, 0])


class NeoSLAM:
    """The whole system, one frame at a time."""

    def __init__(self, config: NeoSLAMConfig) -> None:
        self.config = config
        self.grid_cells = GridCells(config.grid_cells)
        self.head_direction = HeadDirectionCells(config.head_direction)
        self.object_vector_cells = ObjectVectorCells(config.object_vector)
        self.object_map = ObjectMap(config.object_map)
        self.loop_closures: list[LoopClosure] = []
        self._previous_odometry: np.ndarray | None = None
        self._grid_position = np.zeros(3)  # decoded grid-cell position unwrapped over the torus, metres
        self._grid_centre = self.grid_cells.centre
        self._object_vector_batch: list[tuple[np.ndarray, np.ndarray]] = []
        self._timestamps: list[float] = []
        self._estimate: list[np.ndarray] = []
        self._odometry: list[np.ndarray] = []
        self._cell_states: list[np.ndarray] = []

    def step(self, frame: Frame) -> np.ndarray:
        """Process one frame; returns the current pose estimate T_world_robot."""
        self._integrate_path(frame)
        pose = frame.odometry_pose  # the experience map will correct this once loops are closed
        self._learn_object_vectors(pose, frame)
        self.object_map.add(pose, frame.observations)
        self._record(frame, pose)
        return pose

    def _integrate_path(self, frame: Frame) -> None:
        """Head-direction cells turn by the yaw change; grid cells move along the decoded heading (NeuroSLAM)."""
        previous = frame.odometry_pose if self._previous_odometry is None else self._previous_odometry
        horizontal, yaw_change, vertical = planar_motion(previous, frame.odometry_pose)
        self.head_direction.step(yaw_change)
        self.grid_cells.step(horizontal, self.head_direction.heading, vertical)
        centre = self.grid_cells.centre
        self._grid_position += circular_difference(centre, self._grid_centre, self.grid_cells.dims) * (
            self.grid_cells.cell_size_m
        )
        self._grid_centre = centre
        self._previous_odometry = frame.odometry_pose

    def _learn_object_vectors(self, pose: np.ndarray, frame: Frame) -> None:
        """Train the OVCN, one epoch per `keyframes_per_epoch` views of objects, for `epochs` epochs (paper 3.4).

        Until object keyframes land, every frame that sees objects counts as one keyframe of training data.
        """
        config = self.config.object_vector
        if len(self.object_vector_cells.loss_history) >= config.epochs or not frame.observations:
            return
        self._object_vector_batch.append(object_vectors(pose, frame))
        if len(self._object_vector_batch) == config.keyframes_per_epoch:
            distances, directions = (np.concatenate(parts) for parts in zip(*self._object_vector_batch, strict=True))
            self.object_vector_cells.train_epoch(distances, directions)
            self._object_vector_batch.clear()

    def _record(self, frame: Frame, pose: np.ndarray) -> None:
        self._timestamps.append(frame.timestamp)
        self._odometry.append(frame.odometry_pose)
        self._estimate.append(pose)
        self._cell_states.append(np.append(self._grid_position, self.head_direction.heading))

    def result(self, frame_times_s: np.ndarray) -> RunResult:
        stamps = np.asarray(self._timestamps)
        return RunResult(
            estimate=Trajectory(stamps, np.asarray(self._estimate).reshape(-1, 4, 4)),
            odometry=Trajectory(stamps, np.asarray(self._odometry).reshape(-1, 4, 4)),
            cell_states=np.asarray(self._cell_states).reshape(-1, 4),
            objects=self.object_map.objects(),
            loop_closures=list(self.loop_closures),
            object_vector_cells=self.object_vector_cells,
            frame_times_s=frame_times_s,
        )


def run(frames: Iterable[Frame], config: NeoSLAMConfig, total: int | None = None, progress: bool = True) -> RunResult:
    """Drive NeoSLAM over frames; wall time per frame is recorded for the timing block of metrics.json."""
    slam = NeoSLAM(config)
    times = []
    for frame in tqdm(frames, total=total, desc="neoslam", unit="frame", disable=not progress):
        start = time.perf_counter()
        slam.step(frame)
        times.append(time.perf_counter() - start)
    return slam.result(np.asarray(times))
