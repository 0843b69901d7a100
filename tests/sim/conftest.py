"""Recordings shared by the simulator tests: the short built-in route "block", simulated once per session, and
the true drive of the route "town"."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.config import SimulatorConfig
from neoslam.datasets.simulated import write_dataset
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import SimulatedRecording, simulate_route
from neoslam.types import Trajectory


@pytest.fixture(scope="session")
def block_recording() -> SimulatedRecording:
    """The route "block" (816 frames) with the ideal detection profile (a rich street), seed 0."""
    return simulate_route("block", SimulatorConfig(detection_profile="ideal"))


@pytest.fixture(scope="session")
def block_folder(block_recording: SimulatedRecording, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """block_recording written as a dataset folder (with its truth/ folder)."""
    folder = tmp_path_factory.mktemp("block") / "dataset"
    write_dataset(folder, block_recording)
    return folder


@pytest.fixture(scope="session")
def town_truth() -> Trajectory:
    """The route "town" driven at the simulator's frame period, the camera at its height above the road."""
    config = SimulatorConfig()
    return drive_route(ROUTES["town"], config.frame_period, config.camera.height_above_ground)
