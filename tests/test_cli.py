"""The `neoslam` command end to end: version, dump-config, simulate + run on a cut KITTI 05 trajectory, the results
folder contract of DESIGN.md, evaluate, and one line on stderr with exit code 2 for every bad input."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam import __version__
from neoslam.config import NeoSLAMConfig, load_config

FRAMES = 300
RESULT_FILES = {
    "trajectory_tum.txt",
    "odometry_tum.txt",
    "groundtruth_tum.txt",
    "trajectory_kitti.txt",
    "odometry_kitti.txt",
    "groundtruth_kitti.txt",
    "loop_closures.csv",
    "keyframe_frames.csv",
    "objects.csv",
    "config.yaml",
    "metrics.json",
}
SAME_WITHOUT_TRUTH = ("trajectory_tum.txt", "odometry_tum.txt", "objects.csv", "loop_closures.csv")


def _executable() -> str:
    beside = Path(sys.executable).parent / "neoslam"
    found = str(beside) if beside.is_file() else shutil.which("neoslam")
    assert found, "the neoslam console script is not installed"
    return found


def _evo_ape(reference: Path, estimate: Path) -> float:
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(reference))
    est = file_interface.read_tum_trajectory_file(str(estimate))
    ref, est = sync.associate_trajectories(ref, est)
    est.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))


@pytest.fixture(scope="module")
def workspace(cli, tmp_path_factory: pytest.TempPathFactory, kitti_poses: Callable[[str], Path]) -> Path:
    """The first 300 poses of KITTI 05, simulated with vo noise, run with and without the dataset's truth/."""
    root = tmp_path_factory.mktemp("cli")
    lines = kitti_poses("05").read_text().splitlines(keepends=True)[:FRAMES]
    (root / "kitti05.txt").write_text("".join(lines))
    simulated = cli.ok(
        "simulate",
        "--trajectory",
        root / "kitti05.txt",
        "--format",
        "kitti",
        "--noise",
        "vo",
        "--seed",
        5,
        "--out",
        root / "data",
        "-q",
    )
    (root / "simulate_stdout.txt").write_text(simulated.stdout)
    cli.ok("run", root / "data", "--out", root / "results", "-q")
    shutil.copytree(root / "data", root / "data_no_truth")
    shutil.rmtree(root / "data_no_truth" / "truth")
    cli.ok("run", root / "data_no_truth", "--out", root / "results_no_truth", "-q")
    return root


def test_version_in_a_real_process(cli) -> None:
    done = subprocess.run([_executable(), "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"neoslam {__version__}\n"
    assert cli.ok("--version").stdout == f"neoslam {__version__}\n"


def test_no_arguments_shows_help(cli) -> None:
    result = cli.invoke()
    assert "simulate" in result.output and "run" in result.output and "evaluate" in result.output


def test_dump_config_loads_back(cli, tmp_path: Path) -> None:
    result = cli.ok("dump-config")
    path = tmp_path / "dumped.yaml"
    path.write_text(result.stdout)
    assert load_config(path, environ={}) == load_config(environ={})


def test_dump_config_with_file_and_environment(cli, tmp_path: Path) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text("keyframes:\n  e_max: 2.0\nmatching:\n  min_inliers: 4\n")
    env = {"NEOSLAM_MATCHING__MIN_INLIERS": "6", "NEOSLAM_DATA": "/nowhere"}
    result = cli.ok("dump-config", "--config", path, env=env)
    (tmp_path / "dumped.yaml").write_text(result.stdout)
    dumped = load_config(tmp_path / "dumped.yaml", environ={})
    assert dumped.keyframes.e_max == 2.0
    assert dumped.matching.min_inliers == 6
    assert dumped.grid_cells == NeoSLAMConfig().grid_cells


@pytest.mark.slow
def test_simulate_prints_a_summary(workspace: Path) -> None:
    summary = (workspace / "simulate_stdout.txt").read_text()
    assert summary.startswith(f"wrote {workspace / 'data'}: {FRAMES} frames, ")
    assert "detections" in summary and "objects" in summary and summary.count("\n") == 1
    assert (workspace / "data" / "dataset.yaml").is_file()
    assert "noise_profile: vo" in (workspace / "data" / "dataset.yaml").read_text()
    assert len((workspace / "data" / "frames.csv").read_text().splitlines()) == FRAMES + 1


def test_results_folder_contract(workspace: Path) -> None:
    results = workspace / "results"
    names = {p.name for p in results.iterdir()}
    assert names >= RESULT_FILES
    plots = list((results / "plots").glob("*.png"))
    assert plots and all(p.stat().st_size > 1000 for p in plots)
    for name in RESULT_FILES:
        if name.endswith(".txt"):
            assert len((results / name).read_text().splitlines()) == FRAMES, name
    config = load_config(results / "config.yaml", environ={})
    assert config == NeoSLAMConfig()


def test_metrics_json_keys(workspace: Path) -> None:
    metrics = json.loads((workspace / "results" / "metrics.json").read_text())
    assert metrics["frames"] == FRAMES
    assert set(metrics["ate_rmse_m"]) == {"odometry", "corrected"}
    assert all(isinstance(v, float) and v > 0 for v in metrics["ate_rmse_m"].values())
    loops = metrics["loops"]
    assert {"accepted", "true_positive", "false_positive", "precision", "recall"} <= set(loops)
    assert isinstance(loops["accepted"], int)
    assert loops["accepted"] == loops["true_positive"] + loops["false_positive"]
    assert metrics["timing"]["wall_s"] > 0 and metrics["timing"]["fps"] > 0
    noise = metrics["odometry_noise"]  # the stated floor at least
    assert noise["heading_rad_per_sqrt_s"] >= 0.0032 and noise["distance_m_per_sqrt_s"] >= 0.063


def test_ate_equals_evo(workspace: Path) -> None:
    results = workspace / "results"
    metrics = json.loads((results / "metrics.json").read_text())
    truth = results / "groundtruth_tum.txt"
    odometry = _evo_ape(truth, results / "odometry_tum.txt")
    assert metrics["ate_rmse_m"]["odometry"] == pytest.approx(odometry, rel=1e-4)
    corrected = _evo_ape(truth, results / "trajectory_tum.txt")
    assert metrics["ate_rmse_m"]["corrected"] == pytest.approx(corrected, rel=1e-4)


def test_ground_truth_comes_back_as_the_input_kitti_poses(workspace: Path) -> None:
    """KITTI camera poses in, robot poses inside, camera poses out: the conversion is consistent."""
    given = np.loadtxt(workspace / "kitti05.txt")
    written = np.loadtxt(workspace / "results" / "groundtruth_kitti.txt")
    np.testing.assert_allclose(written, given, atol=1e-6)
    tum = np.loadtxt(workspace / "results" / "groundtruth_tum.txt")
    np.testing.assert_allclose(tum[:, 0], np.arange(FRAMES) * 0.1037, atol=1e-6)
    np.testing.assert_allclose(tum[:, 1], given[:, 11], atol=1e-6)  # robot x = camera z (forward)
    np.testing.assert_allclose(tum[:, 2], -given[:, 3], atol=1e-6)  # robot y = -camera x
    np.testing.assert_allclose(tum[:, 3], -given[:, 7], atol=1e-6)  # robot z = -camera y


def test_run_without_truth_gives_the_same_map(workspace: Path) -> None:
    with_truth, without = workspace / "results", workspace / "results_no_truth"
    for name in SAME_WITHOUT_TRUTH:
        assert (with_truth / name).read_bytes() == (without / name).read_bytes(), name
    metrics = json.loads((without / "metrics.json").read_text())
    assert "ate_rmse_m" not in metrics
    assert metrics["frames"] == FRAMES
    assert metrics["loops"]["accepted"] == json.loads((with_truth / "metrics.json").read_text())["loops"]["accepted"]
    assert not (without / "groundtruth_tum.txt").exists()


@pytest.mark.slow
def test_existing_out_is_refused_unless_overwrite(cli, workspace: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    result = cli.invoke("run", workspace / "data", "--out", out, "-q")
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and str(out) in result.stderr and "--overwrite" in result.stderr
    assert (out / "keep.txt").read_text() == "mine"
    result = cli.invoke("simulate", "--route", "block", "--out", out, "-q")
    assert result.exit_code == 2 and (out / "keep.txt").exists()
    cli.ok("run", workspace / "data", "--out", out, "--overwrite", "-q")
    assert not (out / "keep.txt").exists()
    for name in SAME_WITHOUT_TRUTH:
        assert (out / name).read_bytes() == (workspace / "results" / name).read_bytes(), name


def test_evaluate_prints_the_ate(cli, workspace: Path, tmp_path: Path) -> None:
    results = workspace / "results"
    metrics = json.loads((results / "metrics.json").read_text())
    result = cli.ok(
        "evaluate", results / "odometry_tum.txt", results / "groundtruth_tum.txt", "--json", tmp_path / "m.json"
    )
    rows = dict(line.split(None, 1) for line in result.stdout.splitlines())
    assert float(rows["ate_rmse_m"]) == pytest.approx(metrics["ate_rmse_m"]["odometry"], rel=1e-6)
    assert int(rows["matched_poses"]) == FRAMES
    assert json.loads((tmp_path / "m.json").read_text())["ate_rmse_m"] == float(rows["ate_rmse_m"])
    # the KITTI twins give the same ATE (timestamps from the frame period)
    result = cli.ok("evaluate", results / "odometry_kitti.txt", results / "groundtruth_kitti.txt")
    rows = dict(line.split(None, 1) for line in result.stdout.splitlines())
    assert float(rows["ate_rmse_m"]) == pytest.approx(metrics["ate_rmse_m"]["odometry"], rel=1e-4)
    result = cli.ok(
        "evaluate",
        results / "trajectory_tum.txt",
        results / "groundtruth_tum.txt",
        "--loops",
        results / "loop_closures.csv",
        "--align",
        "sim3",
    )
    assert "loops accepted" in result.stdout and "sim3" in result.stdout


# ---------------------------------------------------------------------------------------------------------------
# Bad input: exit code 2, exactly one line on stderr naming the file and the problem, no traceback.

TUM_OK = "0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 0 1\n0.2 2 0 0 0 0 0 1\n"
BAD_FILES = {
    "nan.txt": "0 0 0 0 0 0 0 1\n0.1 nan 0 0 0 0 0 1\n",
    "columns.txt": "0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 1\n",
    "rotation.txt": "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1.2 1\n",
    "back.txt": "0 0 0 0 0 0 0 1\n0.2 1 0 0 0 0 0 1\n0.1 2 0 0 0 0 0 1\n",
    "ok.txt": TUM_OK,
}
BAD_INPUTS = {
    "missing trajectory": (
        ["simulate", "--trajectory", "{d}/absent.txt", "--out", "{d}/o"],
        ["{d}/absent.txt", "not found"],
    ),
    "trajectory with NaN": (["simulate", "--trajectory", "{d}/nan.txt", "--out", "{d}/o"], ["{d}/nan.txt:2", "finite"]),
    "wrong column count": (
        ["simulate", "--trajectory", "{d}/columns.txt", "--out", "{d}/o"],
        ["{d}/columns.txt:2", "7 columns"],
    ),
    "non-orthonormal KITTI rotation": (
        ["simulate", "--trajectory", "{d}/rotation.txt", "--format", "kitti", "--out", "{d}/o"],
        ["{d}/rotation.txt:2", "orthonormal"],
    ),
    "TUM timestamps going back": (
        ["simulate", "--trajectory", "{d}/back.txt", "--out", "{d}/o"],
        ["{d}/back.txt:3", "goes back"],
    ),
    "unknown noise profile": (
        ["simulate", "--route", "block", "--noise", "bogus", "--out", "{d}/o"],
        ["noise profile", "bogus"],
    ),
    "unknown detection profile": (
        ["simulate", "--route", "block", "--detector", "bogus", "--out", "{d}/o"],
        ["detection profile", "bogus", "real", "ideal"],
    ),
    "unknown route": (["simulate", "--route", "nowhere", "--out", "{d}/o"], ["route", "nowhere"]),
    "unknown trajectory format": (
        ["simulate", "--trajectory", "{d}/ok.txt", "--format", "xyz", "--out", "{d}/o"],
        ["{d}/ok.txt", "format"],
    ),
    "missing dataset folder": (["run", "{d}/absent", "--out", "{d}/o"], ["{d}/absent: ", "not found"]),
    "folder that is not a dataset": (["run", "{d}/empty", "--out", "{d}/o"], ["{d}/empty: ", "neither"]),
    "missing config file": (
        ["run", "{d}/empty", "--config", "{d}/absent.yaml", "--out", "{d}/o"],
        ["{d}/absent.yaml", "not found"],
    ),
    "unknown config key": (["dump-config", "--config", "{d}/unknown.yaml"], ["{d}/unknown.yaml", "bogus_key"]),
    "config that is not YAML": (["dump-config", "--config", "{d}/broken.yaml"], ["{d}/broken.yaml", "YAML"]),
    "evaluate a missing estimate": (["evaluate", "{d}/absent.txt", "{d}/ok.txt"], ["{d}/absent.txt", "not found"]),
    "evaluate a trajectory with NaN": (["evaluate", "{d}/ok.txt", "{d}/nan.txt"], ["{d}/nan.txt:2", "finite"]),
}


@pytest.fixture
def bad_inputs(tmp_path: Path) -> Path:
    for name, text in BAD_FILES.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "empty").mkdir()
    (tmp_path / "unknown.yaml").write_text("matching:\n  bogus_key: 1\n")
    (tmp_path / "broken.yaml").write_text("matching: [\n")
    return tmp_path


def _assert_one_line_error(result, expected: list[str]) -> None:
    assert "Traceback" not in result.output
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), result.exception
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    for part in expected:
        assert part in lines[0], (part, lines[0])


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_is_one_line_and_exit_2(cli, case: str, bad_inputs: Path) -> None:
    args, expected = BAD_INPUTS[case]
    quiet = ["-q"] if args[0] in ("simulate", "run") else []
    result = cli.invoke(*(arg.format(d=bad_inputs) for arg in args), *quiet)
    _assert_one_line_error(result, [part.format(d=bad_inputs) for part in expected])
    assert not (bad_inputs / "o").exists()
    assert not [p for p in bad_inputs.iterdir() if "partial" in p.name]


@pytest.mark.slow
def test_bad_input_in_a_real_process(tmp_path: Path) -> None:
    (tmp_path / "nan.txt").write_text(BAD_FILES["nan.txt"])
    command = [_executable(), "simulate", "--trajectory", str(tmp_path / "nan.txt"), "--out", str(tmp_path / "o")]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, env=os.environ.copy())
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert f"{tmp_path / 'nan.txt'}:2" in done.stderr and "finite" in done.stderr
    assert not (tmp_path / "o").exists()


XFAIL_CASES = {
    "single pose": (
        "sim/world.py _centre_line calls np.gradient on the densified centre line: a trajectory of one pose "
        "makes `neoslam simulate` exit 1 with a numpy ValueError traceback",
        "0 0 0 0 0 0 0 1\n",
    ),
    "standing still": (
        "sim/world.py _centre_line: a trajectory that never moves (path length 0) gives an empty centre line and "
        "np.gradient raises; `neoslam simulate` exits 1 with a traceback",
        "0 5 5 0 0 0 0 1\n0.1 5 5 0 0 0 0 1\n0.2 5 5 0 0 0 0 1\n0.3 5 5 0 0 0 0 1\n",
    ),
}


@pytest.mark.parametrize(
    "case",
    [pytest.param(name) for name, (reason, _) in XFAIL_CASES.items()],
)
def test_degenerate_trajectory_is_a_clean_error(cli, case: str, tmp_path: Path) -> None:
    (tmp_path / "poses.txt").write_text(XFAIL_CASES[case][1])
    result = cli.invoke("simulate", "--trajectory", tmp_path / "poses.txt", "--out", tmp_path / "o", "-q")
    if result.exit_code == 0:  # a clean success is fine too
        return
    _assert_one_line_error(result, ["poses.txt"])


def test_bad_environment_value_is_one_line(cli) -> None:
    result = cli.invoke("dump-config", env={"NEOSLAM_MATCHING__MIN_INLIERS": "["})
    _assert_one_line_error(result, ["NEOSLAM_MATCHING__MIN_INLIERS"])


def test_both_trajectory_and_route_is_refused(cli, bad_inputs: Path) -> None:
    result = cli.invoke(
        "simulate", "--trajectory", bad_inputs / "ok.txt", "--route", "block", "--out", bad_inputs / "o"
    )
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert "either --trajectory or --route" in result.output
    assert not (bad_inputs / "o").exists()


def test_evaluate_a_short_trajectory(cli, tmp_path: Path) -> None:
    path = tmp_path / "short.txt"
    path.write_text("".join(f"{0.1 * k:.1f} {k} 0 0 0 0 0 1\n" for k in range(50)))  # 49 m
    result = cli.invoke("evaluate", path, path)
    assert result.exit_code in (0, 2), result.exception
    assert "Traceback" not in result.output


# ---------------------------------------------------------------------------------------------------------------
# The experience map of a run (paper 3.6): experience_map.json against metrics.json, and the two back ends.

BLOCK_FRAMES = 600  # the block route up to its first revisit of the start: a few loop closures


@pytest.fixture(scope="module")
def block_runs(cli, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The simulated block route (vo noise, the ideal detection profile: a rich street that closes loops), run with
    `--backend relaxation` and with `--backend pose-graph`."""
    from neoslam.io.trajectory_files import write_tum
    from neoslam.sim.routes import ROUTES, drive_route

    root = tmp_path_factory.mktemp("backends")
    sim = NeoSLAMConfig().simulator
    truth = drive_route(ROUTES["block"], sim.frame_period, sim.camera.height_above_ground)
    write_tum(root / "block.txt", truth.subset(np.arange(BLOCK_FRAMES)))
    simulate = ["simulate", "--trajectory", root / "block.txt", "--noise", "vo", "--detector", "ideal", "--seed", 2]
    cli.ok(*simulate, "--out", root / "data", "-q")
    outs = {}
    for backend in ("relaxation", "pose-graph"):
        outs[backend] = root / backend
        cli.ok("run", root / "data", "--backend", backend, "--out", outs[backend], "-q")
    return outs


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["relaxation", "pose-graph"])
def test_run_records_its_backend(block_runs: dict[str, Path], backend: str) -> None:
    out = block_runs[backend]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["experience_map"]["backend"] == backend
    assert json.loads((out / "experience_map.json").read_text())["backend"] == backend
    assert load_config(out / "config.yaml", environ={}).experience_map.backend == backend
    assert metrics["frames"] == BLOCK_FRAMES
    assert metrics["loops"]["accepted"] > 0
    assert metrics["ate_rmse_m"]["corrected"] < metrics["ate_rmse_m"]["odometry"]


@pytest.mark.parametrize("backend", ["relaxation", "pose-graph"])
def test_experience_map_json_agrees_with_metrics(block_runs: dict[str, Path], backend: str) -> None:
    out = block_runs[backend]
    metrics = json.loads((out / "metrics.json").read_text())
    block = metrics["experience_map"]
    payload = json.loads((out / "experience_map.json").read_text())
    experiences, links = payload["experiences"], payload["links"]

    assert set(block) == {"backend", "experiences", "links", "links_withdrawn", "closures_rejected_by_grid_cells"}
    assert block["links_withdrawn"] == sum(link["withdrawn"] for link in links)
    assert len(experiences) == block["experiences"] > 1
    assert len(links) == block["links"]
    assert isinstance(block["closures_rejected_by_grid_cells"], int) and block["closures_rejected_by_grid_cells"] >= 0
    assert {"loops", "cells", "experience_map"} <= set(metrics)
    assert {"grid_cells_vs_odometry_rms_m", "head_direction_vs_odometry_rms_deg"} <= set(metrics["cells"])

    ids = [e["id"] for e in experiences]
    assert ids == list(range(len(experiences)))
    frames = [e["frame"] for e in experiences]
    assert frames[0] == 0 and frames == sorted(set(frames)) and frames[-1] < BLOCK_FRAMES
    keyframes = [e["keyframe"] for e in experiences if e["keyframe"] is not None]
    assert len(keyframes) == len(set(keyframes)) == metrics["keyframes"]
    for link in links:
        assert 0 <= link["source"] < len(experiences) and 0 <= link["target"] < len(experiences), link
        assert link["kind"] in ("odometry", "loop")
    odometry_links = [(k["source"], k["target"]) for k in links if k["kind"] == "odometry"]
    assert odometry_links == [(i, i + 1) for i in range(len(experiences) - 1)]  # each experience to the previous
    loop_links = [k for k in links if k["kind"] == "loop"]
    assert 0 < len(loop_links) <= metrics["loops"]["accepted"]  # a closure between linked experiences adds none
    assert all(k["distance_m"] == 0.0 for k in loop_links)
    assert all(k["distance_m"] > 0.0 for k in links if k["kind"] == "odometry")


@pytest.mark.parametrize("backend", ["relaxation", "pose-graph"])
def test_loop_links_are_the_accepted_closures(block_runs: dict[str, Path], backend: str) -> None:
    """Each loop link joins the experiences of a closure's stored and query keyframes (loop_closures.csv); a
    closure that recognised its keyframe as the stored one (lifelong mapping: the keyframe is not stored, the robot
    re-enters the stored keyframe's experience) links the experience the robot came from to the stored one, if the
    two were not linked yet."""
    from neoslam.io.results import read_loop_closures

    out = block_runs[backend]
    payload = json.loads((out / "experience_map.json").read_text())
    keyframe_of = {e["id"]: e["keyframe"] for e in payload["experiences"]}
    linked = sorted(
        (keyframe_of[k["source"]], keyframe_of[k["target"]]) for k in payload["links"] if k["kind"] == "loop"
    )
    closures = read_loop_closures(out / "loop_closures.csv")
    stored = set(keyframe_of.values())
    own = sorted((c.match_keyframe, c.query_keyframe) for c in closures if c.query_keyframe in stored)
    assert [pair for pair in linked if pair in own] == own
    recognised = {c.match_keyframe for c in closures if c.query_keyframe not in stored}
    others = [pair for pair in linked if pair not in own]
    assert all(target in recognised for _, target in others) and len(others) <= len(recognised)


@pytest.mark.parametrize("backend", ["relaxation", "pose-graph"])
def test_experience_poses_are_the_trajectory_at_their_frames(block_runs: dict[str, Path], backend: str) -> None:
    """An experience's corrected pose is the written trajectory at its frame; its odometry pose the odometry's."""
    out = block_runs[backend]
    experiences = json.loads((out / "experience_map.json").read_text())["experiences"]
    frames = [e["frame"] for e in experiences]
    trajectory = np.loadtxt(out / "trajectory_tum.txt")
    odometry = np.loadtxt(out / "odometry_tum.txt")
    corrected = np.array([[e["pose"][k] for k in ("x", "y", "z")] for e in experiences])
    dead_reckoned = np.array([[e["odometry_pose"][k] for k in ("x", "y", "z")] for e in experiences])
    np.testing.assert_allclose(corrected, trajectory[frames, 1:4], atol=2e-6)
    np.testing.assert_allclose(dead_reckoned, odometry[frames, 1:4], atol=2e-6)
    assert np.abs(corrected - dead_reckoned).max() > 0.1  # the map was corrected


def test_the_two_backends_correct_the_same_map_differently(block_runs: dict[str, Path]) -> None:
    """The back end changes the correction only: same experiences and links, different corrected poses."""
    relaxed, optimised = (json.loads((block_runs[b] / "experience_map.json").read_text()) for b in block_runs)

    def structure(payload: dict) -> tuple:
        return (
            [(e["id"], e["frame"], e["keyframe"]) for e in payload["experiences"]],
            [(k["source"], k["target"], k["kind"]) for k in payload["links"]],
        )

    assert structure(relaxed) == structure(optimised)
    assert [e["pose"] for e in relaxed["experiences"]] != [e["pose"] for e in optimised["experiences"]]


@pytest.mark.parametrize("backend", ["relaxation", "pose-graph"])
def test_closure_plots_exist_when_closures_exist(block_runs: dict[str, Path], backend: str) -> None:
    out = block_runs[backend]
    assert json.loads((out / "metrics.json").read_text())["loops"]["accepted"] > 0
    for name in ("keyframe_labels.png", "matching_scores.png"):
        assert (out / "plots" / name).stat().st_size > 1000, name


def test_unknown_backend_is_one_line_and_exit_2(cli, tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    result = cli.invoke("run", tmp_path / "empty", "--backend", "gtsam2", "--out", tmp_path / "o", "-q")
    _assert_one_line_error(result, ["backend", "gtsam2", "relaxation", "pose-graph"])
    assert not (tmp_path / "o").exists()
    assert not [p for p in tmp_path.iterdir() if "partial" in p.name]


# --- KITTI image sequences through the perception front end ---


@pytest.fixture(scope="module")
def image_run(cli, tmp_path_factory: pytest.TempPathFactory, shared_data: Path) -> Path:
    out = tmp_path_factory.mktemp("images") / "mini"
    model = shared_data / "models" / "yolox_nano_coco" / "yolox_nano.onnx"
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(model)}
    cli.ok("run", shared_data / "kitti_mini", "--sequence", "06", "--out", out, "-q", env=env)
    return out


@pytest.mark.slow
def test_a_run_on_real_images_draws_what_the_detector_saw_at_its_keyframes(cli, shared_data: Path, tmp_path) -> None:
    """60 m of KITTI 06: the strip has a tile for each keyframe frame (up to 8), two a row, boxes drawn on them; the
    video asked for has every frame, at the camera's rate (KITTI's 0.1037 s)."""
    out = tmp_path / "r06"
    model = shared_data / "models" / "yolox_nano_coco" / "yolox_nano.onnx"
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(model)}
    cli.ok("run", shared_data / "kitti_06_51", "--sequence", "06", "--out", out, "-q", "--detections-video", env=env)
    video = cv2.VideoCapture(str(out / "plots" / "detections.avi"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 51 and 9.0 <= video.get(cv2.CAP_PROP_FPS) <= 10.0
    keyframes = np.unique(np.loadtxt(out / "keyframe_frames.csv", skiprows=1, ndmin=1))
    strip = cv2.imread(str(out / "plots" / "detections.png"))
    assert len(keyframes) >= 2 and strip is not None
    tiles = min(len(keyframes), 8)
    rows = (tiles + 1) // 2
    assert strip.shape[1] == 2 * 620 and strip.shape[0] % rows == 0
    assert 180 <= strip.shape[0] // rows <= 195  # KITTI's 1226 x 370 images, 620 wide
    grey = (strip[..., 0] == strip[..., 1]) & (strip[..., 1] == strip[..., 2])
    assert (~grey).mean() > 0.001  # coloured boxes and labels on the grey images


@pytest.mark.slow
def test_run_on_kitti_images_writes_the_results_folder(image_run: Path) -> None:
    assert {p.name for p in image_run.iterdir()} >= RESULT_FILES
    objects = (image_run / "objects.csv").read_text().splitlines()
    assert objects[0].startswith("id,label,x,y,z") and any(",car," in line for line in objects[1:])
    metrics = json.loads((image_run / "metrics.json").read_text())
    assert metrics["frames"] == 12 and metrics["dataset"] == "kitti-06"
    assert metrics["perception"]["fps_median"] > 0
    # Stereo odometry over 13 m of real images: the odometry ATE is small.
    assert metrics["ate_rmse_m"]["odometry"] < 0.5
    assert len((image_run / "trajectory_tum.txt").read_text().splitlines()) == 12
    keyframes = np.loadtxt(image_run / "keyframe_frames.csv", skiprows=1, ndmin=1)
    strip = cv2.imread(str(image_run / "plots" / "detections.png"))  # what the detector saw at the keyframes
    assert (strip is not None and strip.shape[1] == 2 * 620) if len(keyframes) else strip is None


def test_run_on_kitti_images_with_detections_and_odometry_files(
    cli, image_run: Path, shared_data: Path, tmp_path: Path
) -> None:
    detections = tmp_path / "detections.jsonl"
    box = [712.0, 170.0, 842.0, 252.0]
    lines = [json.dumps({"frame": i, "detections": [{"label": "car", "score": 0.9, "box": box}]}) for i in range(3)]
    detections.write_text("\n".join(lines) + "\n")
    odometry = image_run / "groundtruth_kitti.txt"
    out = tmp_path / "files"
    root = shared_data / "kitti_mini"
    cli.ok("run", root, "--sequence", "06", "--detections", detections, "--odometry", odometry, "--out", out, "-q")
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ate_rmse_m"]["odometry"] < 1e-3  # the ground truth given as odometry comes back


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--out", "{o}"], ["kitti_mini", "needs --sequence NN", "sequences here: 06"]),
        (["--sequence", "07", "--out", "{o}"], ["sequences/07", "sequence not found"]),
        (["--sequence", "06", "--detections", "{t}/missing.jsonl", "--out", "{o}"], ["missing.jsonl", "not found"]),
        (["--sequence", "06", "--odometry", "{t}/missing.txt", "--out", "{o}"], ["missing.txt", "not found"]),
    ],
)
def test_bad_image_inputs_are_one_line(
    cli, args: list[str], expected: list[str], shared_data: Path, tmp_path: Path
) -> None:
    out = tmp_path / "o"
    fill = {"o": out, "t": tmp_path}
    result = cli.invoke("run", shared_data / "kitti_mini", *(a.format(**fill) for a in args), "-q")
    _assert_one_line_error(result, [e.format(**fill) for e in expected])
    assert not out.exists()


def test_missing_detector_model_is_one_line(cli, shared_data: Path, tmp_path: Path) -> None:
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(tmp_path / "nowhere.onnx")}
    result = cli.invoke("run", shared_data / "kitti_mini", "--sequence", "06", "--out", tmp_path / "o", "-q", env=env)
    _assert_one_line_error(result, ["nowhere.onnx", "YOLOX-ONNX-TFLite-Sample"])


def test_a_model_path_of_megabytes_is_cut_in_the_one_line(cli, shared_data: Path, tmp_path: Path) -> None:
    """A value given at any length (here a 10 MB model path in a config file) is cut in the middle of the line."""
    config = tmp_path / "long.yaml"
    config.write_text(f"perception:\n  detector:\n    model: {'x' * 10_000_000}.onnx\n")
    result = cli.invoke(
        "run", shared_data / "kitti_mini", "--sequence", "06", "--config", config, "--out", tmp_path / "o"
    )
    _assert_one_line_error(result, ["characters cut", ".onnx"])
    assert len(result.stderr) < 1100


def test_image_options_need_image_inputs(cli, workspace: Path, tmp_path: Path) -> None:
    result = cli.invoke("run", workspace / "data", "--sequence", "06", "--out", tmp_path / "o", "-q")
    _assert_one_line_error(result, ["--sequence", "apply to image inputs, not a simulated dataset"])


# --- neoslam detect ---


@pytest.mark.slow
def test_detect_writes_what_run_reads(cli, shared_data: Path, tmp_path: Path) -> None:
    """`neoslam detect` runs the detector once; `run --detections` on its file maps what a run with the detector
    maps (same detections, so the same objects)."""
    root = shared_data / "kitti_mini"
    dets = tmp_path / "dets.jsonl"
    result = cli.ok("detect", root, "--sequence", "06", "--out", dets, "-q")
    assert f"wrote {dets}" in result.stdout
    lines = [json.loads(line) for line in dets.read_text().splitlines()]
    assert [line["frame"] for line in lines] == list(range(12))
    assert sum(len(line["detections"]) for line in lines) >= 12
    cli.ok("run", root, "--sequence", "06", "--out", tmp_path / "with_file", "--detections", dets, "-q")
    cli.ok("run", root, "--sequence", "06", "--out", tmp_path / "with_detector", "-q")
    objects = [(tmp_path / name / "objects.csv").read_text() for name in ("with_file", "with_detector")]
    assert objects[0] == objects[1]


def test_detect_refuses_an_existing_file_and_bad_roots(cli, shared_data: Path, tmp_path: Path) -> None:
    existing = tmp_path / "mine.jsonl"
    existing.write_text("keep me\n")
    result = cli.invoke("detect", shared_data / "kitti_mini", "--sequence", "06", "--out", existing, "-q")
    _assert_one_line_error(result, ["mine.jsonl", "exists", "--overwrite"])
    assert existing.read_text() == "keep me\n"
    result = cli.invoke("detect", shared_data / "kitti_mini", "--out", tmp_path / "d.jsonl", "-q")
    _assert_one_line_error(result, ["--sequence", "sequences here: 06"])
    not_kitti = tmp_path / "not-kitti"
    not_kitti.mkdir()
    result = cli.invoke("detect", not_kitti, "--sequence", "06", "--out", tmp_path / "d.jsonl", "-q")
    _assert_one_line_error(result, [str(not_kitti), "not a KITTI odometry root"])
    assert not (tmp_path / "d.jsonl").exists() and not [p for p in tmp_path.iterdir() if "partial" in p.name]
