"""How results are judged against ground truth."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from neoslam.config.base import Section

__all__ = ["EvaluationConfig"]


class EvaluationConfig(Section):
    """How results are judged against ground truth (never read by the SLAM path)."""

    loop_max_distance: float = Field(5.0, gt=0, le=1e4, description="a true closure's frames are this close, m")
    loop_min_frame_gap: int = Field(100, ge=0, le=10_000_000, description="and at least this many frames apart")
    loop_distance: Literal["3d", "horizontal"] = Field(
        "horizontal",
        description="distance of that test: horizontal (KITTI's ground-truth heights disagree by metres where a "
        "road is driven again), or 3d",
    )
    alignment: Literal["se3", "sim3", "none"] = Field("se3", description="alignment before ATE")
    rpe_delta: float = Field(100.0, gt=0, le=1e6, description="RPE pair spacing")
    rpe_unit: Literal["frames", "m"] = Field("m", description="unit of rpe_delta")
    max_time_difference: float = Field(0.01, gt=0, le=1000, description="timestamp association tolerance, s")
