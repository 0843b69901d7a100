"""The `neoslam` command: it parses arguments and calls `neoslam.commands`, nothing more."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from neoslam import __version__, stopping
from neoslam.config import NOISE_PROFILES, dump_config, load_config
from neoslam.errors import ConfigError, NeoSLAMError

RERUN_OPTION = "--rerun"
RERUN_SPAWN = "spawn"  # neoslam.viz.rerun_view.SPAWN, without importing it at start-up


class _Commands(TyperGroup):
    """`--rerun` takes an optional value: alone it spawns the viewer, followed by a FILE.rrd it records there.
    Click options cannot make their value optional, so a bare `--rerun` is given the value "spawn" here; a value is
    taken only when it ends in .rrd, so that `run --rerun DATA` never reads DATA as the recording file."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        given = []
        for index, arg in enumerate(args):
            given.append(arg)
            if arg == RERUN_OPTION and (index + 1 == len(args) or not args[index + 1].endswith(".rrd")):
                given.append(RERUN_SPAWN)
        return super().parse_args(ctx, given)


app = typer.Typer(
    cls=_Commands,
    name="neoslam",
    help="Neural Object SLAM: object SLAM with grid cells, head-direction cells and object-vector cells.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

ConfigOption = Annotated[Path | None, typer.Option("--config", "-c", help="YAML file overriding the defaults.")]
OutOption = Annotated[Path, typer.Option("--out", "-o", help="Output folder (written whole or not at all).")]
OverwriteOption = Annotated[bool, typer.Option("--overwrite", help="Replace a non-empty output folder.")]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]
LeftTopicOption = Annotated[
    str | None, typer.Option(help="A bag's left camera topic (Image or CompressedImage); found when unambiguous.")
]
RightTopicOption = Annotated[str | None, typer.Option(help="A bag's right camera topic; found when unambiguous.")]
CalibrationOption = Annotated[
    Path | None, typer.Option(metavar="FILE", help="Image folder's calibration (default: its calibration.yaml).")
]


def _say(text: object, err: bool = False, nl: bool = True) -> None:
    """Print a line; a file name that is not UTF-8 (kept by Python as surrogate escapes) is shown with its bytes
    escaped (seq\\xff), where printing it as it is would fail."""
    readable = str(text).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    typer.echo(readable, err=err, nl=nl)


def _fail(error: NeoSLAMError | OSError) -> None:
    # OSError: a folder that cannot be written, a disk that is full; the user can fix these too.
    message = f"{error.filename}: {error.strerror}" if isinstance(error, OSError) and error.filename else error
    _say(f"neoslam: error: {message}", err=True)
    raise typer.Exit(code=2)


def _version(value: bool) -> None:
    if value:
        _say(f"neoslam {__version__}")
        raise typer.Exit()


@app.callback()
def root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """Neural Object SLAM."""


def _table(rows: list[tuple[str, Any]]) -> str:
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


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
        _fail(error)
    detections = sum(len(d) for d in recording.detections)
    _say(f"wrote {out}: {len(recording.truth)} frames, {detections} detections, {len(recording.world)} objects")


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
    rerun: Annotated[
        str | None,
        typer.Option(
            RERUN_OPTION,
            metavar="[FILE.rrd]",
            # The backslash keeps rich from reading [viewer] as markup.
            help="Show the run live in Rerun: alone, spawn the viewer; with FILE.rrd, record there "
            '(needs pip install "neoslam\\[viewer]").',
        ),
    ] = None,
    map_path: Annotated[
        Path | None,
        typer.Option(
            "--map",
            metavar="FILE",
            help="Map file (SQLite) to start from and extend, created if missing; written as the run goes.",
        ),
    ] = None,
    localise_only: Annotated[
        bool, typer.Option("--localise-only", help="Relocalise in the --map and use it; change nothing in it.")
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
        )
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    rows: list[tuple[str, Any]] = [("results", out), ("frames", metrics["frames"])]
    if "ate_rmse_m" in metrics:
        rows += [(f"ATE {name} [m]", value) for name, value in metrics["ate_rmse_m"].items()]
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
    _say(_table(rows))


@app.command()
def detect(
    data: Annotated[Path, typer.Argument(help="KITTI root, ROS bag, EuRoC recording or folder of stereo images.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Detections file to write (JSON lines).")],
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under the root, e.g. 06.")] = None,
    left_topic: LeftTopicOption = None,
    right_topic: RightTopicOption = None,
    calibration: CalibrationOption = None,
    config: ConfigOption = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing file.")] = False,
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
        _fail(error)
    _say(f"wrote {out}: {counts['detections']} detections in {counts['frames']} frames")


@app.command()
def evaluate(
    estimate: Annotated[Path, typer.Argument(help="Estimated trajectory (TUM or KITTI).")],
    groundtruth: Annotated[Path, typer.Argument(help="Ground-truth trajectory (TUM or KITTI).")],
    est_format: Annotated[str, typer.Option("--est-format", help="tum, kitti or auto.")] = "auto",
    gt_format: Annotated[str, typer.Option("--gt-format", help="tum, kitti or auto.")] = "auto",
    align: Annotated[str | None, typer.Option(help="se3, sim3 or none (default: config).")] = None,
    loops: Annotated[Path | None, typer.Option(help="loop_closures.csv to judge against the ground truth.")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Also write the metrics as JSON.")] = None,
    config: ConfigOption = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing --json file.")] = False,
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
            estimate, groundtruth, settings, est_format, gt_format, loops, json_out, [config], overwrite
        )
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    rows = [(key, value) for key, value in metrics.items() if not isinstance(value, dict)]
    rows += [(f"loops {key}", value) for key, value in metrics.get("loops", {}).items()]
    _say(_table(rows))


@app.command()
def route(
    map_file: Annotated[Path, typer.Argument(help="Map file (SQLite) of `neoslam run --map`.")],
    to: Annotated[
        str, typer.Option("--to", help='Goal: "truck", "nearest car", "start", "experience 40", "12.5,-3", ...')
    ],
    out: OutOption,
    start: Annotated[
        str | None, typer.Option("--from", help="Start, in the same words (default: the experience made last).")
    ] = None,
    stale: Annotated[
        bool, typer.Option("--stale", help="A stale object (not seen where it should be) may be the goal.")
    ] = False,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
) -> None:
    """Plan a route on a map to a place or an object and write it (route.csv, route.json, route.png); the map is
    read only. The goal language: docs/navigation.md."""
    from neoslam.commands.route import route_on_map

    try:
        report = route_on_map(map_file, to, out, load_config(config), start, stale, overwrite, read=[config])
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    planned = report.route
    time_s = "unknown (no speed in the map)" if planned.expected_time_s is None else f"{planned.expected_time_s:.1f}"
    rows: list[tuple[str, Any]] = [
        ("route", out),
        ("goal", planned.goal.description),
        ("from", f"experience {planned.start}"),
        ("length [m]", f"{planned.length_m:.1f}"),
        ("expected time [s]", time_s),
        ("waypoints", len(planned)),
        ("objects in map", f"{report.objects} ({report.stale_objects} stale)"),
        ("planning [ms]", f"{report.planning_ms:.2f} (graph built in {report.graph_ms:.1f})"),
    ]
    _say(_table(rows))


@app.command("dump-config")
def dump_config_command(config: ConfigOption = None) -> None:
    """Print the resolved configuration (defaults, then --config, then NEOSLAM_* variables) as YAML."""
    try:
        _say(dump_config(load_config(config)), nl=False)
    except (NeoSLAMError, OSError) as error:
        _fail(error)


@app.command()
def sweep(
    spec: Annotated[Path, typer.Argument(help="Sweep spec (YAML): sources, noise, detectors, seeds, overrides.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Sweep folder: new, or this sweep's (resumed: done cells are kept).")
    ],
    ray: Annotated[
        str | None,
        typer.Option(
            "--ray",
            envvar="RAY_ADDRESS",
            help='Run the cells as Ray tasks on this cluster ("auto", "ray://HOST:10001"); needs neoslam[cluster].',
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Local worker processes (default: one per core; 0: in this process); with --ray, the most "
            "tasks at once."
        ),
    ] = None,
    quiet: QuietOption = False,
) -> None:
    """Run a grid of drives x noise x detection profiles x seeds x config overrides, each cell evaluated and kept,
    into one table (sweep.csv, sweep.parquet) and a summary (summary.md). Rerun to resume."""
    from neoslam.sweep import load_spec, make_executor, run_sweep

    def kept_cells() -> str | None:
        if any((out / "cells").glob("*/metrics.json")):
            return f"the finished cells are kept in {out}/cells: run the same command to resume"
        return None

    try:
        with stopping.stop_note(kept_cells):
            loaded = load_spec(spec)
            result = run_sweep(loaded, out, make_executor(ray, workers), progress=not quiet, read=[spec])
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    _say(result.summary)
    failed = len({r.cell.id for r in result.failed})
    _say(
        f"wrote {out}: {len(result.records)} cells ({result.ran} run, {result.reused} reused, {failed} failed) "
        f"in {result.wall_s:.1f} s; table {result.paths['csv'].name}, {result.paths['parquet'].name}"
    )
    if failed:
        _say(f"neoslam: {failed} cells failed (their errors: the error column of {result.paths['csv']})",
                   err=True)  # fmt: skip
        raise typer.Exit(code=1)


DomainOption = Annotated[
    int | None, typer.Option("--domain-id", help="ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).")
]


@app.command("ros2")
def ros2_command(
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Results folder written when the node stops (optional).")
    ] = None,
    map_path: Annotated[
        Path | None,
        typer.Option("--map", metavar="FILE", help="Map file to start from and extend (created if missing)."),
    ] = None,
    localise_only: Annotated[
        bool, typer.Option("--localise-only", help="Relocalise in the --map and use it; change nothing in it.")
    ] = False,
    domain: DomainOption = None,
    frames: Annotated[int | None, typer.Option(min=1, help="Stop after mapping this many frames.")] = None,
    idle_exit: Annotated[
        float | None,
        typer.Option(min=0.0, metavar="SECONDS", help="Stop when no images came this long after some did."),
    ] = None,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
) -> None:
    """The live node: map a stereo camera's ROS 2 topics (live.* settings: topics, frames, QoS) and publish the
    corrected pose, tf, path, objects, events and status until Ctrl-C or SIGTERM, then commit the map and write
    the results. Needs no ROS installation (Cyclone DDS: pip install "neoslam\\[ros2]")."""
    from neoslam.commands.ros2 import domain_id, run_node

    def warn(line: str) -> None:
        _say(f"neoslam: warning: {line}", err=True)

    def inform(line: str) -> None:
        _say(f"neoslam: {line}", err=True)

    try:
        settings = load_config(config)
        chosen = domain_id(domain)
        metrics = run_node(
            settings, chosen, out, overwrite, [config], map_path, localise_only, frames, idle_exit, warn, inform
        )
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    node = metrics["live"]
    rows: list[tuple[str, Any]] = [("frames mapped", node["frames"]), ("stopped by", node["stopped_by"])]
    rows += [("pairs received", node["pairs_received"]), ("pairs dropped (node busy)", node["pairs_dropped"])]
    if "latency_ms_median" in node:
        rows += [("latency median / p95 [ms]", f"{node['latency_ms_median']} / {node['latency_ms_p95']}")]
    rows += [("loop closures", metrics["loops"]["accepted"]), ("objects in map", metrics["objects"])]
    if out is not None:
        rows.insert(0, ("results", out))
    _say(_table(rows))
    stopping.leave(0)  # everything is written and closed: a stopped node ends now, not after seconds of shutdown


@app.command("ros2-play")
def ros2_play_command(
    data: Annotated[Path, typer.Argument(help="KITTI root, ROS bag, EuRoC recording or folder of stereo images.")],
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under a KITTI odometry root.")] = None,
    rate: Annotated[float | None, typer.Option(help="Frames a second (default: as fast as they can be sent).")] = None,
    compressed: Annotated[bool, typer.Option("--compressed", help="Send PNG CompressedImage messages.")] = False,
    frames: Annotated[
        str | None, typer.Option(metavar="START:STOP", help="Play only these frames (Python slice, e.g. 0:20).")
    ] = None,
    wait: Annotated[
        float, typer.Option(min=0.0, metavar="SECONDS", help="First wait up to this long for a subscriber.")
    ] = 0.0,
    left_topic: LeftTopicOption = None,
    right_topic: RightTopicOption = None,
    calibration: CalibrationOption = None,
    domain: DomainOption = None,
    config: ConfigOption = None,
) -> None:
    """Play a recorded stereo sequence on ROS 2 topics as a camera driver would (Image and CameraInfo on the
    live.* topics), for trying the node without a camera."""
    from neoslam.commands.ros2 import domain_id, play
    from neoslam.datasets.opening import ImageInputs

    try:
        settings = load_config(config)
        inputs = ImageInputs(sequence, left_topic=left_topic, right_topic=right_topic, calibration=calibration)
        report = play(data, settings, domain_id(domain), inputs, rate, compressed, wait, frames)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    _say(f"played {report.frames} stereo frames on ROS domain {domain_id(domain)}")


@app.command("ros2-record")
def ros2_record_command(
    topics: Annotated[list[str], typer.Argument(help="Topics to record, e.g. /neoslam/odometry /tf.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="ROS 2 bag folder to write.")],
    storage: Annotated[str, typer.Option(help="Bag storage: sqlite3 or mcap.")] = "sqlite3",
    discovery: Annotated[
        float, typer.Option(min=0.0, metavar="SECONDS", help="How long to wait for the topics to appear.")
    ] = 10.0,
    idle_exit: Annotated[
        float | None,
        typer.Option(min=0.0, metavar="SECONDS", help="Stop when nothing came this long after something did."),
    ] = None,
    domain: DomainOption = None,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
) -> None:
    """Record ROS 2 topics (the node's message types) into a ROS 2 bag until Ctrl-C or SIGTERM."""
    from neoslam.commands.ros2 import domain_id, record

    try:
        settings = load_config(config)
        def ready(found: list[str]) -> None:
            _say(f"neoslam: recording {', '.join(found)} into {out}", err=True)

        report = record(topics, out, domain_id(domain), settings, overwrite, discovery, storage, idle_exit, ready)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    counts = ", ".join(f"{topic} {count}" for topic, count in report.messages.items()) or "nothing"
    _say(f"wrote {out}: {counts}")
    if report.missing:
        _say(f"neoslam: warning: never published: {', '.join(report.missing)}", err=True)


def entry() -> None:
    """The app, stopped cleanly by Ctrl-C, SIGTERM and SIGHUP at any point (see neoslam.stopping)."""
    stopping.install()
    app()


if __name__ == "__main__":  # pragma: no cover
    entry()
