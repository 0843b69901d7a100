"""NeoSLAM: `step(frame)` reads as the paper's steps; `run(frames)` drives it with a progress bar.

The system: path integration in the head-direction and grid cells (paper 3.3, NeuroSLAM), object keyframes and
loop closure by graph matching (3.2), the object-vector cells learning their firing field from keyframe objects
(3.4), the Hebbian association of keyframes with the cells (3.5), and the object experience map corrected at each
loop (3.6), whose corrected trajectory is the estimate.

Beyond the paper, a run can start from a stored map (neoslam.store): it is a new session in its own frame until
its keyframes relocalise in the stored map (searched whole), then the session joins the map's frame and its
keyframes join the map. `map_state()` gives what a map file stores.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace

import numpy as np
from tqdm import tqdm

from neoslam.cells import GridCells, HeadDirectionCells, HebbianMemory, ObjectVectorCells, circular_difference
from neoslam.cells.attractor import ShiftKernel, circular_mean, circular_shift
from neoslam.cells.place import offset_in_cells
from neoslam.config import NeoSLAMConfig
from neoslam.geometry import invert_pose, planar_motion
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.keyframes import KeyframeBuilder
from neoslam.mapping.experience_map import CellState, ExperienceMap, Revisit
from neoslam.mapping.moving_objects import MovingObjectDetector
from neoslam.mapping.object_map import MapObject, ObjectMap
from neoslam.relocalisation import StoredMapRelocalisation
from neoslam.step_inputs import FrameOrder
from neoslam.types import Frame, Keyframe, LoopClosure, MapState, SessionRecord, StoredClosure, Trajectory

__all__ = ["NeoSLAM", "RunResult", "StepObserver", "run", "object_vectors"]

FRAMES_PER_CHUNK = 4096  # the per-frame record grows a chunk at a time: no doubling, no copy of what it holds
RECORD_WIDTH = 29  # timestamp, odometry pose (12), pose estimate (12), cells (4)


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
    # Ids of the keyframes the loop detector holds, and the recognised one's spectral and verified scores against
    # each (Fig. 4c).
    recognised_scores: tuple[np.ndarray, np.ndarray, np.ndarray]
    object_vector_cells: ObjectVectorCells
    hebbian: HebbianMemory
    frame_times_s: np.ndarray  # wall time of each step
    # Frame of every keyframe made, stored or recognised as a stored one (the query frames of loop recall);
    # `keyframes` holds the stored ones this session made.
    keyframe_frames: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    session: SessionRecord = SessionRecord(1, "", 0, None)  # this run, in a map kept over sessions
    first_keyframe: int = 0  # keyframes with lower ids are a stored map's (earlier sessions')
    moving_objects: list[MapObject] = field(default_factory=list)  # where each moving object was last seen
    moving_observations: int = 0  # observations kept out of keyframes and the map as moving
    # the odometry's heading and position noise the motion detector allowed for at the end, rad and m per root second
    odometry_noise: tuple[float, float] = (0.0, 0.0)

    def closure_sessions(self) -> list[tuple[int, int]]:
        """Per loop closure, this session and the session of the keyframe it recognised."""
        return [(self.session.id, self.experience_map.session_of(c.match_keyframe)) for c in self.loop_closures]

    def session_closures(self) -> list[LoopClosure]:
        """The closures with keyframes of this session (their frames are this run's)."""
        return [c for c in self.loop_closures if c.match_keyframe >= self.first_keyframe]


def object_vectors(pose: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m, horizontal) and allocentric direction (rad) from the robot to world points (eq. 11)."""
    offsets = centres - pose[:3, 3]
    return np.hypot(offsets[:, 0], offsets[:, 1]), np.arctan2(offsets[:, 1], offsets[:, 0])


class NeoSLAM:
    """The whole system, one frame at a time."""

    def __init__(self, config: NeoSLAMConfig, stored: MapState | None = None, session_name: str = "") -> None:
        """`stored`: a map to start from (this run is its next session), as neoslam.store reads it."""
        self.config = config
        self.grid_cells = GridCells(config.grid_cells)
        self.head_direction = HeadDirectionCells(config.head_direction)
        self.object_vector_cells = ObjectVectorCells(config.object_vector)
        self.hebbian = HebbianMemory(config.hebbian)
        stored = stored if stored is not None else MapState()
        moving = config.moving_objects
        provisional = moving.enabled and moving.unjudged == "wait"
        self.keyframes = KeyframeBuilder(config.keyframes, stored.next_keyframe, provisional)
        self.loop_detector = LoopClosureDetector(config.keyframes, config.matching)
        self.object_map = ObjectMap(config.object_map, config.keyframes.footprints)
        self.moving_objects = MovingObjectDetector(
            config.moving_objects, config.object_map, config.keyframes.footprints
        )
        if moving.window_scatter > 0:  # a broken-off car's first views join no keyframe
            self.keyframes.moves = self.moving_objects.window_views_move
        self.experience_map = ExperienceMap(config.experience_map, self.grid_cells.dims, config.head_direction.cells)
        self.experience_map.backend.landmark_source = self.object_map  # its objects, landmarks with object_landmarks
        self.detected_closures: list[LoopClosure] = []  # accepted by the loop-closure detector
        self.loop_closures: list[LoopClosure] = []  # and by the experience map's grid-cell check
        self._previous_odometry: np.ndarray | None = None
        self._previous_time: float | None = None
        # What the API is given, checked as the CLI's files are.
        self._frame_order = FrameOrder(config.motion_limits, Frame)
        self._grid_position = np.zeros(3)  # decoded grid-cell position unwrapped over the torus, metres
        self._grid_centre = self.grid_cells.centre
        self._object_vector_batch: list[tuple[np.ndarray, np.ndarray]] = []
        self._unassociated: list[tuple[Keyframe, np.ndarray, np.ndarray]] = []  # made before the OVCN learnt
        self._query_poses: dict[int, np.ndarray] = {}  # odometry pose of the keyframes a closure can come from
        # Per frame, in chunks of arrays (a lifelong drive records many frames): timestamp, odometry pose and pose
        # estimate (3x4 rows each), decoded cells (x, y, z, heading).
        self._chunks: list[np.ndarray] = []
        self._recorded = 0
        self.stored = stored
        self.session = SessionRecord(stored.next_session, session_name, 0, None)
        self._object_vector_weights: tuple[int, dict[str, np.ndarray]] = (-1, {})  # a copy, by epochs learnt
        self._restore(stored)
        self.relocalisation = StoredMapRelocalisation(config, stored.keyframes, self.experience_map, self.loop_detector)

    def _restore(self, stored: MapState) -> None:
        """Start from a stored map: experiences, objects, associations and the OVCN as stored (its keyframes wait
        in the relocalisation, in the map's frame)."""
        if not stored.experiences:
            return
        self.experience_map.restore(stored, self.session.id)
        self.object_map.restore(stored.objects)
        self.hebbian.restore(stored.hebbian, self.grid_cells.dims, self.head_direction.cells)
        if stored.object_vector_weights:
            self.object_vector_cells.restore(stored.object_vector_weights, stored.object_vector_losses)

    def step(self, frame: Frame) -> np.ndarray:
        """Process one frame (the paper's steps in order); returns the current pose estimate T_world_robot.
        ValueError for a frame out of order or beyond `motion_limits` (nothing of it is taken)."""
        self._frame_order.check(frame)
        travelled_m = self._integrate_path(frame)  # 3.3: head-direction and grid cells
        elapsed_s = self._elapsed(frame)
        odometry = frame.odometry_pose
        observations = self.moving_objects.static(frame, self.keyframes.window)  # beyond the paper: no movers
        keyframe = self.keyframes.add(frame.index, odometry, observations, travelled_m, frame.timestamp)  # 3.2
        cells = self._cell_state()
        velocities = (frame.linear_velocity, frame.angular_velocity)
        keyframe_id = keyframe.id if keyframe is not None else None
        closures: list[LoopClosure] = []
        revisit = None
        if keyframe is not None:  # 3.2 matching; a stored keyframe seen again is not stored twice (lifelong)
            closures = self._find_loops(frame.index, keyframe, odometry)
            cells = self._cell_state()  # relocalising in a stored map moves the cells to its frame
            revisit = self.experience_map.recognise(keyframe.id, closures, cells, odometry)
        self._weigh_odometry()  # beyond the paper: links by their time too, at the odometry noise estimated online
        self.experience_map.step(frame.index, odometry, velocities, cells, travelled_m, keyframe_id, revisit, elapsed_s)
        if keyframe is not None:
            self._learn_object_vectors(keyframe)  # 3.4
            if revisit is None:
                self._associate(keyframe)  # 3.5
            self._close_loop(keyframe, closures, cells, revisit)  # 3.6 loop links
        self.experience_map.correct()  # 3.6: relaxation (eq. 18)
        pose = self.experience_map.current_pose(odometry)
        anchor, anchor_from_robot = self.experience_map.anchor(odometry)
        parts = self.experience_map.parts.labels()  # a later session's objects stay apart until it relocalises
        self.object_map.refresh(self.experience_map.graph.poses, parts=parts)  # objects follow the corrected map
        self.object_map.add(pose, observations, anchor, anchor_from_robot, self.keyframes.odometer_m, parts)
        self._record(frame, pose)
        return pose

    def _find_loops(self, frame_index: int, keyframe: Keyframe, odometry: np.ndarray) -> list[LoopClosure]:
        """The keyframe's closures: with a stored map's parts not joined yet (searched whole; the first joins this
        session to the map), then within the map this session is in (a query keyframe closes one loop)."""
        relocalisation = self.relocalisation.relocalise(keyframe, odometry, self.keyframes.odometer_m)
        if relocalisation.joined is not None:
            self._take_stored_cell_state(relocalisation.joined)
            if self.session.relocalised_frame is None:
                self.session = replace(self.session, relocalised_frame=frame_index)
        queries = {closure.query_keyframe for closure in relocalisation.closures}
        found = self.loop_detector.query(keyframe, self.keyframes.odometer_m)
        return relocalisation.closures + [closure for closure in found if closure.query_keyframe not in queries]

    def _take_stored_cell_state(self, closure: LoopClosure) -> None:
        """Relocalised in a stored map: the cells take the stored place's state, moved to where the closure puts
        the robot (the limit of a strong local-view injection; two sessions' cells start apart)."""
        stored = self.experience_map.experiences[self.experience_map.experience_of(closure.match_keyframe)]
        heading = stored.head_direction * self.head_direction.cell_angle
        shift, turn = offset_in_cells(heading, stored.pose, closure.relative_pose, self.grid_cells, self.head_direction)
        self.grid_cells.reset((stored.grid_cell + shift) % np.asarray(self.grid_cells.dims))
        self.head_direction.reset((stored.head_direction + turn) % self.head_direction.cells)
        self._grid_centre = self.grid_cells.centre  # the unwrapped decoded position goes on, not by the jump
        self.experience_map.recalled(stored.id, self._cell_state(), self._cell_state())

    @property
    def frames_processed(self) -> int:
        return self._recorded

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

    def _elapsed(self, frame: Frame) -> float:
        """Seconds since the previous frame (0 for the first)."""
        previous, self._previous_time = self._previous_time, frame.timestamp
        return 0.0 if previous is None else frame.timestamp - previous

    def _weigh_odometry(self) -> None:
        """The pose graph's odometry links grow uncertain with time too, at the noise the moving-object tracks allow
        for (as stated, or raised by their online estimate): a robot that stands still or crawls drifts as well."""
        if self.config.experience_map.odometry_weights == "estimated":
            self.experience_map.backend.odometry_noise = self.moving_objects.odometry_noise()

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
        """Eq. 14: tie the keyframe's template activity O^k to the current grid x head-direction activity.

        Until the OVCN has learnt its first epoch its output means nothing, and it was negative for the first
        keyframes of the simulated KITTI drives (none of the 19 before the first epoch of 05 was stored): the
        start of a route, where a drive so often comes back, could never be recalled. Keyframes made before then
        keep their cell activity and are associated as soon as the OVCN has learnt."""
        if not self.object_vector_cells.loss_history:
            self._unassociated.append((keyframe, self.grid_cells.activity.copy(), self.head_direction.activity.copy()))
            return
        for waiting, grid, heading in self._unassociated:
            self._store_association(waiting, grid, heading)
        self._unassociated.clear()
        self._store_association(keyframe, self.grid_cells.activity, self.head_direction.activity)

    def _store_association(self, keyframe: Keyframe, grid: np.ndarray, heading: np.ndarray) -> None:
        activity = self.object_vector_cells.template_activity(*object_vectors(keyframe.pose, keyframe.centers))
        if activity > 0:  # a silent template stores nothing (eq. 14 with O^k <= 0)
            self.hebbian.associate(keyframe.id, activity, grid, heading)

    def _close_loop(
        self, keyframe: Keyframe, closures: list[LoopClosure], cells: CellState, revisit: Revisit | None
    ) -> None:
        """Closures the detector accepted go to the experience map, which checks them against the cells (the
        keyframe's own closure, when it recognised a stored keyframe, was taken already as the revisit); each then
        recalls the place's cell state from the Hebbian memory (local-view calibration): every closure the detector
        accepted (NeuroSLAM: a re-seen view calibrates the cells whatever the map does with it), or with
        hebbian.recall_on = accepted only those the check accepted (the paper's order). A closure is checked
        against the cells as they are, after the recalls of the closures before it. A keyframe that is a stored
        one seen again is not stored again."""
        self._query_poses[keyframe.id] = keyframe.pose
        kept = max(self.config.matching.consecutive, self.config.map_store.relocalisation_consecutive)
        for old in [k for k in self._query_poses if k < keyframe.id - kept]:
            del self._query_poses[old]  # the detectors emit closures of the last `consecutive` keyframes only
        every = self.config.hebbian.recall_on == "detected"
        for closure in closures:
            self.detected_closures.append(closure)
            taken = revisit is not None and closure is revisit.closure
            accepted = taken or self.experience_map.close_loop(closure, self._cell_state())
            if accepted:
                self.loop_closures.append(closure)
            if accepted or every:
                self._recall(closure, keyframe)
        if revisit is None:
            self.loop_detector.add(keyframe, self.keyframes.odometer_m)

    def _recall(self, closure: LoopClosure, keyframe: Keyframe) -> None:
        """Re-anchor the cells at the recognised place: inject the stored keyframe's cell pattern where the robot
        is now, in the cells' own frame, with `recall_gain` times the cells' injection energy.

        The closure's fit puts its query keyframe in the stored keyframe's frame and the odometry since moves that
        to the current keyframe (a closure can confirm an earlier keyframe). The pattern moves by fractional cells
        with the path integration's shift blend (a cell is 8 m and 10 degrees)."""
        stored_keyframes = self.loop_detector.index.keyframes
        if closure.match_keyframe not in self.hebbian or closure.match_keyframe not in stored_keyframes:
            return
        recall = self.hebbian.recall(closure.match_keyframe)
        if recall.strength <= 0:
            return
        stored = stored_keyframes[closure.match_keyframe]
        robot = closure.relative_pose @ invert_pose(self._query_poses[closure.query_keyframe]) @ keyframe.pose
        ring = self.head_direction.cells
        heading = circular_mean(recall.hd_indices, recall.hd_weights, ring) * self.head_direction.cell_angle
        shift, turn = offset_in_cells(heading, stored.pose, robot, self.grid_cells, self.head_direction)
        gain = self.config.hebbian.recall_gain
        grid = self.config.grid_cells
        gc_cells, gc_weights = _moved_pattern(
            recall.gc_cells, recall.gc_weights, self.grid_cells.dims, shift, grid.shift_kernel
        )
        self.grid_cells.inject_pattern(gc_cells, gc_weights, gain * grid.injection_energy)
        hd = self.config.head_direction
        hd_cells, hd_weights = _moved_pattern(
            recall.hd_indices[:, None], recall.hd_weights, (ring,), np.array([turn]), hd.shift_kernel
        )
        self.head_direction.inject_pattern(hd_cells[:, 0], hd_weights, gain * hd.injection_energy)
        experience = self.experience_map.keyframe_experiences.get(closure.match_keyframe)
        if experience is not None:  # the drift gate's chain of anchors (neoslam.mapping.cell_lineage)
            place = self.experience_map.experiences[experience]
            recalled = CellState(place.grid_cell + shift, (place.head_direction + turn) % ring)
            self.experience_map.recalled(experience, self._cell_state(), recalled)

    def _record(self, frame: Frame, pose: np.ndarray) -> None:
        if self._recorded == FRAMES_PER_CHUNK * len(self._chunks):
            self._chunks.append(np.zeros((FRAMES_PER_CHUNK, RECORD_WIDTH)))
        row = self._chunks[-1][self._recorded % FRAMES_PER_CHUNK]
        row[0] = frame.timestamp
        row[1:13] = frame.odometry_pose[:3].ravel()
        row[13:25] = pose[:3].ravel()
        row[25:28] = self._grid_position
        row[28] = self.head_direction.heading
        self._recorded += 1

    def _record_columns(self, columns: slice) -> np.ndarray:
        if not self._chunks:
            return np.zeros((0, RECORD_WIDTH))[:, columns]
        return np.concatenate(self._chunks)[: self._recorded, columns]

    def _recorded_poses(self, columns: slice) -> np.ndarray:
        poses = np.tile(np.eye(4), (self._recorded, 1, 1))
        poses[:, :3] = self._record_columns(columns).reshape(-1, 3, 4)
        return poses

    def own_keyframes(self) -> list[Keyframe]:
        """The keyframes this session stored (the loop detector also holds those of a stored map it joined)."""
        return [k for k in self.loop_detector.index.keyframes if k.id >= self.keyframes.first_id]

    def session_record(self) -> SessionRecord:
        return replace(self.session, frames=self.frames_processed)

    def map_state(self) -> MapState:
        """What a map file stores: the stored map this run started from and what this session added to it (the
        arrays are the live ones, not copies)."""
        session_of = self.experience_map.session_of
        closures = [StoredClosure(self.session.id, session_of(c.match_keyframe), c) for c in self.loop_closures]
        return MapState(
            sessions=[*self.stored.sessions, self.session_record()],
            keyframes=[*self.stored.keyframes, *self.own_keyframes()],
            keyframe_experience=self.experience_map.keyframe_experiences,
            experiences=self.experience_map.experiences,
            experience_poses=self.experience_map.graph.poses,
            links=self.experience_map.graph.links,
            withdrawn_links=self.experience_map.withdrawn_links,
            closures=[*self.stored.closures, *closures],
            objects=self.object_map.state(),
            hebbian=self.hebbian.traces(),
            object_vector_weights=self._learnt_object_vector_weights(),
            object_vector_losses=self.object_vector_cells.loss_history,
        )

    def _learnt_object_vector_weights(self) -> dict[str, np.ndarray]:
        """The OVCN's weights, copied again only once it has learnt another epoch (a map is committed at every
        keyframe, the OVCN learns a few epochs in all)."""
        epochs = len(self.object_vector_cells.loss_history)
        if self._object_vector_weights[0] != epochs:
            self._object_vector_weights = (epochs, self.object_vector_cells.weights())
        return self._object_vector_weights[1]

    def _scores(self, keyframe: Keyframe) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ids of the keyframes the loop detector holds and a keyframe's matching scores against each."""
        ids = np.array([k.id for k in self.loop_detector.index.keyframes], dtype=int)
        return (ids, *self.loop_detector.scores(keyframe))

    def result(self, frame_times_s: np.ndarray) -> RunResult:
        """The run so far; `frame_times_s`, the wall time of each step, one per frame processed (empty: not
        timed)."""
        if np.shape(frame_times_s) not in ((self._recorded,), (0,)):
            raise ValueError(
                f"frame_times_s: expected one time per frame processed ({self._recorded}) or none, got shape "
                f"{np.shape(frame_times_s)}"
            )
        self.experience_map.finish()  # links still waiting for the pose graph
        parts = self.experience_map.parts.labels()
        self.object_map.refresh(self.experience_map.graph.poses, True, parts)  # the last merges, on the final map
        stamps = self._record_columns(slice(0, 1))[:, 0]
        stored = self.loop_detector.index.keyframes
        own = [c.match_keyframe for c in self.loop_closures if c.match_keyframe >= self.keyframes.first_id]
        recognised = min(own, default=None)
        empty = (np.empty(0, dtype=int), np.empty(0), np.empty(0))
        odometry = self._recorded_poses(slice(1, 13))
        estimate = self.experience_map.trajectory(stamps, odometry)
        return RunResult(
            estimate=estimate,
            online_estimate=Trajectory(stamps, self._recorded_poses(slice(13, 25))),
            odometry=Trajectory(stamps, odometry),
            experience_map=self.experience_map,
            cell_states=self._record_columns(slice(25, 29)),
            objects=self.object_map.objects(self.experience_map.graph.poses),
            keyframes=self.own_keyframes(),
            loop_closures=list(self.loop_closures),
            recognised_keyframe=recognised,
            recognised_scores=self._scores(stored[recognised]) if recognised is not None else empty,
            object_vector_cells=self.object_vector_cells,
            hebbian=self.hebbian,
            frame_times_s=frame_times_s,
            keyframe_frames=np.asarray(self.keyframes.frames, dtype=int),
            session=self.session_record(),
            first_keyframe=self.keyframes.first_id,
            moving_objects=self.moving_objects.objects(estimate.poses),
            moving_observations=self.moving_objects.flagged,
            odometry_noise=self.moving_objects.odometry_noise(),
        )


def _moved_pattern(
    cells: np.ndarray, weights: np.ndarray, dims: tuple[int, ...], offset: np.ndarray, kernel: ShiftKernel
) -> tuple[np.ndarray, np.ndarray]:
    """A sparse pattern (integer cells (k, d), weights (k,)) moved by `offset` cells per axis, fractional, on the
    torus `dims`: the blend of integer shifts that path integration uses. Returns its non-zero cells and weights."""
    dense = np.zeros(dims)
    np.add.at(dense, tuple((np.asarray(cells) % np.asarray(dims)).T), weights)
    moved = circular_shift(dense, [offset], kernel)
    where = np.argwhere(moved > 0)
    return where, moved[tuple(where.T)]


StepObserver = Callable[["NeoSLAM", Frame, np.ndarray], None]


def run(
    frames: Iterable[Frame],
    config: NeoSLAMConfig,
    total: int | None = None,
    progress: bool = True,
    on_step: StepObserver | None = None,
    stored: MapState | None = None,
    session_name: str = "",
) -> RunResult:
    """Drive NeoSLAM over frames; wall time per frame is recorded for the timing block of metrics.json.
    `on_step(slam, frame, pose)` is called after each step (a live view, a map file's commits); its time is not
    counted as the step's. `stored`: a map to start from (this run is its next session)."""
    slam = NeoSLAM(config, stored, session_name)
    times = []
    for frame in tqdm(frames, total=total, desc="neoslam", unit="frame", disable=not progress):
        start = time.perf_counter()
        pose = slam.step(frame)
        times.append(time.perf_counter() - start)
        if on_step is not None:
            on_step(slam, frame, pose)
    return slam.result(np.asarray(times))
