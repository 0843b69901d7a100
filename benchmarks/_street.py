"""Shared by calibrate_sim.py and sim2real.py: the real front end on kitti_06_51, observations moved to the world
with the ground-truth poses (a benchmark may use them; the SLAM path never does), grouped into distinct objects,
and where each object stands along the street."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neoslam.config import CameraConfig, NeoSLAMConfig
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.geometry import camera_points_to_robot
from neoslam.perception.frontend import open_front_end
from neoslam.types import Frame, ObjectObservation, Trajectory

SEQUENCE = "06"
ASSOCIATION_RADIUS = 2.5  # m: observations of one label this close are one object (keyframes.association_radius)
ASSOCIATION_SIGMAS = 3.0  # and within this many depth std (distant observations scatter more)
MIN_REPEATS = 2  # an object is placed in at least this many frames; single placements are false positives
DISTANCE_BANDS = ((0.0, 10.0), (10.0, 20.0), (20.0, 40.0), (40.0, 60.0))  # m, depth bands of the placed-object counts


@dataclass
class RealRun:
    """The real front end's frames of one sequence, the detector's box count per frame, and the truth."""

    frames: list[Frame]
    boxes_per_frame: list[int]
    truth: Trajectory
    camera: CameraConfig


class _CountingDetector:
    """Passes detections through and counts them (boxes before the stereo step places them)."""

    def __init__(self, detector) -> None:
        self.detector = detector
        self.counts: list[int] = []

    def detect(self, *args, **kwargs):
        detections = self.detector.detect(*args, **kwargs)
        self.counts.append(len(detections))
        return detections


def run_real_front_end(root: Path, config: NeoSLAMConfig) -> RealRun:
    """All frames of the real front end (detection, stereo, stereo odometry) on KITTI sequence 06 under root."""
    sequence = read_kitti_sequence(root, SEQUENCE)
    dataset = open_front_end(sequence, config.perception)
    counter = _CountingDetector(dataset.front_end.detector)
    dataset.front_end.detector = counter
    frames = list(dataset.frames())
    if sequence.ground_truth is None:
        raise SystemExit(f"{root}: no poses/{SEQUENCE}.txt: the calibration needs the ground truth")
    return RealRun(frames, counter.counts, sequence.ground_truth, sequence.camera)


def to_world(pose: np.ndarray, centres_camera: np.ndarray) -> np.ndarray:
    """(n, 3) world points of (n, 3) camera-frame points seen from the robot pose T_world_robot."""
    robot = camera_points_to_robot(centres_camera.reshape(-1, 3))
    return robot @ pose[:3, :3].T + pose[:3, 3]


@dataclass
class Cluster:
    """Observations of one object: (frame, world position, depth, depth std, the observation) each."""

    label: str
    frames: list[int] = field(default_factory=list)
    points: list[np.ndarray] = field(default_factory=list)
    depths: list[float] = field(default_factory=list)
    sigmas: list[float] = field(default_factory=list)
    observations: list[ObjectObservation] = field(default_factory=list)

    @property
    def position(self) -> np.ndarray:
        """Inverse-variance weighted mean of the observations."""
        weights = 1.0 / np.square(self.sigmas)
        return (np.array(self.points) * weights[:, None]).sum(axis=0) / weights.sum()


def depth_sigma(depth: float, camera: CameraConfig, disparity_sigma: float = 0.3) -> float:
    """Stereo depth std at a depth for a disparity std (px): z^2 sigma_d / (f b)."""
    return depth**2 * disparity_sigma / (camera.fx * camera.baseline)


def cluster_observations(run: RealRun) -> list[Cluster]:
    """Observations grouped frame by frame: one joins the nearest group of its label within the association radius
    (at most one observation of a group per frame), or starts a new group."""
    clusters: list[Cluster] = []
    for frame in run.frames:
        pose = run.truth.poses[frame.index]
        taken: set[int] = set()
        for obs in frame.observations:
            point = to_world(pose, obs.center_camera)[0]
            depth = float(obs.center_camera[2])
            sigma = obs.depth_sigma if obs.depth_sigma else depth_sigma(depth, run.camera)
            radius = max(ASSOCIATION_RADIUS, ASSOCIATION_SIGMAS * sigma)
            best, best_distance = None, radius
            for k, cluster in enumerate(clusters):
                if k in taken or cluster.label != obs.label:
                    continue
                distance = float(np.linalg.norm(cluster.position - point))
                if distance < best_distance:
                    best, best_distance = k, distance
            if best is None:
                clusters.append(Cluster(obs.label))
                best = len(clusters) - 1
            taken.add(best)
            cluster = clusters[best]
            cluster.frames.append(frame.index)
            cluster.points.append(point)
            cluster.depths.append(depth)
            cluster.sigmas.append(float(sigma))
            cluster.observations.append(obs)
    return clusters


def along_and_lateral(truth: Trajectory, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance along the driven path (extended straight beyond its ends) and signed lateral offset from it (left
    positive) of (n, 3) world points, in the ground plane."""
    path = truth.positions[:, :2]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    along, lateral = np.zeros(len(points)), np.zeros(len(points))
    for i, point in enumerate(points[:, :2]):
        best = np.inf
        for k in range(len(path) - 1):
            segment = path[k + 1] - path[k]
            length = float(np.linalg.norm(segment))
            if length < 1e-9:
                continue
            direction = segment / length
            t = float((point - path[k]) @ direction)
            first, last = k == 0, k == len(path) - 2
            t_clamped = min(max(t, -np.inf if first else 0.0), np.inf if last else length)
            foot = path[k] + t_clamped * direction
            distance = float(np.linalg.norm(point - foot))
            if distance < best:
                offset = point - path[k]
                best = distance
                along[i] = arc[k] + t_clamped
                lateral[i] = direction[0] * offset[1] - direction[1] * offset[0]
    return along, lateral


def band_counts(depths: list[float]) -> list[int]:
    """How many of the depths fall in each of DISTANCE_BANDS."""
    return [sum(low <= d < high for d in depths) for low, high in DISTANCE_BANDS]


def band_name(band: tuple[float, float]) -> str:
    low, high = band
    return f"<{high:g} m" if low == 0 else f"{low:g}-{high:g} m"
