"""The work behind the CLI: simulation settings, recording, the results folder of a run, evaluation of files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from neoslam.commands.evaluate import evaluate_files
from neoslam.commands.run import run_dataset
from neoslam.commands.simulate import DEFAULT_ROUTE, record, simulate_dataset
from neoslam.config import NOISE_PROFILES, NeoSLAMConfig
from neoslam.config.calibration import DETECTION_PROFILES
from neoslam.config.profiles import simulation_config
from neoslam.datasets.opening import ImageInputs
from neoslam.errors import ConfigError, InputError, OutputError
from neoslam.geometry import transform_points
from neoslam.io.trajectory_files import read_tum, write_tum
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.types import Trajectory

CONFIG = NeoSLAMConfig()
FRAMES = 300


def _route_file(folder: Path, frames: int = FRAMES) -> Path:
    """The first frames of the route "block" as a TUM file (robot poses)."""
    sim = CONFIG.simulator
    truth = drive_route(ROUTES["block"], sim.frame_period, sim.camera.height_above_ground)
    path = folder / "block_cut.txt"
    write_tum(path, truth.subset(np.arange(frames)))
    return path


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("commands")
    settings = simulation_config(CONFIG, "vo", 2)
    simulate_dataset(folder / "dataset", record(settings, trajectory=_route_file(folder)))
    return folder / "dataset"


@pytest.fixture(scope="module")
def results(dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("results") / "out"
    metrics = run_dataset(dataset, out, CONFIG, progress=False)
    return out, metrics


def test_simulation_config_applies_noise_and_seed() -> None:
    settings = simulation_config(CONFIG, "heavy", 7)
    assert settings.simulator.noise_profile == "heavy"
    assert settings.simulator.odometry == NOISE_PROFILES["heavy"]
    assert settings.simulator.seed == 7
    assert settings.simulator.world == CONFIG.simulator.world
    assert settings.grid_cells == CONFIG.grid_cells
    assert simulation_config(CONFIG, None, None) == CONFIG


@pytest.mark.parametrize("detector", ["real", "ideal"])
def test_a_detection_profile_keeps_the_street_values_the_config_set(detector: str) -> None:
    """A config file with traffic (a share of moving objects) and another disparity noise, run with --detector:
    the profile's values replace its own profile's, not what the file set."""
    config = NeoSLAMConfig.model_validate(
        {"simulator": {"world": {"moving_fraction": 0.2}, "detection": {"disparity_sigma": 0.5}}}
    )
    settings = simulation_config(config, "vo", 1, detector).simulator
    profile = DETECTION_PROFILES[detector]
    assert settings.detection_profile == detector
    assert settings.world.moving_fraction == 0.2 and settings.detection.disparity_sigma == 0.5
    assert settings.world.rows == profile.world.rows
    assert settings.detection.detection_probability == profile.detection.detection_probability


def test_unknown_noise_profile() -> None:
    with pytest.raises(ConfigError, match="bogus"):
        simulation_config(CONFIG, "bogus", 1)


def test_unknown_route() -> None:
    with pytest.raises(ConfigError, match="nowhere"):
        record(CONFIG, route="nowhere")


def test_record_a_route_and_a_trajectory_file(tmp_path: Path) -> None:
    path = _route_file(tmp_path, frames=120)
    from_file = record(CONFIG, trajectory=path)
    assert from_file.name == "block_cut" and from_file.source == str(path)
    assert len(from_file.truth) == 120
    np.testing.assert_allclose(from_file.truth.poses, read_tum(path).poses)
    assert DEFAULT_ROUTE in ROUTES


def test_record_a_kitti_file_with_times(tmp_path: Path) -> None:
    poses = tmp_path / "poses.txt"
    poses.write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {0.8 * k}\n" for k in range(40)))  # forward along camera z
    times = tmp_path / "times.txt"
    times.write_text("".join(f"{0.1 * k:.6f}\n" for k in range(40)))
    recording = record(CONFIG, trajectory=poses, fmt="kitti", times=times)
    np.testing.assert_allclose(recording.truth.timestamps, 0.1 * np.arange(40))
    np.testing.assert_allclose(recording.truth.positions[:, 0], 0.8 * np.arange(40), atol=1e-12)
    np.testing.assert_allclose(
        recording.linear_velocity[1:, 0], 8.0 * (1 + NOISE_PROFILES["vo"].speed_scale_bias), atol=1.0
    )


@pytest.mark.slow
def test_results_folder(results: tuple[Path, dict]) -> None:
    out, metrics = results
    names = {p.name for p in out.iterdir()}
    for name in ("trajectory", "odometry", "groundtruth"):
        assert {f"{name}_tum.txt", f"{name}_kitti.txt"} <= names
    assert {"loop_closures.csv", "objects.csv", "config.yaml", "metrics.json", "plots"} <= names
    assert json.loads((out / "metrics.json").read_text()) == metrics
    assert metrics["frames"] == FRAMES
    for name in ("trajectory", "odometry", "groundtruth"):
        assert len(read_tum(out / f"{name}_tum.txt")) == FRAMES
    assert sorted(p.suffix for p in (out / "plots").iterdir()) == [".png"] * len(list((out / "plots").iterdir()))
    assert not [p for p in out.parent.iterdir() if "partial" in p.name]


def test_objects_csv_is_near_the_true_objects(results: tuple[Path, dict], dataset: Path) -> None:
    out, _ = results
    rows = [row.split(",") for row in (out / "objects.csv").read_text().splitlines()]
    assert rows[0] == ["id", "label", "x", "y", "z", "observations", "moving"]
    rows = [rows[0]] + [row for row in rows[1:] if row[-1] == "0"]  # the map's objects (no traffic here)
    assert len(rows) > 10
    assert min(int(row[-2]) for row in rows[1:]) >= CONFIG.object_map.min_observations
    # the map's frame is the first robot pose; move it into the world of truth/objects.csv
    start = read_tum(dataset / "truth" / "poses_tum.txt").poses[0]
    mapped = transform_points(start, np.array([[float(v) for v in row[2:5]] for row in rows[1:]]))
    true_rows = [row.split(",") for row in (dataset / "truth" / "objects.csv").read_text().splitlines()[1:]]
    true_positions = np.array([[float(v) for v in row[2:5]] for row in true_rows])
    nearest = np.linalg.norm(mapped[:, None, :] - true_positions[None], axis=2).min(axis=1)
    assert np.median(nearest) < 2.5


def test_metrics_agree_with_evaluate_files(results: tuple[Path, dict]) -> None:
    out, metrics = results
    for name in ("odometry", "corrected"):
        estimate = out / ("odometry_tum.txt" if name == "odometry" else "trajectory_tum.txt")
        evaluated = evaluate_files(estimate, out / "groundtruth_tum.txt", CONFIG)
        assert evaluated["matched_poses"] == FRAMES
        assert evaluated["ate_rmse_m"] == pytest.approx(metrics["ate_rmse_m"][name], rel=1e-4)
        assert evaluated == {"matched_poses": FRAMES, "alignment": "se3"} | metrics["trajectory"][name]
    with_loops = evaluate_files(
        out / "trajectory_tum.txt", out / "groundtruth_tum.txt", CONFIG, loops_path=out / "loop_closures.csv"
    )
    assert with_loops["loops"]["accepted"] == metrics["loops"]["accepted"]


def test_evaluate_files_that_do_not_match_in_time(tmp_path: Path, results: tuple[Path, dict]) -> None:
    out, _ = results
    truth = read_tum(out / "groundtruth_tum.txt")
    shifted = tmp_path / "shifted.txt"
    write_tum(shifted, Trajectory(truth.timestamps + 1000.0, truth.poses))
    with pytest.raises(InputError) as caught:
        evaluate_files(shifted, out / "groundtruth_tum.txt", CONFIG)
    assert caught.value.path == shifted


def test_run_refuses_a_non_empty_out(results: tuple[Path, dict], dataset: Path) -> None:
    out, _ = results
    before = (out / "metrics.json").read_bytes()
    with pytest.raises(OutputError, match="not empty"):
        run_dataset(dataset, out, CONFIG, progress=False)
    assert (out / "metrics.json").read_bytes() == before


def test_simulate_refuses_a_non_empty_out(dataset: Path) -> None:
    with pytest.raises(OutputError):
        simulate_dataset(dataset, record(CONFIG, trajectory=_route_file(dataset.parent, frames=50)))


def test_a_failed_run_leaves_nothing(tmp_path: Path) -> None:
    (tmp_path / "not_a_dataset").mkdir()
    with pytest.raises(InputError) as caught:
        run_dataset(tmp_path / "not_a_dataset", tmp_path / "out", CONFIG, progress=False)
    assert caught.value.path == tmp_path / "not_a_dataset"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["not_a_dataset"]


def test_kitti_root_needs_a_sequence_and_a_failed_run_leaves_nothing(tmp_path: Path) -> None:
    (tmp_path / "kitti" / "sequences" / "00").mkdir(parents=True)
    with pytest.raises(InputError, match="needs --sequence NN"):
        run_dataset(tmp_path / "kitti", tmp_path / "out", CONFIG, progress=False)
    with pytest.raises(InputError, match="calibration file not found"):
        run_dataset(tmp_path / "kitti", tmp_path / "out", CONFIG, progress=False, inputs=ImageInputs("00"))
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_run_without_truth(dataset: Path, tmp_path: Path) -> None:
    copy = Path(shutil.copytree(dataset, tmp_path / "dataset"))
    shutil.rmtree(copy / "truth")
    metrics = run_dataset(copy, tmp_path / "out", CONFIG, progress=False)
    assert "ate_rmse_m" not in metrics and "trajectory" not in metrics
    assert metrics["loops"] == {"accepted": 0}
    assert not (tmp_path / "out" / "groundtruth_tum.txt").exists()
    assert not (tmp_path / "out" / "groundtruth_kitti.txt").exists()


def test_run_on_a_route_shorter_than_the_rpe_delta(tmp_path: Path) -> None:
    simulate_dataset(tmp_path / "short", record(CONFIG, trajectory=_route_file(tmp_path, frames=60)))
    metrics = run_dataset(tmp_path / "short", tmp_path / "out", CONFIG, progress=False)
    assert metrics["frames"] == 60 and "ate_rmse_m" in metrics


def test_run_on_two_frames(tmp_path: Path) -> None:
    simulate_dataset(tmp_path / "tiny", record(CONFIG, trajectory=_route_file(tmp_path, frames=2)))
    try:
        metrics = run_dataset(tmp_path / "tiny", tmp_path / "out", CONFIG, progress=False)
    except InputError:
        return
    assert metrics["frames"] == 2


@pytest.mark.slow
def test_default_scenario_end_to_end(tmp_path: Path) -> None:
    """`neoslam run` without DATA: the built-in town route, simulated and run (the one full-route test)."""
    out = tmp_path / "out"
    metrics = run_dataset(None, out, CONFIG, progress=False)
    sim = CONFIG.simulator
    frames = len(drive_route(ROUTES[DEFAULT_ROUTE], sim.frame_period, sim.camera.height_above_ground))
    assert metrics["frames"] == frames
    assert (out / "dataset" / "dataset.yaml").is_file()
    assert len(read_tum(out / "trajectory_tum.txt")) == frames
    assert 0.0 < metrics["ate_rmse_m"]["odometry"] < 50.0
    assert {"accepted", "true_positive", "false_positive", "precision", "recall"} <= set(metrics["loops"])
    # What the default scenario is expected to give (measured: 11.0 m of odometry corrected to 1.7 m by 55 closures,
    # all true): closures found, none false, and the corrected trajectory well below the odometry.
    loops = metrics["loops"]
    assert loops["accepted"] >= 20 and loops["false_positive"] == 0 and loops["precision"] == 1.0
    assert metrics["ate_rmse_m"]["corrected"] < min(3.0, 0.3 * metrics["ate_rmse_m"]["odometry"])
    assert not [p for p in tmp_path.iterdir() if "partial" in p.name]


def test_with_backend() -> None:
    from neoslam.commands.run import with_backend

    assert with_backend(CONFIG, None) == CONFIG
    for backend in ("relaxation", "pose-graph"):
        changed = with_backend(CONFIG, backend)
        assert changed.experience_map.backend == backend
        assert changed.experience_map.model_copy(update={"backend": CONFIG.experience_map.backend}) == (
            CONFIG.experience_map
        )
        assert changed.model_copy(update={"experience_map": CONFIG.experience_map}) == CONFIG
    with pytest.raises(ConfigError, match="bogus"):
        with_backend(CONFIG, "bogus")


def test_results_folder_has_the_experience_map(results: tuple[Path, dict]) -> None:
    """experience_map.json of the shared run agrees with the experience_map block of metrics.json."""
    out, metrics = results
    payload = json.loads((out / "experience_map.json").read_text())
    block = metrics["experience_map"]
    assert payload["backend"] == block["backend"] == CONFIG.experience_map.backend
    assert len(payload["experiences"]) == block["experiences"]
    assert len(payload["links"]) == block["links"]
    count = len(payload["experiences"])
    assert all(0 <= k["source"] < count and 0 <= k["target"] < count for k in payload["links"])
    assert sum(k["kind"] == "loop" for k in payload["links"]) == metrics["loops"]["accepted"]
