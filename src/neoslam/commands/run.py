"""`neoslam run`: NeoSLAM over a dataset folder, a KITTI sequence or a ROS bag (or the default simulated scenario),
optionally from and into a map file and shown live, written as a results folder."""

from __future__ import annotations

import time
from collections.abc import Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.commands.run_metrics import run_metrics, session_metrics
from neoslam.commands.simulate import DEFAULT_ROUTE, record
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.opening import Dataset, ImageInputs, open_dataset
from neoslam.datasets.simulated import write_dataset
from neoslam.errors import ConfigError
from neoslam.io.atomic import atomic_directory
from neoslam.io.g2o import write_g2o
from neoslam.io.results import (
    KEYFRAME_FRAMES,
    write_config,
    write_experience_map,
    write_keyframe_frames,
    write_loop_closures,
    write_metrics,
    write_object_vector_cells,
    write_objects,
    write_trajectories,
)
from neoslam.io.route_files import write_guidance_csv
from neoslam.navigation.session import GoalGuidance
from neoslam.perception.frontend import ImageDataset
from neoslam.pipeline import RunResult, run
from neoslam.store.recording import MapRecording, check_map_path, map_recording
from neoslam.viz.detections_strip import SeenObjects, write_detections_strip, write_detections_video
from neoslam.viz.rerun_view import check_rerun_target, recording_target, rerun_session
from neoslam.viz.run_plots import write_plots

__all__ = ["observers", "run_dataset", "with_backend", "write_results"]

DETECTIONS_PLOT = "detections.png"  # a run on images: what the detector saw at some keyframes
DETECTIONS_VIDEO = "detections.avi"  # and, when asked, at every frame
VIDEO_FPS_RANGE = (1.0, 60.0)  # a video plays at the camera's rate, within these


def with_backend(config: NeoSLAMConfig, backend: str | None) -> NeoSLAMConfig:
    """The config with another map-correction back end, if one is named."""
    if backend is None:
        return config
    if backend not in ("relaxation", "pose-graph"):
        raise ConfigError(f"unknown backend {backend!r}; choose relaxation or pose-graph")
    return config.model_copy(update={"experience_map": config.experience_map.model_copy(update={"backend": backend})})


def observers(*observers):
    """One step observer calling each given one in turn (None ones left out)."""
    chosen = [observer for observer in observers if observer is not None]
    if not chosen:
        return None

    def observe(slam, frame, pose) -> None:
        for observer in chosen:
            observer(slam, frame, pose)

    return observe


def run_dataset(
    data: Path | None,
    out: Path,
    config: NeoSLAMConfig,
    overwrite: bool = False,
    progress: bool = True,
    inputs: ImageInputs = ImageInputs(),
    read: Sequence[Path | None] = (),
    rerun: str | None = None,
    map_path: Path | None = None,
    localise_only: bool = False,
    goal: str | None = None,
    stale_goal: bool = False,
    detections_video: bool = False,
) -> dict[str, Any]:
    """Run NeoSLAM on a dataset folder, KITTI sequence or ROS bag (or simulate the default scenario first) and
    write the results folder. `read` names further files the run reads (a config file), which the output must not
    replace. `rerun`: "spawn" shows the run live in the Rerun viewer, a path ending .rrd records it there.
    `map_path`: a map file the run starts from and extends (created if missing; see neoslam.store), written as the
    run goes; with `localise_only` the run uses it and changes nothing in it. `goal`: guidance towards it (the
    goal language of neoslam.navigation; `stale_goal` allows a stale object), written per frame to guidance.csv.
    `detections_video`: on images, every frame with its detections drawn, plots/detections.avi."""
    check_rerun_target(rerun)
    guidance = GoalGuidance(goal, config, stale_goal) if goal is not None else None
    read_paths = [data, *inputs.files(), *read]
    if map_path is not None:
        check_map_path(map_path, out, read_paths, localise_only)
    elif localise_only:
        raise ConfigError("--localise-only needs --map FILE")
    if detections_video and data is None:
        raise ConfigError("--detections-video draws camera images: it needs a run on images, not the default scenario")
    with atomic_directory(out, overwrite, read_paths) as staging:
        if data is None:
            write_dataset(staging / "dataset", record(config, route=DEFAULT_ROUTE, progress=progress))
            data = staging / "dataset"
        dataset = open_dataset(data, config, inputs)
        if detections_video and not isinstance(dataset, ImageDataset):
            raise ConfigError(f"--detections-video draws camera images: {data} holds simulated detections, no images")
        viewer = recording_target(rerun, out, staging)
        kept = map_recording(map_path, config, localise_only) if map_path is not None else nullcontext(None)
        with kept as session, rerun_session(viewer, dataset, overwrite, [data, *inputs.files(), *read]) as on_step:
            if on_step is not None and guidance is not None:
                on_step.follow(guidance)
            stored = session.stored if session is not None else None
            recorder = session.recorder if session is not None else None
            seen = SeenObjects() if isinstance(dataset, ImageDataset) else None  # for the detections strip
            start = time.perf_counter()
            result = run(
                dataset.frames(),
                config,
                total=len(dataset),
                progress=progress,
                on_step=observers(guidance, on_step, recorder, seen),  # the guidance first: the view shows it
                stored=stored,
                session_name=dataset.name,
            )
            wall_s = time.perf_counter() - start
            if recorder is not None:
                recorder.finish()
        metrics = run_metrics(dataset, result, config, wall_s)
        if guidance is not None:
            metrics["guidance"] = guidance.summary()
            write_guidance_csv(staging / "guidance.csv", guidance.records)
        write_results(staging, dataset, result, config, metrics, session)
        if seen is not None:
            pairs = dataset.sequence.stereo_pair
            strip = staging / "plots" / DETECTIONS_PLOT
            write_detections_strip(strip, lambda frame: pairs(frame)[0], result.keyframe_frames, seen)
            if detections_video:
                video = staging / "plots" / DETECTIONS_VIDEO
                write_detections_video(video, lambda frame: pairs(frame)[0], sorted(seen.frames), seen, _fps(result))

    return metrics


def _fps(result: RunResult) -> float:
    """The camera's rate, from the run's timestamps, within VIDEO_FPS_RANGE."""
    steps = np.diff(result.odometry.timestamps)
    steps = steps[steps > 0]
    rate = 1.0 / float(np.median(steps)) if len(steps) else VIDEO_FPS_RANGE[0]
    return float(np.clip(rate, *VIDEO_FPS_RANGE))


def write_results(
    staging: Path,
    dataset: Dataset,
    result: RunResult,
    config: NeoSLAMConfig,
    metrics: dict[str, Any],
    session: MapRecording | None,
    plots: bool = True,
) -> None:
    """A run's results folder (docs/results.md) into `staging`: trajectories, closures, objects, the maps, the
    config, `metrics` (with the map session's figures added) and, with `plots`, the figures."""
    trajectories = {"trajectory": result.estimate, "odometry": result.odometry}
    if dataset.ground_truth is not None:
        trajectories["groundtruth"] = dataset.ground_truth
    write_trajectories(staging, trajectories)
    write_loop_closures(staging / "loop_closures.csv", result.loop_closures, result.closure_sessions())
    write_keyframe_frames(staging / KEYFRAME_FRAMES, result.keyframe_frames)
    write_objects(staging / "objects.csv", result.objects, result.moving_objects)
    write_object_vector_cells(staging, result.object_vector_cells)
    write_experience_map(staging / "experience_map.json", result.experience_map)
    write_g2o(staging / "experience_map.g2o", result.experience_map)
    write_config(staging / "config.yaml", config)
    if session is not None:
        metrics["session"] = session_metrics(session, result)
    write_metrics(staging / "metrics.json", metrics)
    if plots:
        threshold = config.matching.score_threshold
        write_plots(staging / "plots", result, dataset.ground_truth, threshold, config.evaluation)
