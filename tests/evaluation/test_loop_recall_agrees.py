"""One definition of loop recall: a run's metrics.json and `neoslam evaluate --loops` on that run's files count it
over the same query frames (those at which the run made or recognised a keyframe, written to keyframe_frames.csv);
recall over every frame is given only when asked for, and named."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from neoslam.commands.run_metrics import run_metrics
from neoslam.config import EvaluationConfig, NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.report import closure_curve
from neoslam.io.results import KEYFRAME_FRAMES, write_keyframe_frames, write_loop_closures, write_trajectories


def _table(printed: str) -> dict[str, str]:
    """A printed table's rows: a name, two spaces or more, a value."""
    return dict(re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in printed.splitlines())


@pytest.fixture
def results(block_seed5: Path, block_seed5_run, tmp_path: Path) -> tuple[Path, dict]:
    """The block drive's run, its files as `neoslam run` writes them, and its metrics."""
    dataset = read_dataset(block_seed5)
    result = block_seed5_run
    write_trajectories(tmp_path, {"trajectory": result.estimate, "groundtruth": dataset.ground_truth})
    write_loop_closures(tmp_path / "loop_closures.csv", result.loop_closures, result.closure_sessions())
    write_keyframe_frames(tmp_path / KEYFRAME_FRAMES, result.keyframe_frames)
    return tmp_path, run_metrics(dataset, result, NeoSLAMConfig(), wall_s=1.0)


def test_evaluate_counts_loop_recall_as_the_run_did_unless_told_every_frame(cli, results) -> None:
    folder, metrics = results
    loops = metrics["loops"]
    assert loops["recall_over"] == "keyframe frames" and loops["accepted"] > 0 and loops["revisit_frames"] > 0
    files = (folder / "trajectory_tum.txt", folder / "groundtruth_tum.txt", "--loops", folder / "loop_closures.csv")
    rows = _table(cli.ok("evaluate", *files).stdout)
    assert rows["loops recall_over"] == "keyframe frames"
    for key in ("precision", "recall", "true_positive", "false_positive", "revisit_frames", "recalled_frames"):
        assert float(rows[f"loops {key}"]) == pytest.approx(loops[key], abs=1e-12), key
    every = _table(cli.ok("evaluate", *files, "--recall-over", "frames").stdout)
    assert every["loops recall_over"] == "every frame"
    assert int(every["loops revisit_frames"]) > loops["revisit_frames"]
    assert float(every["loops recall"]) < loops["recall"]
    cli.one_line_error(cli.invoke("evaluate", *files, "--recall-over", "all"), "--recall-over")


def test_closures_without_the_runs_keyframes_are_counted_over_every_frame_and_say_so(cli, results) -> None:
    folder, _ = results
    (folder / KEYFRAME_FRAMES).unlink()
    files = (folder / "trajectory_tum.txt", folder / "groundtruth_tum.txt", "--loops", folder / "loop_closures.csv")
    json_out = folder / "m.json"
    rows = _table(cli.ok("evaluate", *files, "--json", json_out).stdout)
    assert rows["loops recall_over"] == "every frame"
    assert json.loads(json_out.read_text())["loops"]["recall_over"] == "every frame"


def test_a_keyframe_frame_beyond_the_ground_truth_is_one_line_naming_its_line(cli, results) -> None:
    folder, _ = results
    frames = np.loadtxt(folder / KEYFRAME_FRAMES, skiprows=1, dtype=int)
    bad = folder / "bad.csv"
    bad.write_text("frame\n" + "\n".join(str(f) for f in frames[:3]) + "\n99999\n")
    files = (folder / "trajectory_tum.txt", folder / "groundtruth_tum.txt", "--loops", folder / "loop_closures.csv")
    cli.one_line_error(cli.invoke("evaluate", *files, "--keyframes", bad), f"{bad}:5", "99999")


def test_the_precision_recall_curve_starts_where_the_run_accepted(block_seed5: Path, block_seed5_run) -> None:
    """The curve's lowest threshold accepts every closure the run accepted: its point is metrics.json's precision and
    recall; raising the threshold never recalls more."""
    dataset = read_dataset(block_seed5)
    result = block_seed5_run
    loops = run_metrics(dataset, result, NeoSLAMConfig(), wall_s=1.0)["loops"]
    curve = closure_curve(result.session_closures(), dataset.ground_truth, EvaluationConfig(), result.keyframe_frames)
    assert curve.precision[0] == pytest.approx(loops["precision"]) and curve.recall[0] == pytest.approx(loops["recall"])
    assert np.all(np.diff(curve.recall) <= 0) and np.all(np.diff(curve.thresholds) > 0)
    assert curve.recall[curve.precision == 1.0].max() == pytest.approx(loops["recall_at_full_precision"])
