"""`neoslam simulate`: a simulated drive along a trajectory file or a built-in route, written as a dataset folder."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from neoslam.config import NeoSLAMConfig, SimulatorConfig
from neoslam.datasets.simulated import write_dataset
from neoslam.errors import ConfigError
from neoslam.io.atomic import atomic_directory
from neoslam.io.motion_limits import check_trajectory_file
from neoslam.io.trajectory_files import read_trajectory
from neoslam.memory import check_budget
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import SimulatedRecording, simulate

__all__ = ["DEFAULT_ROUTE", "record", "simulate_dataset"]

DEFAULT_ROUTE = "town"
PATCH_COPIES = 2  # a simulation's patches are held as they are made, then again as the array written


def record(
    config: NeoSLAMConfig,
    trajectory: Path | None = None,
    fmt: str = "auto",
    times: Path | None = None,
    route: str | None = None,
    progress: bool = False,
) -> SimulatedRecording:
    """Simulate along a trajectory file or a built-in route."""
    sim = config.simulator
    if trajectory is not None:
        truth = read_trajectory(trajectory, fmt, times, frame_period=sim.frame_period)
        check_trajectory_file(trajectory, truth, config.motion_limits, times)
        _check_patch_memory(len(truth), sim)
        return simulate(truth, sim, name=trajectory.stem, source=str(trajectory), progress=progress)
    name = route or DEFAULT_ROUTE
    if name not in ROUTES:
        raise ConfigError(f"unknown route {name!r}; built-in routes: {', '.join(sorted(ROUTES))}")
    truth = drive_route(ROUTES[name], sim.frame_period, sim.camera.height_above_ground)
    _check_patch_memory(len(truth), sim)
    return simulate(truth, sim, name=name, source=f"route:{name}", progress=progress, route=ROUTES[name])


def _check_patch_memory(frames: int, sim: SimulatorConfig) -> None:
    """The appearance patches of the false positives alone (their number a configured mean per frame), twice: held
    as they are made and again as the array written; refused before the simulation when over the budget."""
    detection = sim.detection
    patches = frames * detection.false_positives_per_frame
    check_budget(
        f"simulator.detection: {frames} frames x {detection.false_positives_per_frame:g} false positives a frame x "
        f"{detection.patch_size}x{detection.patch_size} patches",
        PATCH_COPIES * patches * detection.patch_size**2,
    )


def simulate_dataset(
    out: Path, recording: SimulatedRecording, overwrite: bool = False, read: Sequence[Path | None] = ()
) -> None:
    """Write a simulated dataset folder; `read` names the files the simulation read, which it must not replace."""
    with atomic_directory(out, overwrite, read) as staging:
        write_dataset(staging, recording)
