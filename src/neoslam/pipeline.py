"""NeoSLAM: `step(frame)` reads as the paper's steps; `run(frames)` drives it with a progress bar.

Built so far: path integration in the head-direction and grid cells (paper 3.3, NeuroSLAM), object keyframes and
loop closure by graph matching (3.2), the object-vector cells learning their firing field from keyframe objects
(3.4), the Hebbian association of keyframes with the cells (3.5), and the object experience map corrected at each
loop (3.6), whose corrected trajectory is the estimate.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from neoslam.cells import GridCells, HeadDirectionCells, HebbianMemory, ObjectVectorCells, circular_difference
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import planar_motion
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.keyframes import KeyframeBuilder
from neoslam.mapping.experience_map import CellState, ExperienceMap
from neoslam.mapping.object_map import MapObject, ObjectMap
from neoslam.types import Frame, Keyframe, LoopClosure, Trajectory

__all__ = ["NeoSLAM", "RunResult", "run", "object_vectors"]


@dataclass(frozen=True)
class RunResult:
    estimate: Trajectory  # corrected trajectory of the final map, one pose per input frame
    online_estimate: Trajectory  # the pose each step returned, with the map as it was then
    odometry: Trajectory
    experience_map: ExperienceMap
    cell_states: np.ndarray  # (n, 4) decoded grid cells unwrapped to metres (x, y, z) and head direction (rad)
    objects: list[MapObject]
    keyframes: list[Keyframe]
    loop_closures: list[LoopClosure]
    recognised_keyframe: int | None  # the first stored keyframe that a closure recognised
    recognised_scores: tuple[np.ndarray, np.ndarray]  # its spectral and verified scores against all (Fig. 4c)
    object_vector_cells: ObjectVectorCells
    hebbian: HebbianMemory
    frame_times_s: np.ndarray  # wall time of each step


def object_vectors(pose: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m, horizontal) and allocentric direction (rad) from the robot to world points (eq. 11)."""
    offsets = centres - pose[:3, 3]
    return np.hypot(offsets[:, 0], offsets[:, 1]), np.arctan2(offsets[:, 1], offsets[:, 0])


class NeoSLAM:
    """The whole system, one frame at a time."""

    def __init__(self, config: NeoSLAMConfig) -> None:
        self.config = config
        self.grid_cells = GridCells(config.grid_cells)
        self.head_direction = HeadDirectionCells(config.head_direction)
        self.object_vector_cells = ObjectVectorCells(config.object_vector)
        self.hebbian = HebbianMemory(config.hebbian)
        self.keyframes = KeyframeBuilder(config.keyframes)
        self.loop_detector = LoopClosureDetector(config.keyframes, config.matching)
        self.object_map = ObjectMap(config.object_map)
        self.experience_map = ExperienceMap(config.experience_map, self.grid_cells.dims, config.head_direction.cells)
        self.detected_closures: list[LoopClosure] = []  # accepted by the loop-closure detector
        self.loop_closures: list[LoopClosure] = []  # and by the experience map's grid-cell check
        self._previous_odometry: np.ndarray | None = None
        self._grid_position = np.zeros(3)  # decoded grid-cell position unwrapped over the torus, metres
        self._grid_centre = self.grid_cells.centre
        self._object_vector_batch: list[tuple[np.ndarray, np.ndarray]] = []
        self._timestamps: list[float] = []
        self._estimate: list[np.ndarray] = []
        self._odometry: list[np.ndarray] = []
        self._cell_states: list[np.ndarray] = []

    def step(self, frame: Frame) -> np.ndarray:
        """Process one frame (the paper's steps in order); returns the current pose estimate T_world_robot."""
        travelled_m = self._integrate_path(frame)  # 3.3: head-direction and grid cells
        odometry = frame.odometry_pose
        keyframe = self.keyframes.add(frame.index, odometry, frame.observations, travelled_m)  # 3.2
        cells = self._cell_state()
        velocities = (frame.linear_velocity, frame.angular_velocity)
        keyframe_id = keyframe.id if keyframe is not None else None
        self.experience_map.step(frame.index, odometry, velocities, cells, travelled_m, keyframe_id)  # 3.6
        if keyframe is not None:
            self._learn_object_vectors(keyframe)  # 3.4
            self._associate(keyframe)  # 3.5
            self._close_loop(keyframe, cells)  # 3.2 matching, 3.6 loop links
        self.experience_map.correct()  # 3.6: relaxation (eq. 18)
        pose = self.experience_map.current_pose(odometry)
        anchor, anchor_from_robot = self.experience_map.anchor(odometry)
        self.object_map.add(pose, frame.observations, anchor, anchor_from_robot)
        self._record(frame, pose)
        return pose

    def _cell_state(self) -> CellState:
        return CellState(self.grid_cells.centre, self.head_direction.centre)

    def _integrate_path(self, frame: Frame) -> float:
        """Head-direction cells turn by the yaw change; grid cells move along the decoded heading (NeuroSLAM).
        Returns the distance travelled since the previous frame."""
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
        return float(np.hypot(horizontal, vertical))  # the odometer counts reversing as travel too

    def _learn_object_vectors(self, keyframe: Keyframe) -> None:
        """Train the OVCN, one epoch per `keyframes_per_epoch` keyframes, for `epochs` epochs (paper 3.4)."""
        config = self.config.object_vector
        if len(self.object_vector_cells.loss_history) >= config.epochs:
            return
        self._object_vector_batch.append(object_vectors(keyframe.pose, keyframe.centers))
        if len(self._object_vector_batch) == config.keyframes_per_epoch:
            distances, directions = (np.concatenate(parts) for parts in zip(*self._object_vector_batch, strict=True))
            self.object_vector_cells.train_epoch(distances, directions)
            self._object_vector_batch.clear()

    def _associate(self, keyframe: Keyframe) -> None:
        """Eq. 14: tie the keyframe's template activity O^k to the current grid x head-direction activity."""
        activity = self.object_vector_cells.template_activity(*object_vectors(keyframe.pose, keyframe.centers))
        if activity > 0:  # a silent template stores nothing (eq. 14 with O^k <= 0)
            self.hebbian.associate(keyframe.id, activity, self.grid_cells.activity, self.head_direction.activity)

    def _close_loop(self, keyframe: Keyframe, cells: CellState) -> None:
        """Closures the detector accepts go to the experience map, which checks them against the cells; an
        accepted one recalls the place's cell state from the Hebbian memory (local-view calibration)."""
        odometer = self.keyframes.odometer_m
        for closure in self.loop_detector.query(keyframe, odometer):
            self.detected_closures.append(closure)
            if self.experience_map.close_loop(closure, cells):
                self.loop_closures.append(closure)
                self._recall(closure)
        self.loop_detector.add(keyframe, odometer)

    def _recall(self, closure: LoopClosure) -> None:
        """Inject the stored keyframe's cell pattern, moved by the closure's offset (the robot is near, not at, the
        stored place, and may face the other way)."""
        if closure.match_keyframe not in self.hebbian:
            return
        recall = self.hebbian.recall(closure.match_keyframe)
        if recall.strength <= 0:
            return
        stored_pose = self.loop_detector.index.keyframes[closure.match_keyframe].pose
        offset_world = stored_pose[:3, :3] @ closure.relative_pose[:3, 3]
        shift = np.round(offset_world / self.grid_cells.cell_size_m).astype(int)
        gc_cells = (recall.gc_cells + shift) % np.asarray(self.grid_cells.dims)
        self.grid_cells.inject_pattern(gc_cells, recall.gc_weights)
        turn = float(np.arctan2(closure.relative_pose[1, 0], closure.relative_pose[0, 0]))
        ring = self.config.head_direction.cells
        hd_cells = (recall.hd_indices + int(round(turn / (2 * np.pi / ring)))) % ring
        self.head_direction.inject_pattern(hd_cells, recall.hd_weights)

    def _record(self, frame: Frame, pose: np.ndarray) -> None:
        self._timestamps.append(frame.timestamp)
        self._odometry.append(frame.odometry_pose)
        self._estimate.append(pose)
        self._cell_states.append(np.append(self._grid_position, self.head_direction.heading))

    def result(self, frame_times_s: np.ndarray) -> RunResult:
        stamps = np.asarray(self._timestamps)
        stored = self.loop_detector.index.keyframes
        recognised = min((c.match_keyframe for c in self.loop_closures), default=None)
        empty = (np.empty(0), np.empty(0))
        odometry = np.asarray(self._odometry).reshape(-1, 4, 4)
        return RunResult(
            estimate=self.experience_map.trajectory(stamps, odometry),
            online_estimate=Trajectory(stamps, np.asarray(self._estimate).reshape(-1, 4, 4)),
            odometry=Trajectory(stamps, odometry),
            experience_map=self.experience_map,
            cell_states=np.asarray(self._cell_states).reshape(-1, 4),
            objects=self.object_map.objects(self.experience_map.graph.poses),
            keyframes=list(stored),
            loop_closures=list(self.loop_closures),
            recognised_keyframe=recognised,
            recognised_scores=self.loop_detector.scores(stored[recognised]) if recognised is not None else empty,
            object_vector_cells=self.object_vector_cells,
            hebbian=self.hebbian,
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
