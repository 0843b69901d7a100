"""The commands on datasets: `simulate`, `run`, `detect`, `evaluate` and `dump-config`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from neoslam.cli.app import app
from neoslam.cli.common import (
    FLAG,
    CalibrationOption,
    ConfigOption,
    GoalOption,
    LeftTopicOption,
    LocaliseOnlyOption,
    MapOption,
    OutOption,
    OverwriteOption,
    QuietOption,
    RerunOption,
    RightTopicOption,
    StaleOption,
    fail,
    say,
    table,
)
from neoslam.config import NOISE_PROFILES, dump_config, load_config
from neoslam.errors import ConfigError, NeoSLAMError

__all__ = ["detect", "dump_config_command", "evaluate", "report", "run_command", "simulate"]


NO_TRUTH = "none in the dataset: no ATE, RPE or loop precision (KITTI: poses/NN.txt beside sequences/)"


@app.command()
def simulate(
    out: OutOption,
    trajectory: Annotated[Path | None, typer.Option(help="True trajectory to drive (KITTI or TUM poses).")] = None,
    fmt: Annotated[str, typer.Option("--format", help="Format of --trajectory: kitti, tum or auto.")] = "auto",
    times: Annotated[Path | None, typer.Option(help="KITTI times.txt for --trajectory.")] = None,
    route: Annotated[str | None, typer.Option(help="Built-in route instead of a file: town, block.")] = None,
    noise: Annotated[str | None, typer.Option(help=f"Odometry noise: {', '.join(NOISE_PROFILES)}.")] = None,
    detector: Annotated[
        str | None, typer.Option(help="Detection profile: real (calibrated to the real front end, default), ideal.")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed of every random draw.")] = None,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Turn a trajectory into what a stereo camera with a detector and visual odometry would record there."""
    from neoslam.commands.simulate import record, simulate_dataset
    from neoslam.config.profiles import simulation_config
    from neoslam.io.atomic import check_target

    try:
        if trajectory is not None and route is not None:
            raise ConfigError("give either --trajectory or --route, not both")
        settings = simulation_config(load_config(config), noise, seed, detector)
        read = [trajectory, times, config]
        check_target(out, overwrite, read)
        recording = record(settings, trajectory, fmt, times, route, progress=not quiet)
        simulate_dataset(out, recording, overwrite, read)
    except (NeoSLAMError, OSError) as error:
        fail(error)
    detections = sum(len(d) for d in recording.detections)
    say(f"wrote {out}: {len(recording.truth)} frames, {detections} detections, {len(recording.world)} objects")


@app.command("run")
def run_command(
    data: Annotated[
        Path | None, typer.Argument(help="Dataset, KITTI root, bag, EuRoC or image folder; none: the default scenario.")
    ] = None,
    out: OutOption = Path("results"),
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under a KITTI odometry root, e.g. 06.")] = None,
    detections: Annotated[
        Path | None,
        typer.Option(help="Detections file (JSON lines, see `neoslam detect`) instead of the built-in detector."),
    ] = None,
    odometry: Annotated[
        Path | None, typer.Option(help="Odometry poses (TUM or KITTI, one per image) instead of stereo odometry.")
    ] = None,
    left_topic: LeftTopicOption = None,
    right_topic: RightTopicOption = None,
    calibration: CalibrationOption = None,
    odometry_topic: Annotated[
        str | None, typer.Option(help="A bag's nav_msgs/Odometry topic as the motion instead of stereo odometry.")
    ] = None,
    backend: Annotated[str | None, typer.Option(help="Map correction: relaxation or pose-graph.")] = None,
    rerun: RerunOption = None,
    map_path: MapOption = None,
    localise_only: LocaliseOnlyOption = False,
    goal: GoalOption = None,
    stale: StaleOption = False,
    detections_video: Annotated[
        bool,
        typer.Option(
            "--detections-video",
            metavar=FLAG,
            help="On images: every frame with its detections drawn, as plots/detections.avi.",
        ),
    ] = False,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Run NeoSLAM on a simulated dataset or stereo images (KITTI, a ROS bag, EuRoC, an image folder) and write the
    results folder (trajectories, object map, pose graph, metrics, plots); with --map, as a session of a kept map."""
    from neoslam.commands.run import run_dataset, with_backend
    from neoslam.datasets.opening import ImageInputs

    try:
        settings = with_backend(load_config(config), backend)
        inputs = ImageInputs(sequence, detections, odometry, left_topic, right_topic, odometry_topic, calibration)
        metrics = run_dataset(
            data,
            out,
            settings,
            overwrite,
            progress=not quiet,
            inputs=inputs,
            read=[config],
            rerun=rerun,
            map_path=map_path,
            localise_only=localise_only,
            goal=goal,
            stale_goal=stale,
            detections_video=detections_video,
        )
    except (NeoSLAMError, OSError) as error:
        fail(error)
    rows: list[tuple[str, Any]] = [("results", out), ("frames", metrics["frames"])]
    if "ate_rmse_m" in metrics:
        rows += [(f"ATE {name} [m]", value) for name, value in metrics["ate_rmse_m"].items()]
    else:
        rows += [("ground truth", NO_TRUTH)]
    rows += [("loop closures", metrics["loops"]["accepted"]), ("objects in map", metrics["objects"])]
    rows += [("frames per second", metrics["timing"]["fps"])]
    if metrics.get("perception"):
        perception = metrics["perception"]
        rows += [("perception frames per second", perception.get("wall_fps", perception["fps_median"]))]
    if "session" in metrics:
        session = metrics["session"]
        relocalised = session["relocalised_frame"]
        where = "the map's frame" if session["frame"] == "map" else "its own frame (not relocalised)"
        rows += [("map session", f"{session['id']} of {session['map']}, in {where}")]
        if session["id"] > 1:
            rows += [("relocalised at frame", "never" if relocalised is None else relocalised)]
            rows += [("closures with the stored map", session["map_closures"])]
    if "guidance" in metrics:
        guided = metrics["guidance"]
        rows += [("goal", guided["resolved"] or guided["goal"]), ("guidance", guided["reason"] or guided["state"])]
    say(table(rows))


@app.command()
def detect(
    data: Annotated[Path, typer.Argument(help="KITTI root, ROS bag, EuRoC recording or folder of stereo images.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Detections file to write (JSON lines).")],
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under the root, e.g. 06.")] = None,
    left_topic: LeftTopicOption = None,
    right_topic: RightTopicOption = None,
    calibration: CalibrationOption = None,
    config: ConfigOption = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", metavar=FLAG, help="Replace an existing file.")] = False,
    quiet: QuietOption = False,
) -> None:
    """Run the configured detector over a sequence's left images and write the detections in the JSON-lines
    format that `neoslam run --detections` reads."""
    from neoslam.commands.detect import detect_sequence
    from neoslam.datasets.opening import ImageInputs

    try:
        settings = load_config(config)
        topics = ImageInputs(left_topic=left_topic, right_topic=right_topic, calibration=calibration)
        counts = detect_sequence(
            data, sequence, out, settings, overwrite, progress=not quiet, read=[config], topics=topics
        )
    except (NeoSLAMError, OSError) as error:
        fail(error)
    say(f"wrote {out}: {counts['detections']} detections in {counts['frames']} frames")


@app.command()
def evaluate(
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM or KITTI).")],
    groundtruth: Annotated[Path, typer.Argument(help="Ground-truth trajectory (TUM or KITTI).")],
    est_format: Annotated[str, typer.Option("--est-format", help="tum, kitti or auto.")] = "auto",
    gt_format: Annotated[str, typer.Option("--gt-format", help="tum, kitti or auto.")] = "auto",
    align: Annotated[str | None, typer.Option(help="se3, sim3 or none (default: config).")] = None,
    loops: Annotated[Path | None, typer.Option(help="loop_closures.csv to judge against the ground truth.")] = None,
    keyframes: Annotated[
        Path | None,
        typer.Option(metavar="FILE", help="The run's keyframe frames (default: keyframe_frames.csv beside --loops)."),
    ] = None,
    recall_over: Annotated[
        str,
        typer.Option(
            "--recall-over",
            metavar="keyframes|frames",
            help="Loop recall over the keyframe frames (as metrics.json) or every frame.",
        ),
    ] = "keyframes",
    json_out: Annotated[Path | None, typer.Option("--json", help="Also write the metrics as JSON.")] = None,
    config: ConfigOption = None,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", metavar=FLAG, help="Replace an existing --json file.")
    ] = False,
) -> None:
    """ATE, RPE and KITTI drift of a trajectory file against ground truth; loop precision and recall."""
    from neoslam.commands.evaluate import evaluate_files

    try:
        settings = load_config(config)
        if align is not None:
            if align not in ("se3", "sim3", "none"):
                raise ConfigError(f"--align must be se3, sim3 or none, not {align!r}")
            evaluation = settings.evaluation.model_copy(update={"alignment": align})
            settings = settings.model_copy(update={"evaluation": evaluation})
        metrics = evaluate_files(
            estimate, groundtruth, settings, est_format, gt_format, loops, json_out, [config], overwrite, keyframes,
            recall_over,
        )  # fmt: skip
    except (NeoSLAMError, OSError) as error:
        fail(error)
    rows = [(key, value) for key, value in metrics.items() if not isinstance(value, dict)]
    rows += [(f"loops {key}", value) for key, value in metrics.get("loops", {}).items()]
    rows += [(f"no {key}", why) for key, why in metrics.get("absent", {}).items()]
    say(table(rows))


@app.command()
def report(
    results: Annotated[list[Path], typer.Argument(help="Results folders of `neoslam run`, shown side by side.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="The HTML file (written whole or not at all).")],
    overwrite: Annotated[bool, typer.Option("--overwrite", metavar=FLAG, help="Replace an existing file.")] = False,
) -> None:
    """One self-contained HTML page of one run or several side by side: figures, metrics, time by stage and the
    configuration that differed."""
    from neoslam.commands.report import write_report

    try:
        size = write_report(results, out, overwrite)
    except (NeoSLAMError, OSError) as error:
        fail(error)
    say(f"wrote {out}: {len(results)} run{'s' if len(results) != 1 else ''}, {size:,} bytes")


@app.command("dump-config")
def dump_config_command(config: ConfigOption = None) -> None:
    """Print the resolved configuration (defaults, then --config, then NEOSLAM_* variables) as YAML."""
    try:
        say(dump_config(load_config(config)), nl=False)
    except (NeoSLAMError, OSError) as error:
        fail(error)
