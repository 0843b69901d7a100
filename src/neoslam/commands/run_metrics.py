"""The figures of a run (metrics.json): trajectory errors against ground truth where there is one, loop
closures, the maps' sizes, the cells, timing, and the session of a map file."""

from __future__ import annotations

from typing import Any

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.opening import Dataset
from neoslam.evaluation.report import cell_metrics, loop_metrics, timing_metrics, trajectory_metrics
from neoslam.perception.frontend import ImageDataset
from neoslam.pipeline import RunResult
from neoslam.store.recording import MapRecording

__all__ = ["run_metrics", "session_metrics"]


def run_metrics(dataset: Dataset, result: RunResult, config: NeoSLAMConfig, wall_s: float) -> dict[str, Any]:
    metrics: dict[str, Any] = {"dataset": dataset.name, "frames": len(dataset)}
    truth = dataset.ground_truth
    if truth is not None:
        evaluation = config.evaluation
        odometry = trajectory_metrics(result.odometry, truth, evaluation)
        corrected = trajectory_metrics(result.estimate, truth, evaluation)
        metrics["ate_rmse_m"] = {"odometry": odometry["ate_rmse_m"], "corrected": corrected["ate_rmse_m"]}
        metrics["trajectory"] = {"alignment": evaluation.alignment, "odometry": odometry, "corrected": corrected}
    keyframe_frames = np.asarray(result.keyframe_frames, dtype=int)  # every keyframe made, stored or recognised
    metrics["loops"] = loop_metrics(result.session_closures(), truth, config.evaluation, keyframe_frames)
    metrics["keyframes"] = len(result.keyframes)
    experience_map = result.experience_map
    metrics["experience_map"] = {
        "backend": experience_map.config.backend,
        "experiences": len(experience_map.experiences),
        "links": len(experience_map.graph.links),
        "links_withdrawn": len(experience_map.withdrawn_links),
        "closures_rejected_by_grid_cells": len(experience_map.rejected_closures),
    }
    metrics["hebbian_bytes"] = result.hebbian.nbytes
    metrics["objects"] = len(result.objects)
    metrics["moving_objects"] = len(result.moving_objects)
    metrics["moving_observations"] = result.moving_observations
    heading, distance = result.odometry_noise
    metrics["odometry_noise"] = {"heading_rad_per_sqrt_s": heading, "distance_m_per_sqrt_s": distance}
    metrics["cells"] = cell_metrics(result.cell_states, result.odometry, result.object_vector_cells)
    metrics["timing"] = timing_metrics(result.frame_times_s, wall_s)
    metrics["timing"]["backend_s"] = experience_map.backend.seconds  # in the pose-graph solvers, summed
    if isinstance(dataset, ImageDataset):
        metrics["perception"] = dataset.front_end.times.summary()
    return metrics


def session_metrics(session: MapRecording, result: RunResult) -> dict[str, Any]:
    """Which session of the map file the run was, and whether (at which frame) it relocalised in the stored map."""
    record = result.session
    in_map_frame = record.id == 1 or record.relocalised_frame is not None  # the first session's frame is the map's
    return {
        "id": record.id,
        "map": str(session.path),
        "localise_only": session.localise_only,
        "relocalised_frame": record.relocalised_frame,
        "frame": "map" if in_map_frame else "session",
        "map_keyframes": len(session.stored.keyframes),
        "map_closures": len(result.loop_closures) - len(result.session_closures()),
    }
