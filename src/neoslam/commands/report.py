"""`neoslam report`: one self-contained HTML page of one or several results folders."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from neoslam.errors import InputError
from neoslam.io.atomic import atomic_file, check_target_file
from neoslam.report import RunFolder, read_results, render_report

__all__ = ["write_report"]


def write_report(folders: Sequence[Path], out: Path, overwrite: bool = False) -> int:
    """Write the report of `folders` (results folders of `neoslam run`, shown in this order) to `out`, whole or not
    at all (never over a file of the folders; over an existing file only with `overwrite`); its size in bytes."""
    if not folders:
        raise InputError(out, "a report needs at least one results folder")
    inputs = list(folders)
    check_target_file(out, overwrite, inputs)
    runs = _named_apart([read_results(folder) for folder in folders], folders)
    page = render_report(runs).encode("utf-8")
    with atomic_file(out, overwrite, inputs) as staging:
        staging.write_bytes(page)
    return len(page)


def _named_apart(runs: list[RunFolder], folders: Sequence[Path]) -> list[RunFolder]:
    """Runs whose folders share a name are named with their parent folder too (a/results, b/results), and by
    their place in the list where that is not enough."""
    names = [run.name for run in runs]
    if len(set(names)) == len(names):
        return runs
    longer = [f"{folder.resolve().parent.name}/{run.name}" for run, folder in zip(runs, folders, strict=True)]
    if len(set(longer)) != len(longer):
        longer = [f"{name} ({k})" for k, name in enumerate(longer, start=1)]
    return [replace(run, name=name) for run, name in zip(runs, longer, strict=True)]
