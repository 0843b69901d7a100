"""The ROS 2 commands: `ros2` (the live node), `ros2-play` and `ros2-record` (the optional extra `ros2`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from neoslam import stopping
from neoslam.cli.app import app
from neoslam.cli.common import (
    FLAG,
    CalibrationOption,
    ConfigOption,
    GoalOption,
    LeftTopicOption,
    LocaliseOnlyOption,
    MapOption,
    OverwriteOption,
    RerunOption,
    RightTopicOption,
    StaleOption,
    fail,
    say,
    table,
)
from neoslam.config import load_config
from neoslam.errors import NeoSLAMError

__all__ = ["ros2_command", "ros2_play_command", "ros2_record_command"]

DomainOption = Annotated[
    int | None, typer.Option("--domain-id", help="ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).")
]


@app.command("ros2")
def ros2_command(
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Results folder written when the node stops (optional).")
    ] = None,
    map_path: MapOption = None,
    localise_only: LocaliseOnlyOption = False,
    goal: GoalOption = None,
    stale: StaleOption = False,
    rerun: RerunOption = None,
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
        say(f"neoslam: warning: {line}", err=True)

    def inform(line: str) -> None:
        say(f"neoslam: {line}", err=True)

    try:
        settings = load_config(config)
        chosen = domain_id(domain)
        metrics = run_node(
            settings,
            chosen,
            out,
            overwrite,
            [config],
            map_path,
            localise_only,
            frames,
            idle_exit,
            warn,
            inform,
            goal,
            stale,
            rerun,
        )
    except (NeoSLAMError, OSError) as error:
        fail(error)
    node = metrics["live"]
    rows: list[tuple[str, Any]] = [("frames mapped", node["frames"]), ("stopped by", node["stopped_by"])]
    rows += [("pairs received", node["pairs_received"]), ("pairs dropped (node busy)", node["pairs_dropped"])]
    if "latency_ms_median" in node:
        rows += [("latency median / p95 [ms]", f"{node['latency_ms_median']} / {node['latency_ms_p95']}")]
    rows += [("loop closures", metrics["loops"]["accepted"]), ("objects in map", metrics["objects"])]
    if out is not None:
        rows.insert(0, ("results", out))
    say(table(rows))
    stopping.leave(0)  # everything is written and closed: a stopped node ends now, not after seconds of shutdown


@app.command("ros2-play")
def ros2_play_command(
    data: Annotated[Path, typer.Argument(help="KITTI root, ROS bag, EuRoC recording or folder of stereo images.")],
    sequence: Annotated[str | None, typer.Option(help="KITTI sequence under a KITTI odometry root.")] = None,
    rate: Annotated[float | None, typer.Option(help="Frames a second (default: as fast as they can be sent).")] = None,
    compressed: Annotated[
        bool, typer.Option("--compressed", metavar=FLAG, help="Send PNG CompressedImage messages.")
    ] = False,
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
        fail(error)
    say(f"played {report.frames} stereo frames on ROS domain {domain_id(domain)}")


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
            say(f"neoslam: recording {', '.join(found)} into {out}", err=True)

        report = record(topics, out, domain_id(domain), settings, overwrite, discovery, storage, idle_exit, ready)
    except (NeoSLAMError, OSError) as error:
        fail(error)
    counts = ", ".join(f"{topic} {count}" for topic, count in report.messages.items()) or "nothing"
    say(f"wrote {out}: {counts}")
    if report.missing:
        say(f"neoslam: warning: never published: {', '.join(report.missing)}", err=True)
