"""The perception front end (paper 3.1): a stereo image sequence becomes NeoSLAM frames.

Per frame: detect objects in the left image, place them in 3-D by ORB stereo matching, and move the robot by
stereo visual odometry (or by a pose file). The frame carries the odometry pose, the body velocities of the step
and the object observations; nothing here reads ground truth.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from neoslam.config import CameraConfig, MotionLimitsConfig
from neoslam.config.perception import PerceptionConfig
from neoslam.errors import ConfigError, InputError
from neoslam.geometry import body_velocities, camera_poses_to_robot, invert_pose
from neoslam.io.motion_limits import check_pose_steps
from neoslam.io.trajectory_files import data_line_numbers, read_trajectory
from neoslam.perception.detection import Detection, ObjectDetector
from neoslam.perception.detections_file import DetectionsFile
from neoslam.perception.detector import make_detector
from neoslam.perception.odometry import StereoOdometry
from neoslam.perception.pipelined import staged
from neoslam.perception.stereo import ObjectTriangulator
from neoslam.step_inputs import velocity_problem
from neoslam.types import Frame, ObjectObservation, Trajectory

__all__ = [
    "StereoSequence",
    "MotionSource",
    "PerceptionTimes",
    "StereoPair",
    "DetectedPair",
    "PlacedPair",
    "StereoFrontEnd",
    "ImageDataset",
    "open_front_end",
]

STAGES = ("read", "detection", "stereo", "odometry")


class StereoSequence(Protocol):
    """Rectified stereo frames with their calibration and times: a KITTI sequence, a replay of one, ..."""

    camera: CameraConfig
    timestamps: np.ndarray

    @property
    def name(self) -> str: ...

    @property
    def ground_truth(self) -> Trajectory | None: ...  # evaluation only

    def __len__(self) -> int: ...

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]: ...


class MotionSource(Protocol):
    def pose(self, frame_index: int, left: np.ndarray, right: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        """T_world_robot of the frame, the world being the first frame's robot pose."""
        ...


class StereoMotion:
    """Stereo visual odometry from the images."""

    def __init__(self, odometry: StereoOdometry) -> None:
        self.odometry = odometry

    def pose(self, frame_index: int, left: np.ndarray, right: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        self.odometry.step(left, right, boxes)
        return camera_poses_to_robot(self.odometry.pose[None])[0]


class PoseFileMotion:
    """Odometry read from a trajectory file (one pose per image), moved so that it starts at the identity."""

    def __init__(self, trajectory: Trajectory) -> None:
        self.poses = invert_pose(trajectory.poses[0]) @ trajectory.poses

    def pose(self, frame_index: int, left: np.ndarray, right: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        return self.poses[frame_index]


@dataclass(frozen=True, slots=True)
class StereoPair:
    """One rectified stereo pair of a sequence, as read."""

    index: int
    timestamp: float
    left: np.ndarray
    right: np.ndarray


@dataclass(frozen=True, slots=True)
class DetectedPair:
    """A stereo pair with the detections of its left image."""

    pair: StereoPair
    detections: list[Detection]


@dataclass(frozen=True, slots=True)
class PlacedPair:
    """A detected stereo pair with its objects placed in 3-D."""

    detected: DetectedPair
    observations: tuple[ObjectObservation, ...]


@dataclass
class PerceptionTimes:
    """Wall time of each front-end stage, per frame, seconds; and when each frame was handed on."""

    stages: dict[str, list[float]] = field(default_factory=lambda: {stage: [] for stage in STAGES})
    handed: list[float] = field(default_factory=list)  # perf_counter() as each frame left the front end

    def add(self, stage: str, seconds: float) -> None:
        self.stages[stage].append(seconds)

    def summary(self) -> dict[str, float]:
        """Median per stage, median and 95th percentile of their sum, in ms; frames a second with the stages one
        after another (`fps_median`) and as the run went, stages overlapped and the consumer's time between frames
        included (`wall_fps`, from the second frame: the first carries the network's warm-up)."""
        timed = [stage for stage in STAGES if self.stages[stage]]
        if not timed:
            return {}
        # A frame stopped between stages (a stop signal while the next was already detected) has no total.
        complete = min(len(self.stages[s]) for s in timed)
        total = np.sum([self.stages[s][:complete] for s in timed], axis=0)
        figures = {f"{s}_ms_median": round(float(np.median(self.stages[s])) * 1e3, 2) for s in timed}
        figures["total_ms_median"] = round(float(np.median(total)) * 1e3, 2)
        figures["total_ms_p95"] = round(float(np.percentile(total, 95)) * 1e3, 2)
        figures["fps_median"] = round(1.0 / float(np.median(total)), 2)
        if len(self.handed) > 2 and self.handed[-1] > self.handed[1]:
            figures["wall_fps"] = round((len(self.handed) - 2) / (self.handed[-1] - self.handed[1]), 2)
        return figures


class StereoFrontEnd:
    """Detection, ORB stereo triangulation and odometry for one stereo frame at a time."""

    def __init__(
        self,
        triangulator: ObjectTriangulator,
        detector: ObjectDetector,
        motion: MotionSource,
        limits: MotionLimitsConfig | None = None,
    ) -> None:
        """`limits`: a step of the odometry beyond them (a visual odometry that failed) is replaced by the previous
        frame's motion (constant velocity) and counted in `implausible_steps`; None: taken as it is."""
        self.triangulator = triangulator
        self.detector = detector
        self.motion = motion
        self.limits = limits
        self.times = PerceptionTimes()
        self.implausible_steps = 0
        self._previous: tuple[float, np.ndarray, np.ndarray] | None = None  # time, the source's pose, the pose given
        self._step = np.eye(4)  # the previous frame's motion, T_previous_current
        self._correction: np.ndarray | None = None  # from the source's poses to those given, once a step was replaced

    def _timed(self, stage: str, work, *args):
        start = time.perf_counter()
        result = work(*args)
        self.times.add(stage, time.perf_counter() - start)
        return result

    def frame(self, index: int, timestamp: float, left: np.ndarray, right: np.ndarray) -> Frame:
        """The frame of one rectified stereo pair (paper 3.1: objects in the camera frame, robot pose, velocities)."""
        return self.moved(self.triangulated(self.detected(StereoPair(index, timestamp, left, right))))

    def detected(self, pair: StereoPair) -> DetectedPair:
        """Objects detected in the pair's left image."""
        return DetectedPair(pair, self._timed("detection", self.detector.detect, pair.index, pair.left))

    def triangulated(self, detected: DetectedPair) -> PlacedPair:
        """The detected objects placed in 3-D by stereo matching (after `detected`; depends on no other frame)."""
        pair, detections = detected.pair, detected.detections
        observations = self._timed("stereo", self.triangulator.observe, pair.left, pair.right, detections)
        return PlacedPair(detected, tuple(observations))

    def moved(self, placed: PlacedPair) -> Frame:
        """The robot moved by the pair, with the objects placed in 3-D: the frame (after `triangulated`; the
        odometry carries state from frame to frame, so the frames come here in order)."""
        pair, detections = placed.detected.pair, placed.detected.detections
        boxes = np.array([d.box for d in detections], dtype=np.float64).reshape(-1, 4)
        raw = self._timed("odometry", self.motion.pose, pair.index, pair.left, pair.right, boxes)
        pose = raw if self._correction is None else self._correction @ raw
        linear, angular = np.zeros(3), np.zeros(3)
        if self._previous is not None:
            stamp, raw_before, before = self._previous
            stamps = np.array([stamp, pair.timestamp])
            linear, angular = (v[1] for v in body_velocities(np.stack([raw_before, raw]), stamps))
            if self.limits is not None and velocity_problem(linear, angular, self.limits) is not None:
                self.implausible_steps += 1  # the source's own step is beyond the limits: the previous one instead
                pose = before @ self._step
                self._correction = pose @ invert_pose(raw)  # the source's later steps go on from there
                linear, angular = (v[1] for v in body_velocities(np.stack([before, pose]), stamps))
            self._step = invert_pose(before) @ pose
        self._previous = (pair.timestamp, raw, pose)
        return Frame(pair.index, pair.timestamp, pose, linear, angular, placed.observations)


@dataclass
class ImageDataset:
    """A KITTI sequence seen through the front end; `frames()` is all the SLAM path sees."""

    sequence: StereoSequence
    front_end: StereoFrontEnd
    pipeline_depth: int = 0  # frames read and detected ahead in threads (perception.pipeline_depth); 0: none

    @property
    def name(self) -> str:
        return self.sequence.name

    @property
    def ground_truth(self) -> Trajectory | None:
        return self.sequence.ground_truth  # evaluation only

    def __len__(self) -> int:
        return len(self.sequence)

    def _pairs(self) -> Iterator[StereoPair]:
        for index, timestamp in enumerate(self.sequence.timestamps):
            start = time.perf_counter()
            left, right = self.sequence.stereo_pair(index)
            self.front_end.times.add("read", time.perf_counter() - start)
            yield StereoPair(index, float(timestamp), left, right)

    def frames(self) -> Iterator[Frame]:
        """The frames in order; with a pipeline depth, reading, detection and stereo placement run ahead in threads
        of their own."""
        front_end = self.front_end
        handed = front_end.times.handed
        if self.pipeline_depth == 0:
            for pair in self._pairs():
                frame = front_end.moved(front_end.triangulated(front_end.detected(pair)))
                handed.append(time.perf_counter())
                yield frame
            return
        stages = [front_end.detected, front_end.triangulated]
        for placed in staged(self._pairs(), stages, self.pipeline_depth):
            frame = front_end.moved(placed)
            handed.append(time.perf_counter())
            yield frame


def _detections_file(path: Path, config: PerceptionConfig, frames: int) -> DetectionsFile:
    # A frame beyond the sequence is most likely another sequence's: the file refuses it, naming its line.
    return DetectionsFile(path, config.detector.classes, frame_count=frames)


def _pose_file_motion(path: Path, timestamps: np.ndarray, limits: MotionLimitsConfig) -> PoseFileMotion:
    trajectory = read_trajectory(path, "auto")
    if len(trajectory) != len(timestamps):
        raise InputError(path, f"{len(trajectory)} poses for the {len(timestamps)} frames of the sequence")
    # The frames' velocities are the pose steps over the sequence's own time steps: check those.
    check_pose_steps(path, Trajectory(timestamps, trajectory.poses), limits, data_line_numbers(path))
    return PoseFileMotion(trajectory)


def open_front_end(
    sequence: StereoSequence,
    config: PerceptionConfig,
    detections: Path | None = None,
    odometry: Path | Trajectory | None = None,
    limits: MotionLimitsConfig | None = None,
) -> ImageDataset:
    """The front end the config asks for: a YOLO model or a detections file, stereo odometry or poses (a pose
    file, checked against the motion limits, or a Trajectory of one pose per frame such as a bag's odometry
    topic)."""
    if detections is not None or config.detector.source == "file":
        if detections is None:
            raise ConfigError("perception.detector.source is 'file': give the detections with --detections FILE")
        detector: ObjectDetector = _detections_file(detections, config, len(sequence))
    else:
        detector = make_detector(config.detector)
    if odometry is not None or config.odometry.source == "poses":
        if odometry is None:
            raise ConfigError("perception.odometry.source is 'poses': give the pose file with --odometry FILE")
        if isinstance(odometry, Trajectory):
            motion: MotionSource = PoseFileMotion(odometry)
        else:
            stamps = np.asarray(sequence.timestamps, dtype=float)
            motion = _pose_file_motion(odometry, stamps, limits or MotionLimitsConfig())
    else:
        motion = StereoMotion(StereoOdometry(sequence.camera, config.odometry))
    triangulator = ObjectTriangulator(sequence.camera, config.stereo)
    return ImageDataset(sequence, StereoFrontEnd(triangulator, detector, motion, limits), config.pipeline_depth)
