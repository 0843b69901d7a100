"""Output folders appear whole or not at all: written under a temporary name, renamed when complete."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from neoslam.errors import OutputError

__all__ = ["check_target", "atomic_directory", "atomic_file"]


def check_target(target: Path, overwrite: bool = False) -> None:
    """Refuse a target that is a file, or a non-empty folder without `overwrite` (before any long work)."""
    if target.exists() and not target.is_dir():
        raise OutputError(f"{target}: exists and is not a folder")
    if target.is_dir() and any(target.iterdir()) and not overwrite:
        raise OutputError(f"{target}: folder exists and is not empty (pass --overwrite to replace it)")


@contextmanager
def atomic_directory(target: Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a fresh temporary folder beside `target`; on success it replaces `target`, on failure it vanishes.

    An existing non-empty `target` is refused unless `overwrite`.
    """
    check_target(target, overwrite)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.partial-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if target.exists():
        shutil.rmtree(target)
    staging.rename(target)


@contextmanager
def atomic_file(target: Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside `target`; on success it replaces `target`, on failure it vanishes.

    An existing `target` is refused unless `overwrite`, and a folder always.
    """
    if target.is_dir():
        raise OutputError(f"{target}: is a folder, not a file")
    if target.exists() and not overwrite:
        raise OutputError(f"{target}: file exists (pass --overwrite to replace it)")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.partial-{os.getpid()}"
    try:
        yield staging
    except BaseException:
        staging.unlink(missing_ok=True)
        raise
    os.replace(staging, target)
