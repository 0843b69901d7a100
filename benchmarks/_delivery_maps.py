"""The maps deliveries are made on (benchmarks/navigation.py, part `deliveries`): a simulated drive mapped by NeoSLAM,
kept with the world it drove through and its ground truth.

A drive (KITTI 00 or 05 ground truth, or a built-in route such as `town`) is simulated as `neoslam simulate` does
(`neoslam.commands.simulate.record`: the config's odometry noise and detection profile, its seed), written to a
temporary dataset folder and read back as `neoslam run` reads it, and NeoSLAM runs over it; the map is
`slam.map_state()` after the run, as a map file would store it. Everything else here is ground truth, for the
benchmark's judging and for setting deliveries up, never for the SLAM path:

- the map's frame is the odometry's, which starts at the identity at the drive's first frame, so T_world_map is the
  drive's first true pose;
- each experience's true position is the drive's true position at the frame it was made;
- each map object is matched to the world object it stands for: its observations, placed from the true poses of the
  experiences that made them (no map drift), must lie within MATCH_RADIUS_M of a world object of its class (the
  nearest one).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks._street_graph import StreetGraph, street_graph
from benchmarks.harness import require_data
from neoslam.commands.simulate import record
from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.opening import ImageInputs, open_dataset
from neoslam.datasets.simulated import write_dataset
from neoslam.navigation import RoutePlanner
from neoslam.navigation.view import object_positions
from neoslam.pipeline import NeoSLAM
from neoslam.sim.routes import ROUTES
from neoslam.sim.world import World
from neoslam.types import MapState, Trajectory

__all__ = ["MATCH_RADIUS_M", "MOVING_SPEED", "MappedDrive", "map_drive", "map_names"]

KITTI_MAPS = ("00", "05")
MATCH_RADIUS_M = 3.0  # a map object stands for the nearest world object of its class this close to it
MOVING_SPEED = 1.0  # m/s: frames of the drive slower than this do not count for its typical speed


@dataclass(frozen=True)
class MappedDrive:
    """A drive's map and its ground truth (see the module)."""

    name: str
    config: NeoSLAMConfig
    state: MapState
    world: World
    truth: Trajectory
    world_from_map: np.ndarray  # (4, 4) T_world_map
    streets: StreetGraph
    speed: float  # the drive's typical (median) speed, m/s
    frame_period: float  # its median time between frames, s
    experience_truth: np.ndarray  # (n, 3) each experience's true position, world frame
    object_ids: np.ndarray  # (k,) the map objects a goal may name (seen min_observations times, not stale)
    object_labels: np.ndarray  # (k,) their classes
    object_match: np.ndarray  # (k,) the world object each stands for, -1: none within MATCH_RADIUS_M
    mapping_s: float  # wall time of the simulation and the run

    def drawn_on_map(self, point: np.ndarray) -> np.ndarray:
        """A world point where the map draws it, map frame: placed from its nearest experience as that experience
        truly is, then from the experience's pose in the map. A user picks a street spot on the map's plot, among
        the map's streets; through T_world_map alone the point would carry the map's drift there as well."""
        nearest = int(np.argmin(np.linalg.norm(self.experience_truth - np.asarray(point, dtype=float), axis=1)))
        experience = self.state.experiences[nearest]
        local = np.linalg.inv(self.truth.poses[experience.frame_index]) @ np.append(point, 1.0)
        return (np.asarray(self.state.experience_poses[nearest]) @ local)[:3]

    def match_of(self, object_id: int) -> int:
        """The world object a map object stands for (-1: none, or not a goal the map offers)."""
        rows = np.flatnonzero(self.object_ids == object_id)
        return int(self.object_match[rows[0]]) if len(rows) else -1


DELIVERY_TURN_RATE = 10.0  # rad/s, the delivery robot's frames' largest rotation rate with the odometry's noise


def map_names() -> list[str]:
    return [*KITTI_MAPS, *sorted(ROUTES)]


def _config(seed: int, noise: str, detector: str) -> NeoSLAMConfig:
    config = simulation_config(NeoSLAMConfig(), noise, seed, detector)
    # The delivery robot takes a street's bend at a node in one frame (up to SNAP_TURN_RAD: 4.4 rad/s at 10 Hz),
    # beyond the road vehicle's rotation rate the pipeline checks each frame against.
    limits = config.motion_limits.model_copy(update={"max_turn_rate": DELIVERY_TURN_RATE})
    return config.model_copy(update={"motion_limits": limits})


def _recording(name: str, config: NeoSLAMConfig):
    if name in ROUTES:
        return record(config, route=name)
    return record(config, trajectory=require_data("kitti", "poses", f"{name}.txt"))


def map_drive(name: str, seed: int, noise: str = "vo", detector: str = "real") -> MappedDrive:
    """Simulate the drive `name`, run NeoSLAM over it and keep its map with the ground truth."""
    started = time.perf_counter()
    config = _config(seed, noise, detector)
    recording = _recording(name, config)
    with tempfile.TemporaryDirectory(prefix="neoslam-deliveries-") as folder:
        data = Path(folder) / "dataset"
        write_dataset(data, recording)
        dataset = open_dataset(data, config, ImageInputs())
        slam = NeoSLAM(config, session_name=dataset.name)
        times = []
        for frame in dataset.frames():
            step = time.perf_counter()
            slam.step(frame)
            times.append(time.perf_counter() - step)
    slam.result(np.asarray(times))  # finishes the map as a run does before its map is stored
    state = slam.map_state()
    truth = recording.truth
    frames = np.array([e.frame_index for e in state.experiences], dtype=int)
    ids, labels, match = _object_matches(state, config, truth.poses[frames], recording.world)
    steps = np.diff(truth.timestamps)
    speeds = np.linalg.norm(np.diff(truth.positions, axis=0), axis=1) / steps
    return MappedDrive(
        name=name,
        config=config,
        state=state,
        world=recording.world,
        truth=truth,
        world_from_map=truth.poses[0].copy(),
        streets=street_graph(truth.positions),
        speed=float(np.median(speeds[speeds > MOVING_SPEED])),
        frame_period=float(np.median(steps)),
        experience_truth=truth.positions[frames].copy(),
        object_ids=ids,
        object_labels=labels,
        object_match=match,
        mapping_s=time.perf_counter() - started,
    )


def _object_matches(
    state: MapState, config: NeoSLAMConfig, true_poses: np.ndarray, world: World
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The map's goal objects (fresh, seen often enough), their classes and the world object each stands for."""
    objects = RoutePlanner(state, config).objects()
    fresh = ~objects.stale
    ids, labels = objects.ids[fresh], np.asarray(objects.labels[fresh], dtype=str)
    placed = object_positions(state.objects, true_poses)[ids]
    match = np.full(len(ids), -1)
    for label in np.unique(labels):
        mine, theirs = np.flatnonzero(labels == label), np.flatnonzero(world.labels == label)
        if not len(theirs):
            continue
        distance, nearest = cKDTree(world.positions[theirs, :2]).query(placed[mine, :2])
        close = distance <= MATCH_RADIUS_M
        match[mine[close]] = theirs[nearest[close]]
    return ids, labels, match
