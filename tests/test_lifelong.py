"""Lifelong mapping end to end: the block route driven three times in a row ends with the map of one pass, not
three copies of it (objects recognised, keyframes and experiences reused), and is no less accurate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig, SimulatorConfig
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.evaluation.loops import LoopCriteria, judge_closures
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.pipeline import NeoSLAM
from neoslam.sim.passes import join_passes
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate

pytestmark = pytest.mark.slow  # every test here runs whole drives, real images or real bags

CONFIG = NeoSLAMConfig()
PASSES = 3


def _drive(folder: Path, passes: int, config: NeoSLAMConfig) -> dict:
    """Simulate the block route driven `passes` times (the ideal street, vo odometry, one world built along one
    pass) and run NeoSLAM over it; the map's sizes at the end of each pass."""
    sim = SimulatorConfig(detection_profile="ideal", seed=1)
    block = drive_route(ROUTES["block"], sim.frame_period, sim.camera.height_above_ground)
    drive = join_passes(block, passes)
    one = join_passes(block, 1).trajectory
    write_dataset(folder, simulate(drive.trajectory, sim, "block", "block", world_along=one))
    dataset = read_dataset(folder)
    slam = NeoSLAM(config)
    sizes = []
    for frame in dataset.frames():
        slam.step(frame)
        if (frame.index + 1) % drive.frames_per_pass == 0:
            sizes.append((len(slam.loop_detector.index), len(slam.experience_map.experiences), len(slam.hebbian)))
    result = slam.result(np.zeros(len(dataset)))
    truth = dataset.ground_truth
    return {
        "result": result,
        "sizes": sizes,
        "ate": absolute_trajectory_error(result.estimate, truth, "se3").rmse,
        "true_closures": judge_closures(result.loop_closures, truth.positions[:, :2], LoopCriteria()),
    }


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict]:
    root = tmp_path_factory.mktemp("lifelong")
    return {passes: _drive(root / f"x{passes}", passes, CONFIG) for passes in (1, PASSES)}


def test_objects_seen_again_are_recognised(drives: dict[int, dict]) -> None:
    one, many = (len(drives[p]["result"].objects) for p in (1, PASSES))
    assert abs(many - one) <= 0.1 * one, (one, many)


def test_keyframes_experiences_and_memory_stop_growing(drives: dict[int, dict]) -> None:
    sizes = drives[PASSES]["sizes"]
    first, second, third = sizes
    # the second pass adds a few (where the robot entered the known streets before recognising them) ...
    assert all(b - a <= 0.1 * a for a, b in zip(first, second, strict=True)), sizes
    # ... and the third none: keyframes, experiences, Hebbian associations
    assert third == second, sizes
    result = drives[PASSES]["result"]
    assert len(result.keyframe_frames) > 2 * len(result.keyframes)  # keyframes made, most recognised as stored ones


def test_driving_again_is_no_less_accurate(drives: dict[int, dict]) -> None:
    assert drives[PASSES]["ate"] <= drives[1]["ate"] + 0.05
    correct = drives[PASSES]["true_closures"]
    assert len(correct) > 0 and correct.all()


def test_without_reuse_the_map_grows_with_every_pass(tmp_path: Path) -> None:
    """The paper's map (every keyframe stored, an experience each) grows with every pass: what reuse_places stops."""
    config = CONFIG.model_copy(
        update={"experience_map": CONFIG.experience_map.model_copy(update={"reuse_places": False})}
    )
    grown = _drive(tmp_path / "x2", 2, config)["sizes"]
    assert all(b > 1.8 * a for a, b in zip(grown[0][:2], grown[1][:2], strict=True)), grown
