"""The `neoslam` typer app and its root options (`--version`); the commands register on it from their modules."""

from __future__ import annotations

from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from neoslam import __version__
from neoslam.cli.common import FLAG, say

__all__ = ["RERUN_OPTION", "RERUN_SPAWN", "app"]

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


def _version(value: bool) -> None:
    if value:
        say(f"neoslam {__version__}")
        raise typer.Exit()


@app.callback()
def root(
    version: Annotated[
        bool,
        typer.Option("--version", metavar=FLAG, callback=_version, is_eager=True, help="Print the version and exit."),
    ] = False,
) -> None:
    """Neural Object SLAM."""
