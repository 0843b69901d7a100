"""`neoslam simulate`: a true trajectory in, what the robot would record along it out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from neoslam.config import SimulatorConfig
from neoslam.sim.detections import DetectionSimulator, SimulatedDetection
from neoslam.sim.odometry import noisy_odometry
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.world import World, build_world
from neoslam.types import Trajectory

__all__ = ["SimulatedRecording", "simulate", "simulate_route", "world_for"]


@dataclass(frozen=True)
class SimulatedRecording:
    """Everything a simulation produced; `truth` and `world` (and detections' object ids) are ground truth."""

    name: str
    source: str
    truth: Trajectory
    linear_velocity: np.ndarray  # (n, 3) odometry, body frame
    angular_velocity: np.ndarray  # (n, 3)
    detections: list[list[SimulatedDetection]]
    world: World
    config: SimulatorConfig


def _streams(seed: int) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """The world, odometry and detection random streams of a seed: one independent stream per concern, so that
    changing, say, the detection noise leaves the world unchanged (and a world given whole leaves the others)."""
    world, odometry, detection = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    return world, odometry, detection


def world_for(truth: Trajectory, config: SimulatorConfig) -> World:
    """The world `simulate(truth, config, ...)` would place along `truth` (same seed, same objects)."""
    return build_world(
        truth, config.world, config.detection, config.camera.height_above_ground, _streams(config.seed)[0]
    )


def simulate(
    truth: Trajectory,
    config: SimulatorConfig,
    name: str,
    source: str,
    progress: bool = False,
    route=None,
    world_along: Trajectory | None = None,
    world: World | None = None,
) -> SimulatedRecording:
    """Place a world along `truth` (or along `world_along`: the streets of a drive that goes round them several
    times, see neoslam.sim.passes, so that one pass and many see the same world), or take `world` as it is (one
    built for another drive, e.g. the shared world of several sessions, see neoslam.sim.sessions), then record
    odometry and detections at every pose of `truth`. Deterministic in seed."""
    world_rng, odometry_rng, detection_rng = _streams(config.seed)
    if world is None:
        world = build_world(
            truth if world_along is None else world_along,
            config.world,
            config.detection,
            config.camera.height_above_ground,
            world_rng,
            repeats=route.repeats if route is not None else (),
        )
    linear, angular = noisy_odometry(truth, config.odometry, odometry_rng)
    detector = DetectionSimulator(world, config.camera, config.detection)
    stamps = tqdm(range(len(truth)), desc="simulate", unit="frame", disable=not progress)
    detections = [detector.detect(truth.poses[i], float(truth.timestamps[i]), detection_rng) for i in stamps]
    return SimulatedRecording(name, source, truth, linear, angular, detections, world, config)


def simulate_route(name: str, config: SimulatorConfig, progress: bool = False) -> SimulatedRecording:
    """Simulate one of the built-in routes (see neoslam.sim.routes.ROUTES)."""
    route = ROUTES[name]
    truth = drive_route(route, config.frame_period, config.camera.height_above_ground)
    return simulate(truth, config, name=name, source=f"route:{name}", progress=progress, route=route)
