"""The plots of a results folder: the maps beside the ground truth, the error along the route, the OVCN's loss,
the matching scores of a recognised keyframe and the keyframes' objects by label."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from neoslam.config import EvaluationConfig
from neoslam.evaluation.report import RECALL_OVER_KEYFRAMES, closure_curve, closure_verdicts
from neoslam.evaluation.trajectory_metrics import align
from neoslam.geometry import SimilarityTransform, fit_yaw_translation
from neoslam.pipeline import RunResult
from neoslam.types import Trajectory
from neoslam.viz.map_plot import MapLayers, plot_map_2d
from neoslam.viz.plots import (
    plot_error_along_route,
    plot_keyframe_labels,
    plot_map_3d,
    plot_matching_scores,
    plot_ovcn_loss,
    plot_precision_recall,
)

__all__ = ["write_plots"]

MIN_ALIGNMENT_POSES = 3  # Umeyama needs three points


def _plot_alignment(estimate: Trajectory, truth: Trajectory) -> SimilarityTransform:
    """Where an estimate is shown beside the truth: its best fit in yaw and translation. Gravity is known, and a
    full 3-D rotation is ill-posed for a straight drive (it could roll the objects about the route)."""
    fit = fit_yaw_translation(estimate.positions, truth.positions)
    return SimilarityTransform(fit[:3, :3], fit[:3, 3])


def _layers(
    result: RunResult,
    truth: Trajectory | None,
    evaluation: EvaluationConfig,
    shown: SimilarityTransform,
    note: str | None,
) -> MapLayers:
    """The top view's closures (this session's query frame to the matched keyframe's experience; judged against the
    truth where both ends are this session's frames), the map's experiences by session, where this session
    relocalised and the objects, all moved by `shown`."""
    experience_map = result.experience_map
    poses = experience_map.graph.poses
    closures = result.loop_closures
    query = result.estimate.positions[[c.query_frame for c in closures]]
    match = poses[[experience_map.experience_of(c.match_keyframe) for c in closures], :3, 3]
    links = np.stack([shown.apply_to_points(query), shown.apply_to_points(match)], axis=1)[..., :2]
    verdicts = None
    if truth is not None and closures and all(c.match_keyframe >= result.first_keyframe for c in closures):
        verdicts = closure_verdicts(closures, truth, evaluation)
    relocalised = result.session.relocalised_frame
    where = None if relocalised is None else shown.apply_to_points(result.estimate.positions[[relocalised]])[0, :2]
    return MapLayers(
        objects=[replace(o, position=shown.apply_to_points(o.position[None])[0]) for o in result.objects],
        closures=links.reshape(-1, 2, 2),
        closure_truth=verdicts,
        experiences=shown.apply_to_points(poses[:, :3, 3])[:, :2] if len(poses) else np.zeros((0, 2)),
        sessions=np.array([e.session for e in experience_map.experiences], dtype=int),
        relocalised=where,
        note=note,
    )


def write_plots(
    folder: Path,
    result: RunResult,
    truth: Trajectory | None,
    threshold: float,
    evaluation: EvaluationConfig | None = None,
) -> None:
    """The plots of a run. The error along the route is of the estimates aligned as metrics.json's ATE is
    (`evaluation.alignment`), so that its RMSE is that ATE; the maps show them fitted in yaw and translation only
    (gravity is known), and say so; closures are judged by `evaluation`'s criteria, as metrics.json's."""
    evaluation = evaluation or EvaluationConfig()
    alignment = evaluation.alignment
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
    note = None
    if truth is not None and len(truth) >= MIN_ALIGNMENT_POSES:
        shown = _plot_alignment(result.estimate, truth)
        note = "estimates fitted to the ground truth in yaw and translation"
        errors = {name: align(e, truth, alignment)[0] for name, e in estimates.items()}
        plot_error_along_route(folder / "error_along_route.png", truth, errors, f"aligned {alignment}, as the ATE")
        closures = result.session_closures()
        if closures:
            curve = closure_curve(closures, truth, evaluation, result.keyframe_frames)
            plot_precision_recall(folder / "precision_recall.png", curve, f"recall over the {RECALL_OVER_KEYFRAMES}")
        estimates = {"ground truth": truth} | {
            name: Trajectory(e.timestamps, _plot_alignment(e, truth).apply_to_poses(e.poses))
            for name, e in estimates.items()
        }
    plot_map_2d(folder / "map_2d.png", estimates, _layers(result, truth, evaluation, shown, note))
    plot_map_3d(folder / "map_3d.png", estimates, note)
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
