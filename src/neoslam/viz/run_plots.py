"""The plots of a results folder: the maps beside the ground truth, the error along the route, the OVCN's loss,
the matching scores of a recognised keyframe and the keyframes' objects by label."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from neoslam.geometry import SimilarityTransform, fit_yaw_translation
from neoslam.pipeline import RunResult
from neoslam.types import Trajectory
from neoslam.viz.plots import (
    plot_error_along_route,
    plot_keyframe_labels,
    plot_map_2d,
    plot_map_3d,
    plot_matching_scores,
    plot_ovcn_loss,
)

__all__ = ["write_plots"]

MIN_ALIGNMENT_POSES = 3  # Umeyama needs three points


def _plot_alignment(estimate: Trajectory, truth: Trajectory) -> SimilarityTransform:
    """Where an estimate is shown beside the truth: its best fit in yaw and translation. Gravity is known, and a
    full 3-D rotation is ill-posed for a straight drive (it could roll the objects about the route)."""
    fit = fit_yaw_translation(estimate.positions, truth.positions)
    return SimilarityTransform(fit[:3, :3], fit[:3, 3])


def write_plots(folder: Path, result: RunResult, truth: Trajectory | None, threshold: float) -> None:
    folder.mkdir()
    if result.object_vector_cells.loss_history:
        plot_ovcn_loss(folder / "ovcn_loss.png", result.object_vector_cells.loss_history)
    if result.recognised_keyframe is not None:
        plot_matching_scores(
            folder / "matching_scores.png",
            result.recognised_keyframe,
            *result.recognised_scores,
            threshold,
            [c.query_keyframe for c in result.loop_closures if c.match_keyframe == result.recognised_keyframe],
        )
    estimates = {"odometry": result.odometry, "corrected": result.estimate}
    shown = SimilarityTransform(np.eye(3), np.zeros(3))
    if truth is not None and len(truth) >= MIN_ALIGNMENT_POSES:
        shown = _plot_alignment(result.estimate, truth)
        estimates = {"ground truth": truth} | {
            name: Trajectory(e.timestamps, _plot_alignment(e, truth).apply_to_poses(e.poses))
            for name, e in estimates.items()
        }
        plot_error_along_route(
            folder / "error_along_route.png", truth, {k: estimates[k] for k in ("odometry", "corrected")}
        )
    objects = [replace(o, position=shown.apply_to_points(o.position[None])[0]) for o in result.objects]
    plot_map_2d(folder / "map_2d.png", estimates, objects)
    plot_map_3d(folder / "map_3d.png", estimates)
    if result.keyframes:
        labels = np.concatenate([k.labels for k in result.keyframes])
        points = np.concatenate([result.experience_map.corrected_points(k.id, k.centers) for k in result.keyframes])
        corrected = shown.apply_to_poses(result.estimate.poses)
        plot_keyframe_labels(
            folder / "keyframe_labels.png",
            Trajectory(result.estimate.timestamps, corrected),
            labels,
            shown.apply_to_points(points),
        )
