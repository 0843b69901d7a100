"""`neoslam evaluate`: an estimate file against a ground-truth file (ATE, RPE, drift; loop closures if given)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError
from neoslam.evaluation.report import loop_metrics, trajectory_metrics
from neoslam.evaluation.trajectory_metrics import associate
from neoslam.geometry import is_single_place
from neoslam.io.atomic import atomic_file, check_target_file
from neoslam.io.results import read_loop_closures, write_metrics
from neoslam.io.trajectory_files import read_trajectory

__all__ = ["evaluate_files"]

MIN_ALIGNMENT_POSES = 3  # a sim3 alignment needs three points


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
) -> dict[str, Any]:
    """Metrics of an estimate file against a ground-truth file (timestamps associated first), also written to
    `json_out` if named (never over one of the files read; over an existing file only with `overwrite`)."""
    inputs = [estimate_path, truth_path, loops_path, *read]
    if json_out is not None:
        check_target_file(json_out, overwrite, inputs)
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
        metrics["loops"] = loop_metrics(closures, truth, config.evaluation)
    if json_out is not None:
        with atomic_file(json_out, overwrite, inputs) as staging:
            write_metrics(staging, metrics)
    return metrics
