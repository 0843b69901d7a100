"""The `neoslam` command: it parses arguments and calls `neoslam.jobs`, nothing more."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from neoslam import __version__
from neoslam.config import NOISE_PROFILES, dump_config, load_config
from neoslam.errors import ConfigError, NeoSLAMError

app = typer.Typer(
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


def _fail(error: NeoSLAMError | OSError) -> None:
    # OSError: a folder that cannot be written, a disk that is full; the user can fix these too.
    message = f"{error.filename}: {error.strerror}" if isinstance(error, OSError) and error.filename else error
    typer.echo(f"neoslam: error: {message}", err=True)
    raise typer.Exit(code=2)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"neoslam {__version__}")
        raise typer.Exit()


@app.callback()
def main(
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
    from neoslam.io.atomic import check_target
    from neoslam.jobs import record, simulate_dataset, simulation_config

    try:
        if trajectory is not None and route is not None:
            raise ConfigError("give either --trajectory or --route, not both")
        settings = simulation_config(load_config(config), noise, seed, detector)
        check_target(out, overwrite)
        recording = record(settings, trajectory, fmt, times, route, progress=not quiet)
        simulate_dataset(out, recording, overwrite)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    detections = sum(len(d) for d in recording.detections)
    typer.echo(f"wrote {out}: {len(recording.truth)} frames, {detections} detections, {len(recording.world)} objects")


@app.command("run")
def run_command(
    data: Annotated[Path | None, typer.Argument(help="Dataset folder; none runs the default scenario.")] = None,
    out: OutOption = Path("results"),
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under a KITTI odometry root, e.g. 06.")] = None,
    detections: Annotated[
        Path | None,
        typer.Option(help="Detections file (JSON lines, see `neoslam detect`) instead of the built-in detector."),
    ] = None,
    odometry: Annotated[
        Path | None, typer.Option(help="Odometry poses (TUM or KITTI, one per image) instead of stereo odometry.")
    ] = None,
    backend: Annotated[str | None, typer.Option(help="Map correction: relaxation or pose-graph.")] = None,
    config: ConfigOption = None,
    overwrite: OverwriteOption = False,
    quiet: QuietOption = False,
) -> None:
    """Run NeoSLAM on a simulated dataset or a KITTI image sequence and write the results folder (trajectories,
    object map, metrics, plots)."""
    from neoslam.jobs import ImageInputs, run_dataset, with_backend

    try:
        settings = with_backend(load_config(config), backend)
        inputs = ImageInputs(sequence, detections, odometry)
        metrics = run_dataset(data, out, settings, overwrite, progress=not quiet, inputs=inputs)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    rows: list[tuple[str, Any]] = [("results", out), ("frames", metrics["frames"])]
    if "ate_rmse_m" in metrics:
        rows += [(f"ATE {name} [m]", value) for name, value in metrics["ate_rmse_m"].items()]
    rows += [("loop closures", metrics["loops"]["accepted"]), ("objects in map", metrics["objects"])]
    rows += [("frames per second", metrics["timing"]["fps"])]
    if metrics.get("perception"):
        rows += [("perception frames per second (median)", metrics["perception"]["fps_median"])]
    typer.echo(_table(rows))


@app.command()
def detect(
    data: Annotated[Path, typer.Argument(help="KITTI odometry root (sequences/NN/image_0 ...).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Detections file to write (JSON lines).")],
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under the root, e.g. 06.")] = None,
    config: ConfigOption = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing file.")] = False,
    quiet: QuietOption = False,
) -> None:
    """Run the configured detector over a sequence's left images and write the detections in the JSON-lines
    format that `neoslam run --detections` reads."""
    from neoslam.jobs import detect_sequence

    try:
        counts = detect_sequence(data, sequence, out, load_config(config), overwrite, progress=not quiet)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    typer.echo(f"wrote {out}: {counts['detections']} detections in {counts['frames']} frames")


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
) -> None:
    """ATE, RPE and KITTI drift of a trajectory file against ground truth; loop precision and recall."""
    from neoslam.io.results import write_metrics
    from neoslam.jobs import evaluate_files

    try:
        settings = load_config(config)
        if align is not None:
            if align not in ("se3", "sim3", "none"):
                raise ConfigError(f"--align must be se3, sim3 or none, not {align!r}")
            evaluation = settings.evaluation.model_copy(update={"alignment": align})
            settings = settings.model_copy(update={"evaluation": evaluation})
        metrics = evaluate_files(estimate, groundtruth, settings, est_format, gt_format, loops)
        if json_out is not None:
            write_metrics(json_out, metrics)
    except (NeoSLAMError, OSError) as error:
        _fail(error)
    rows = [(key, value) for key, value in metrics.items() if not isinstance(value, dict)]
    rows += [(f"loops {key}", value) for key, value in metrics.get("loops", {}).items()]
    typer.echo(_table(rows))


@app.command("dump-config")
def dump_config_command(config: ConfigOption = None) -> None:
    """Print the resolved configuration (defaults, then --config, then NEOSLAM_* variables) as YAML."""
    try:
        typer.echo(dump_config(load_config(config)), nl=False)
    except (NeoSLAMError, OSError) as error:
        _fail(error)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
