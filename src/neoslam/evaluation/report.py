"""The metrics of a run against ground truth, as the JSON-ready blocks of metrics.json."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from neoslam.config import EvaluationConfig
from neoslam.evaluation.loops import (
    LoopCriteria,
    PrecisionRecall,
    evaluate_closures,
    judge_closures,
    precision_recall_curve,
)
from neoslam.evaluation.trajectory_metrics import (
    KITTI_SEGMENT_LENGTHS_M,
    ErrorStats,
    absolute_trajectory_error,
    kitti_drift,
    relative_pose_error,
)
from neoslam.geometry import yaw_of
from neoslam.types import LoopClosure, Trajectory

__all__ = ["trajectory_metrics", "loop_metrics", "cell_metrics", "timing_metrics"]


def _finite(value: float) -> float | None:
    # None for NaN and for inf alike: neither is JSON, and neither is a figure the data supports.
    return round(float(value), 6) if math.isfinite(value) else None


def trajectory_metrics(estimate: Trajectory, truth: Trajectory, config: EvaluationConfig) -> dict[str, Any]:
    """ATE (aligned as configured), RPE and KITTI drift of one estimate whose poses match truth frame by frame.

    A metric the data cannot support (alignment of fewer than 3 poses, a route shorter than the RPE delta, or than
    KITTI's shortest segment) is None rather than an error: a short run is not a user's mistake.
    """
    nan_stats = ErrorStats.from_errors(np.empty(0))
    # Absurd but finite coordinates (1e300) overflow to inf on the way: such a figure is None, without warnings.
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            ate = absolute_trajectory_error(estimate, truth, align=config.alignment)
        except (ValueError, np.linalg.LinAlgError):
            ate = nan_stats
        try:
            rpe_translation, rpe_rotation = _rpe(estimate, truth, config)
        except ValueError:
            rpe_translation = rpe_rotation = nan_stats
        drift = kitti_drift(estimate, truth)
    metrics: dict[str, Any] = {
        "ate_rmse_m": _finite(ate.rmse),
        "ate_max_m": _finite(ate.max),
        "rpe_translation_rmse_m": _finite(rpe_translation.rmse),
        "rpe_rotation_rmse_deg": _finite(rpe_rotation.rmse),
        "kitti_translation_percent": _finite(drift.translation_percent),
        "kitti_rotation_deg_per_100m": _finite(drift.rotation_deg_per_100m),
    }
    absent = _absent(metrics, truth, config)
    return metrics | ({"absent": absent} if absent else {})


def _absent(metrics: dict[str, Any], truth: Trajectory, config: EvaluationConfig) -> dict[str, str]:
    """Why each figure that is None is absent, in words (a short drive has no RPE at a 100 m step)."""
    steps = np.linalg.norm(np.diff(truth.positions, axis=0), axis=1) if len(truth) > 1 else np.zeros(0)
    route_m = float(steps.sum()) if np.isfinite(steps).all() else float("nan")
    route = f"the route ({route_m:.1f} m, {len(truth)} poses)"
    why = {}
    if metrics["ate_rmse_m"] is None:
        why["ate"] = f"{route} cannot be aligned ({config.alignment} needs 3 poses or more, not all on one point)"
    if metrics["rpe_translation_rmse_m"] is None:
        why["rpe"] = f"{route} has no pose pairs evaluation.rpe_delta = {config.rpe_delta:g} {config.rpe_unit} apart"
    if metrics["kitti_translation_percent"] is None:
        shortest = min(KITTI_SEGMENT_LENGTHS_M)
        why["kitti_drift"] = f"{route} is shorter than KITTI's shortest segment ({shortest:g} m)"
    return why


def _rpe(estimate: Trajectory, truth: Trajectory, config: EvaluationConfig) -> tuple[ErrorStats, ErrorStats]:
    rpe = relative_pose_error(estimate, truth, delta=config.rpe_delta, unit=config.rpe_unit)
    return rpe.translation, rpe.rotation


RECALL_OVER_KEYFRAMES = "keyframe frames"  # revisits at which the run made or recognised a keyframe
RECALL_OVER_FRAMES = "every frame"  # every revisit frame: lower, as most frames make no keyframe


def loop_metrics(
    closures: list[LoopClosure],
    truth: Trajectory | None,
    config: EvaluationConfig,
    query_frames: np.ndarray | None = None,
) -> dict[str, Any]:
    """The loops block: counts always, precision and recall only when ground truth exists. Recall is over
    `query_frames` (the keyframes' frames: only they can close a loop), or every frame; `recall_over` says which."""
    block: dict[str, Any] = {"accepted": len(closures)}
    if truth is None:
        return block
    criteria, positions = _loop_criteria(truth, config)
    over = RECALL_OVER_FRAMES if query_frames is None else RECALL_OVER_KEYFRAMES
    return block | evaluate_closures(closures, positions, criteria, query_frames).as_dict() | {"recall_over": over}


def closure_verdicts(closures: list[LoopClosure], truth: Trajectory, config: EvaluationConfig) -> np.ndarray:
    """(k,) bool: each closure (frames of the trajectory `truth` follows) true by the loops block's criteria."""
    criteria, positions = _loop_criteria(truth, config)
    return judge_closures(closures, positions, criteria)


def closure_curve(
    closures: list[LoopClosure], truth: Trajectory, config: EvaluationConfig, query_frames: np.ndarray | None = None
) -> PrecisionRecall:
    """The closures' precision-recall curve over their score, by the loops block's criteria and recall."""
    criteria, positions = _loop_criteria(truth, config)
    return precision_recall_curve(closures, positions, criteria, query_frames)


def _loop_criteria(truth: Trajectory, config: EvaluationConfig) -> tuple[LoopCriteria, np.ndarray]:
    """A true closure's criteria and the positions they are measured on (horizontal by default)."""
    positions = truth.positions[:, :2] if config.loop_distance == "horizontal" else truth.positions
    return LoopCriteria(config.loop_max_distance, config.loop_min_frame_gap), positions


def cell_metrics(cell_states: np.ndarray, odometry: Trajectory, object_vector_cells) -> dict[str, Any]:
    """How far the decoded grid and head-direction cells are from the odometry they integrate, and how the OVCN
    learned (no ground truth involved)."""
    position_error = np.linalg.norm(cell_states[:, :3] - odometry.positions, axis=1)
    heading_error = np.angle(np.exp(1j * (cell_states[:, 3] - yaw_of(odometry.poses))))
    losses = object_vector_cells.loss_history
    held_out = object_vector_cells.held_out_error()
    frames = len(position_error)  # 0: a live session stopped before its first frame
    return {
        "grid_cells_vs_odometry_rms_m": _finite(np.sqrt(np.mean(position_error**2))) if frames else None,
        "grid_cells_vs_odometry_final_m": _finite(position_error[-1]) if frames else None,
        "head_direction_vs_odometry_rms_deg": (
            _finite(np.degrees(np.sqrt(np.mean(heading_error**2)))) if frames else None
        ),
        "ovcn_epochs": len(losses),
        "ovcn_loss_first": _finite(losses[0]) if losses else None,
        "ovcn_loss_last": _finite(losses[-1]) if losses else None,
        "ovcn_held_out_rmse_hz": _finite(held_out["rmse_hz"]),
        "ovcn_held_out_max_hz": _finite(held_out["max_abs_hz"]),
    }


def timing_metrics(frame_times_s: np.ndarray, wall_s: float) -> dict[str, float]:
    frames = max(len(frame_times_s), 1)
    return {
        "wall_s": round(wall_s, 3),
        "fps": round(frames / wall_s, 2) if wall_s > 0 else 0.0,
        "ms_per_frame_median": round(float(np.median(frame_times_s)) * 1e3, 4) if len(frame_times_s) else 0.0,
        "ms_per_frame_p95": round(float(np.percentile(frame_times_s, 95)) * 1e3, 4) if len(frame_times_s) else 0.0,
    }
