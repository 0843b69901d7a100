"""What the command modules share: printing a line, failing with one line and exit code 2, a table of results,
and the options several commands take."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from neoslam.errors import NeoSLAMError

__all__ = [
    "FLAG",
    "CalibrationOption",
    "ConfigOption",
    "GoalOption",
    "LeftTopicOption",
    "LocaliseOnlyOption",
    "MapOption",
    "OutOption",
    "OverwriteOption",
    "QuietOption",
    "RerunOption",
    "RightTopicOption",
    "StaleOption",
    "fail",
    "say",
    "table",
]

FLAG = ""  # a flag takes no value: its help shows none (typer would show <bool>)
ConfigOption = Annotated[Path | None, typer.Option("--config", "-c", help="YAML file overriding the defaults.")]
OutOption = Annotated[Path, typer.Option("--out", "-o", help="Output folder (written whole or not at all).")]
OverwriteOption = Annotated[bool, typer.Option("--overwrite", metavar=FLAG, help="Replace a non-empty output folder.")]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", metavar=FLAG, help="No progress bar.")]
LeftTopicOption = Annotated[
    str | None, typer.Option(help="A bag's left camera topic (Image or CompressedImage); found when unambiguous.")
]
RightTopicOption = Annotated[str | None, typer.Option(help="A bag's right camera topic; found when unambiguous.")]
GoalOption = Annotated[
    str | None,
    typer.Option(help='Guide the run to a goal on the map ("truck", "start", ...: docs/navigation.md); guidance.csv.'),
]
StaleOption = Annotated[bool, typer.Option("--stale", metavar=FLAG, help="A stale object may be the --goal.")]
CalibrationOption = Annotated[
    Path | None, typer.Option(metavar="FILE", help="Image folder's calibration (default: its calibration.yaml).")
]


MapOption = Annotated[
    Path | None,
    typer.Option(
        "--map",
        metavar="FILE",
        help="Map file (SQLite) to start from and extend, created if missing; written as the run goes.",
    ),
]
LocaliseOnlyOption = Annotated[
    bool,
    typer.Option("--localise-only", metavar=FLAG, help="Relocalise in the --map and use it; change nothing in it."),
]
RerunOption = Annotated[
    str | None,
    typer.Option(
        "--rerun",
        metavar="[FILE.rrd]",
        # The backslash keeps rich from reading [viewer] as markup.
        help="Show the run live in Rerun: alone, spawn the viewer; with FILE.rrd, record there "
        '(needs pip install "neoslam\\[viewer]").',
    ),
]


MESSAGE_CHARS = 1000  # an error line is cut to this many characters


def say(text: object, err: bool = False, nl: bool = True) -> None:
    """Print a line; a file name that is not UTF-8 (kept by Python as surrogate escapes) is shown with its bytes
    escaped (seq\\xff), where printing it as it is would fail."""
    readable = str(text).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    typer.echo(readable, err=err, nl=nl)


def fail(error: NeoSLAMError | OSError) -> None:
    # OSError: a folder that cannot be written, a disk that is full; the user can fix these too.
    message = f"{error.filename}: {error.strerror}" if isinstance(error, OSError) and error.filename else error
    say(f"neoslam: error: {one_line(str(message))}", err=True)
    raise typer.Exit(code=2)


def one_line(message: str, limit: int = MESSAGE_CHARS) -> str:
    """A message as one line a user reads: line breaks joined, and a value given at any length (a path of
    megabytes) cut in the middle to `limit` characters, its start and end kept."""
    line = " ".join(message.split("\n"))
    if len(line) <= limit:
        return line
    cut = len(line) - limit
    head, tail = line[: limit * 2 // 3], line[len(line) - limit // 3 :]
    return f"{head}...({cut} characters cut)...{tail}"


def table(rows: list[tuple[str, Any]]) -> str:
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)
