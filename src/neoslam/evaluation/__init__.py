"""Evaluation: trajectory accuracy (ATE, RPE, KITTI drift) and loop-closure judgement against ground truth."""

from neoslam.evaluation.loops import (
    DEFAULT_CRITERIA,
    LoopCriteria,
    LoopStats,
    evaluate_closures,
    judge_closures,
    true_revisits,
)
from neoslam.evaluation.trajectory_metrics import (
    DEFAULT_MAX_TIME_DIFF_S,
    KITTI_SEGMENT_LENGTHS_M,
    KITTI_STEP_FRAMES,
    AlignMode,
    DeltaUnit,
    DriftStats,
    ErrorStats,
    RPEStats,
    absolute_trajectory_error,
    align,
    associate,
    kitti_drift,
    relative_pose_error,
)

__all__ = [
    "AlignMode",
    "DeltaUnit",
    "ErrorStats",
    "RPEStats",
    "DriftStats",
    "associate",
    "align",
    "absolute_trajectory_error",
    "relative_pose_error",
    "kitti_drift",
    "DEFAULT_MAX_TIME_DIFF_S",
    "KITTI_SEGMENT_LENGTHS_M",
    "KITTI_STEP_FRAMES",
    "LoopCriteria",
    "DEFAULT_CRITERIA",
    "LoopStats",
    "true_revisits",
    "judge_closures",
    "evaluate_closures",
]
