"""The commands on a map file: `route`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from neoslam.cli.app import app
from neoslam.cli.common import FLAG, ConfigOption, OutOption, OverwriteOption, fail, say, table
from neoslam.config import load_config
from neoslam.errors import NeoSLAMError

__all__ = ["route"]


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
        bool,
        typer.Option("--stale", metavar=FLAG, help="A stale object (not seen where it should be) may be the goal."),
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
        fail(error)
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
    say(table(rows))
