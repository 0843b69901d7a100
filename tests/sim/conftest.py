"""Recordings shared by the simulator tests: the short built-in route "block", simulated once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.config import SimulatorConfig
from neoslam.datasets.simulated import write_dataset
from neoslam.sim.simulator import SimulatedRecording, simulate_route


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
