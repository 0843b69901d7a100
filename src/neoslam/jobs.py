"""The work behind each CLI command: simulate a dataset, run NeoSLAM on one, evaluate trajectory files."""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from neoslam.config import MotionLimitsConfig, NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.bag import BagSequence, is_bag, open_bag
from neoslam.datasets.kitti import KittiSequence, is_kitti_root, read_kitti_sequence, sequences_in
from neoslam.datasets.simulated import is_simulated_dataset, read_dataset, write_dataset
from neoslam.errors import ConfigError, InputError
from neoslam.evaluation.report import cell_metrics, loop_metrics, timing_metrics, trajectory_metrics
from neoslam.evaluation.trajectory_metrics import associate
from neoslam.geometry import SimilarityTransform, fit_yaw_translation, is_single_place
from neoslam.io.atomic import atomic_directory, atomic_file, check_target_file
from neoslam.io.g2o import write_g2o
from neoslam.io.motion_limits import check_pose_steps, check_trajectory_file
from neoslam.io.results import (
    read_loop_closures,
    write_config,
    write_experience_map,
    write_loop_closures,
    write_metrics,
    write_object_vector_cells,
    write_objects,
    write_trajectories,
)
from neoslam.io.trajectory_files import read_trajectory
from neoslam.perception.frontend import ImageDataset, open_front_end
from neoslam.pipeline import RunResult, run
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import SimulatedRecording, simulate
from neoslam.store.recording import MapRecording, check_map_path, map_recording
from neoslam.types import Frame, Trajectory
from neoslam.viz.plots import (
    plot_error_along_route,
    plot_keyframe_labels,
    plot_map_2d,
    plot_map_3d,
    plot_matching_scores,
    plot_ovcn_loss,
)
from neoslam.viz.rerun_view import check_rerun_target, recording_target, rerun_session

__all__ = [
    "DEFAULT_ROUTE",
    "ImageInputs",
    "simulation_config",
    "with_backend",
    "record",
    "simulate_dataset",
    "run_dataset",
    "detect_sequence",
    "evaluate_files",
]

DEFAULT_ROUTE = "town"
MIN_ALIGNMENT_POSES = 3  # Umeyama needs three points


class Dataset(Protocol):
    """What a run reads: a simulated dataset folder or a KITTI sequence seen through the perception front end."""

    name: str
    ground_truth: Trajectory | None  # evaluation only

    def __len__(self) -> int: ...

    def frames(self) -> Iterator[Frame]: ...


def with_backend(config: NeoSLAMConfig, backend: str | None) -> NeoSLAMConfig:
    """The config with another map-correction back end, if one is named."""
    if backend is None:
        return config
    if backend not in ("relaxation", "pose-graph"):
        raise ConfigError(f"unknown backend {backend!r}; choose relaxation or pose-graph")
    return config.model_copy(update={"experience_map": config.experience_map.model_copy(update={"backend": backend})})


def record(
    config: NeoSLAMConfig,
    trajectory: Path | None = None,
    fmt: str = "auto",
    times: Path | None = None,
    route: str | None = None,
    progress: bool = False,
) -> SimulatedRecording:
    """Simulate along a trajectory file or a built-in route."""
    sim = config.simulator
    if trajectory is not None:
        truth = read_trajectory(trajectory, fmt, times, frame_period=sim.frame_period)
        check_trajectory_file(trajectory, truth, config.motion_limits, times)
        return simulate(truth, sim, name=trajectory.stem, source=str(trajectory), progress=progress)
    name = route or DEFAULT_ROUTE
    if name not in ROUTES:
        raise ConfigError(f"unknown route {name!r}; built-in routes: {', '.join(sorted(ROUTES))}")
    truth = drive_route(ROUTES[name], sim.frame_period, sim.camera.height_above_ground)
    return simulate(truth, sim, name=name, source=f"route:{name}", progress=progress, route=ROUTES[name])


def simulate_dataset(
    out: Path, recording: SimulatedRecording, overwrite: bool = False, read: Sequence[Path | None] = ()
) -> None:
    """Write a simulated dataset folder; `read` names the files the simulation read, which it must not replace."""
    with atomic_directory(out, overwrite, read) as staging:
        write_dataset(staging, recording)


@dataclass(frozen=True)
class ImageInputs:
    """What a run on a KITTI image sequence or a ROS bag needs besides its path: the KITTI sequence or the bag's
    topics (found in the bag when unambiguous), and optionally detections and odometry from files (or a bag's
    odometry topic) instead of the built-in detector and stereo odometry."""

    sequence: str | None = None
    detections: Path | None = None
    odometry: Path | None = None
    left_topic: str | None = None
    right_topic: str | None = None
    odometry_topic: str | None = None

    def files(self) -> list[Path]:
        """The files a run reads besides the dataset (an output must not replace them)."""
        return [path for path in (self.detections, self.odometry) if path is not None]


def _kitti_sequence(root: Path, name: str | None) -> KittiSequence:
    """The named sequence of a KITTI root; without a name, one line listing the sequences there."""
    if name is None:
        found = ", ".join(sequences_in(root)) or "none"
        raise InputError(root, f"a KITTI root needs --sequence NN (sequences here: {found})")
    return read_kitti_sequence(root, name)


def _bag_sequence(path: Path, config: NeoSLAMConfig, inputs: ImageInputs, motion: bool = True) -> BagSequence:
    """A bag's stereo sequence; with `motion`, its odometry topic too when one is named (or when the config asks
    for poses and no pose file is given: then the bag's only nav_msgs/Odometry topic)."""
    if inputs.sequence is not None:
        raise ConfigError("--sequence applies to KITTI roots; choose a bag's cameras with --left-topic/--right-topic")
    if inputs.odometry is not None and inputs.odometry_topic is not None:
        raise ConfigError("give either --odometry FILE or --odometry-topic, not both")
    wanted = motion and config.perception.odometry.source == "poses" and inputs.odometry is None
    odometry_topic = inputs.odometry_topic if motion else None
    bag = config.perception.bag
    return open_bag(path, bag, inputs.left_topic, inputs.right_topic, odometry_topic, odometry_wanted=wanted)


def _check_bag_odometry(path: Path, bag: BagSequence, limits: MotionLimitsConfig) -> None:
    """A bag's odometry topic is held to the motion limits as a pose file is, the frame named instead of a line."""
    if bag.odometry is None:
        return
    try:
        check_pose_steps(path, bag.odometry, limits, np.arange(len(bag.odometry)))
    except InputError as error:
        where = f"odometry topic {bag.topics.odometry}, frame {error.line}"
        raise InputError(path, f"{where}: {error.problem}") from None


def _load(data: Path, config: NeoSLAMConfig, inputs: ImageInputs) -> Dataset:
    if not data.exists():
        raise InputError(data, "dataset folder not found")
    if (inputs.left_topic, inputs.right_topic, inputs.odometry_topic) != (None, None, None) and not is_bag(data):
        raise ConfigError("--left-topic, --right-topic and --odometry-topic apply to ROS bags only")
    if is_simulated_dataset(data):
        if inputs != ImageInputs():
            raise ConfigError("--sequence, --detections and --odometry apply to KITTI image sequences only")
        return read_dataset(data, config.motion_limits)
    if is_kitti_root(data):
        sequence = _kitti_sequence(data, inputs.sequence)
        return open_front_end(sequence, config.perception, inputs.detections, inputs.odometry, config.motion_limits)
    if is_bag(data):
        bag = _bag_sequence(data, config, inputs)
        if inputs.odometry is None and bag.odometry is not None:
            _check_bag_odometry(data, bag, config.motion_limits)
        odometry = inputs.odometry if inputs.odometry is not None else bag.odometry
        return open_front_end(bag, config.perception, inputs.detections, odometry, config.motion_limits)
    raise InputError(
        data,
        "neither a simulated dataset (dataset.yaml) nor a KITTI odometry root (sequences/) nor a ROS bag (.bag, "
        ".db3, .mcap, or a folder with metadata.yaml)",
    )


def _metrics(dataset: Dataset, result: RunResult, config: NeoSLAMConfig, wall_s: float) -> dict[str, Any]:
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


def _session_metrics(session: MapRecording, result: RunResult) -> dict[str, Any]:
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


def _observers(*observers):
    """One step observer calling each given one in turn (None ones left out)."""
    chosen = [observer for observer in observers if observer is not None]
    if not chosen:
        return None

    def observe(slam, frame, pose) -> None:
        for observer in chosen:
            observer(slam, frame, pose)

    return observe


def _plot_alignment(estimate: Trajectory, truth: Trajectory) -> SimilarityTransform:
    """Where an estimate is shown beside the truth: its best fit in yaw and translation. Gravity is known, and a
    full 3-D rotation is ill-posed for a straight drive (it could roll the objects about the route)."""
    fit = fit_yaw_translation(estimate.positions, truth.positions)
    return SimilarityTransform(fit[:3, :3], fit[:3, 3])


def _plots(folder: Path, result: RunResult, truth: Trajectory | None, threshold: float) -> None:
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
) -> dict[str, Any]:
    """Run NeoSLAM on a dataset folder, KITTI sequence or ROS bag (or simulate the default scenario first) and
    write the results folder. `read` names further files the run reads (a config file), which the output must not
    replace. `rerun`: "spawn" shows the run live in the Rerun viewer, a path ending .rrd records it there.
    `map_path`: a map file the run starts from and extends (created if missing; see neoslam.store), written as the
    run goes; with `localise_only` the run uses it and changes nothing in it."""
    check_rerun_target(rerun)
    read_paths = [data, *inputs.files(), *read]
    if map_path is not None:
        check_map_path(map_path, out, read_paths, localise_only)
    elif localise_only:
        raise ConfigError("--localise-only needs --map FILE")
    with atomic_directory(out, overwrite, read_paths) as staging:
        if data is None:
            write_dataset(staging / "dataset", record(config, route=DEFAULT_ROUTE, progress=progress))
            data = staging / "dataset"
        dataset = _load(data, config, inputs)
        viewer = recording_target(rerun, out, staging)
        kept = map_recording(map_path, config, localise_only) if map_path is not None else nullcontext(None)
        with kept as session, rerun_session(viewer, dataset, overwrite, [data, *inputs.files(), *read]) as on_step:
            stored = session.stored if session is not None else None
            recorder = session.recorder if session is not None else None
            start = time.perf_counter()
            result = run(
                dataset.frames(),
                config,
                total=len(dataset),
                progress=progress,
                on_step=_observers(on_step, recorder),
                stored=stored,
                session_name=dataset.name,
            )
            wall_s = time.perf_counter() - start
            if recorder is not None:
                recorder.finish()
        trajectories = {"trajectory": result.estimate, "odometry": result.odometry}
        if dataset.ground_truth is not None:
            trajectories["groundtruth"] = dataset.ground_truth
        write_trajectories(staging, trajectories)
        write_loop_closures(staging / "loop_closures.csv", result.loop_closures, result.closure_sessions())
        write_objects(staging / "objects.csv", result.objects, result.moving_objects)
        write_object_vector_cells(staging, result.object_vector_cells)
        write_experience_map(staging / "experience_map.json", result.experience_map)
        write_g2o(staging / "experience_map.g2o", result.experience_map)
        write_config(staging / "config.yaml", config)
        metrics = _metrics(dataset, result, config, wall_s)
        if session is not None:
            metrics["session"] = _session_metrics(session, result)
        write_metrics(staging / "metrics.json", metrics)
        _plots(staging / "plots", result, dataset.ground_truth, config.matching.score_threshold)
    return metrics


def detect_sequence(
    root: Path,
    sequence_name: str | None,
    out: Path,
    config: NeoSLAMConfig,
    overwrite: bool = False,
    progress: bool = True,
    read: Sequence[Path | None] = (),
    topics: ImageInputs = ImageInputs(),
) -> dict[str, int]:
    """Run the configured detector over a KITTI sequence's or a ROS bag's left images and write its detections as
    JSON lines (the format `--detections` reads), so that a detector runs once and its output can be inspected and
    reused. `topics` names a bag's camera topics (frames are the bag's stereo pairs, as a run numbers them)."""
    from neoslam.perception.detections_file import write_detections_file
    from neoslam.perception.detector import make_detector

    inputs = [root, *read]
    check_target_file(out, overwrite, inputs)
    sequence: KittiSequence | BagSequence
    if is_bag(root):
        sequence = _bag_sequence(root, config, replace(topics, sequence=sequence_name), motion=False)
    elif not is_kitti_root(root):
        raise InputError(root, "not a KITTI odometry root (sequences/NN/image_0, image_1, calib.txt, times.txt)")
    else:
        sequence = _kitti_sequence(root, sequence_name)
    with atomic_file(out, overwrite, inputs) as staging:
        detector = make_detector(config.perception.detector)
        indices = tqdm(range(len(sequence)), desc="detect", unit="frame", disable=not progress, leave=False)
        per_frame = {i: detector.detect(i, sequence.left_image(i)) for i in indices}
        write_detections_file(staging, per_frame)
    return {"frames": len(per_frame), "detections": sum(len(d) for d in per_frame.values())}


def evaluate_files(
    estimate_path: Path,
    truth_path: Path,
    config: NeoSLAMConfig,
    estimate_format: str = "auto",
    truth_format: str = "auto",
    loops_path: Path | None = None,
    json_out: Path | None = None,
    read: Sequence[Path | None] = (),
) -> dict[str, Any]:
    """Metrics of an estimate file against a ground-truth file (timestamps associated first), also written to
    `json_out` if named (never over one of the files read)."""
    inputs = [estimate_path, truth_path, loops_path, *read]
    if json_out is not None:
        check_target_file(json_out, overwrite=True, inputs=inputs)
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
        with atomic_file(json_out, overwrite=True, inputs=inputs) as staging:
            write_metrics(staging, metrics)
    return metrics
