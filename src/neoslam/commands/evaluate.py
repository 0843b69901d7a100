"""`neoslam evaluate`: an estimate file against a ground-truth file (ATE, RPE, drift; loop closures if given)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.errors import ConfigError, InputError
from neoslam.evaluation.report import loop_metrics, trajectory_metrics
from neoslam.evaluation.trajectory_metrics import associate
from neoslam.geometry import is_single_place
from neoslam.inputs import count_lines
from neoslam.io.atomic import atomic_file, check_target_file
from neoslam.io.results import KEYFRAME_FRAMES, read_keyframe_frames, read_loop_closures, write_metrics
from neoslam.io.trajectory_files import read_trajectory
from neoslam.memory import check_budget

__all__ = ["evaluate_files"]

MIN_ALIGNMENT_POSES = 3  # a sim3 alignment needs three points
# Peak memory of reading and evaluating two trajectories, per line of the two files: measured 231 bytes (TUM) and
# 325 (KITTI) on files of a million lines each (`python -m benchmarks.evaluation`).
BYTES_PER_LINE = 352
RecallOver = Literal["keyframes", "frames"]
RECALL_CHOICES = ("keyframes", "frames")


def evaluate_files(
    estimate_path: Path,
    truth_path: Path,
    config: NeoSLAMConfig,
    estimate_format: str = "auto",
    truth_format: str = "auto",
    loops_path: Path | None = None,
    json_out: Path | None = None,
    read: Sequence[Path | None] = (),
    overwrite: bool = False,
    keyframes_path: Path | None = None,
    recall_over: RecallOver = "keyframes",
) -> dict[str, Any]:
    """Metrics of an estimate file against a ground-truth file (timestamps associated first), also written to
    `json_out` if named (never over one of the files read; over an existing file only with `overwrite`).

    Loop recall is counted as metrics.json counts it, over the frames at which the run made a keyframe: those of
    `keyframes_path`, by default keyframe_frames.csv beside the closures; where there is none (closures of another
    tool), or with `recall_over` "frames", over every frame. The loops block's `recall_over` says which."""
    if recall_over not in RECALL_CHOICES:
        raise ConfigError(f"--recall-over must be {' or '.join(RECALL_CHOICES)}, not {recall_over!r}")
    inputs = [estimate_path, truth_path, loops_path, keyframes_path, *read]
    if json_out is not None:
        check_target_file(json_out, overwrite, inputs)
    _check_memory(estimate_path, truth_path)
    estimate = read_trajectory(estimate_path, estimate_format)
    truth = read_trajectory(truth_path, truth_format)
    try:
        matched_estimate, matched_truth = associate(estimate, truth, config.evaluation.max_time_difference)
    except ValueError as error:
        raise InputError(estimate_path, f"cannot be matched with {truth_path.name}: {error}") from None
    alignment = config.evaluation.alignment
    for path, matched in ((truth_path, matched_truth), (estimate_path, matched_estimate)):
        if alignment == "sim3" and len(matched) >= MIN_ALIGNMENT_POSES and is_single_place(matched.positions):
            # As evo: a scale fitted to a trajectory that never moves is 0 or undefined, and the ATE meaningless.
            problem = f"the {len(matched)} matched poses are all at one place: a sim3 alignment has no scale"
            raise InputError(path, f"{problem} (use --align se3 or none)")
    metrics: dict[str, Any] = {"matched_poses": len(matched_estimate), "alignment": alignment}
    metrics |= trajectory_metrics(matched_estimate, matched_truth, config.evaluation)
    if loops_path is not None:
        closures = read_loop_closures(loops_path, frames=len(truth))
        query_frames = _query_frames(loops_path, keyframes_path, recall_over, len(truth))
        metrics["loops"] = loop_metrics(closures, truth, config.evaluation, query_frames)
    if json_out is not None:
        with atomic_file(json_out, overwrite, inputs) as staging:
            write_metrics(staging, metrics)
    return metrics


def _check_memory(*paths: Path) -> None:
    """Refuse, before reading them, trajectories whose evaluation would exceed the memory budget."""
    lines = sum(count_lines(path) for path in paths)
    names = " and ".join(path.name for path in paths)
    check_budget(f"evaluate: {names} ({lines:,} lines)", lines * BYTES_PER_LINE)


def _query_frames(loops: Path, keyframes: Path | None, recall_over: str, frames: int) -> np.ndarray | None:
    """The frames loop recall is counted over: the run's keyframe frames, or None for every frame."""
    if recall_over == "frames":
        return None
    if keyframes is None:
        beside = loops.parent / KEYFRAME_FRAMES
        if not beside.is_file():
            return None  # closures without the run's keyframes: every frame, as the loops block says
        keyframes = beside
    return read_keyframe_frames(keyframes, frames=frames)
