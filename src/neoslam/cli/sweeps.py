"""The `sweep` command: many drives, noise and detection profiles, seeds and settings, into one table."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from neoslam import stopping
from neoslam.cli.app import app
from neoslam.cli.common import QuietOption, fail, say
from neoslam.errors import NeoSLAMError

__all__ = ["sweep"]


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
        if any(not p.parent.name.startswith(".") for p in (out / "cells").glob("*/metrics.json")):  # staging: hidden
            return f"the finished cells are kept in {out}/cells: run the same command to resume"
        return None

    try:
        with stopping.stop_note(kept_cells):
            loaded = load_spec(spec)
            result = run_sweep(loaded, out, make_executor(ray, workers), progress=not quiet, read=[spec])
    except (NeoSLAMError, OSError) as error:
        fail(error)
    say(result.summary)
    failed = len({r.cell.id for r in result.failed})
    say(
        f"wrote {out}: {len(result.records)} cells ({result.ran} run, {result.reused} reused, {failed} failed) "
        f"in {result.wall_s:.1f} s; table {result.paths['csv'].name}, {result.paths['parquet'].name}"
    )
    if failed:
        say(f"neoslam: {failed} cells failed (their errors: the error column of {result.paths['csv']})",
                   err=True)  # fmt: skip
        raise typer.Exit(code=1)
