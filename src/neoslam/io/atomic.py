"""Outputs appear whole or not at all, and never at a user's inputs.

A results folder (or file) is written under a temporary name beside its target and renamed when complete. Before
any work starts the target is checked: not a symbolic link, not the working folder or one of its parents, not an
input nor a folder holding or held by one. The final rename never deletes what another process put there meanwhile
(without `overwrite` the kernel's rename refuses a non-empty folder and `link` refuses an existing file), and a run
that sees another live run writing the same target stops at once. Parent folders are created only for the rename
and removed again when the run fails.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import stat
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from neoslam import stopping
from neoslam.errors import OutputError

__all__ = ["check_target", "check_target_file", "atomic_directory", "atomic_file"]

_PARTIAL = ".partial-"


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold stop signals back while the body runs, then deliver the first one that came to the handler it would have
    met: a second Ctrl-C during the clean-up of the first must not leave a half-removed staging folder. Only the main
    thread can set handlers; elsewhere the body runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    # None: a handler set outside Python, which cannot be restored
    held = [number for number in stopping.STOP_SIGNALS if signal.getsignal(number) is not None]
    previous = {number: signal.signal(number, lambda number, _: arrived.append(number)) for number in held}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if arrived:
            signal.raise_signal(arrived[0])


def _refuse_link(target: Path) -> None:
    if target.is_symlink():
        where = "a dangling symbolic link" if not target.exists() else f"a symbolic link to {target.resolve()}"
        raise OutputError(f"{target}: is {where}; name a real path for the output")


def _refuse_working_folder(target: Path) -> None:
    resolved, here = target.resolve(), Path.cwd().resolve()
    if resolved == here or resolved in here.parents:
        raise OutputError(f"{target}: is the working folder or one of its parents; name a new folder for the output")


def _refuse_inputs(target: Path, inputs: Iterable[Path | None]) -> None:
    """An output that is an input, lies inside an input folder, or holds an input would replace it."""
    resolved = target.resolve()
    for given in inputs:
        if given is None:
            continue
        source = Path(given).resolve()
        if resolved == source:
            raise OutputError(f"{target}: is an input of this run; name another output")
        if source in resolved.parents:
            raise OutputError(f"{target}: lies inside the input {given}; name an output outside it")
        if resolved in source.parents:
            raise OutputError(f"{target}: holds the input {given}; name an output that does not contain it")


def _check_common(target: Path, inputs: Iterable[Path | None]) -> None:
    _refuse_link(target)
    _refuse_inputs(target, inputs)


def check_target(target: Path, overwrite: bool = False, inputs: Iterable[Path | None] = ()) -> None:
    """Refuse an output folder before any long work: a link, the working folder or a parent of it, an input or a
    folder related to one, a file, or a non-empty folder without `overwrite`."""
    _check_common(target, inputs)
    _refuse_working_folder(target)
    if target.exists() and not target.is_dir():
        raise OutputError(f"{target}: exists and is not a folder")
    if target.is_dir() and any(target.iterdir()) and not overwrite:
        raise OutputError(f"{target}: folder exists and is not empty (pass --overwrite to replace it)")


def _refuse_special(target: Path) -> None:
    """Only a regular file is ever replaced: a device (/dev/null), a FIFO or a socket stays what it is."""
    try:
        mode = target.lstat().st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        raise OutputError(f"{target}: is a folder, not a file")
    if not stat.S_ISREG(mode) and not stat.S_ISLNK(mode):
        raise OutputError(f"{target}: is a device, FIFO or socket, not a regular file; name a file to write")


def check_target_file(target: Path, overwrite: bool = False, inputs: Iterable[Path | None] = ()) -> None:
    """Refuse an output file before any long work: a link, an input or a file inside an input folder, a folder,
    anything but a regular file, or an existing file without `overwrite`."""
    _check_common(target, inputs)
    _refuse_special(target)
    if target.exists() and not overwrite:
        raise OutputError(f"{target}: file exists (pass --overwrite to replace it)")


def _make_parents(folder: Path, created: list[Path]) -> None:
    """Create the missing ancestors of an output, outermost first, each added to `created` as it is made."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()][::-1]
    for path in missing:
        path.mkdir()
        created.append(path)


def _remove_created(created: list[Path]) -> None:
    for path in reversed(created):
        with suppress(OSError):  # not empty: something else was put there meanwhile, keep it
            path.rmdir()


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by someone else
        return True
    return True


def _refuse_concurrent_writer(target: Path) -> None:
    """Another live run staging the same target: stop now rather than race it to the rename. A staging of it that a
    killed run left (its process gone: SIGKILL gives no chance to clean up) is removed."""
    stale = []
    for staging in target.parent.glob(f".{target.name}{_PARTIAL}*"):
        pid = staging.name.rsplit("-", 1)[-1]
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        if _process_alive(int(pid)):
            raise OutputError(f"{target}: another run (process {pid}) is writing it; wait for it or name another")
        stale.append(staging)
    for staging in stale:
        if staging.is_dir() and not staging.is_symlink():
            shutil.rmtree(staging, ignore_errors=True)
        else:
            with suppress(OSError):
                staging.unlink()


def _staging_path(target: Path) -> Path:
    return target.parent / f".{target.name}{_PARTIAL}{os.getpid()}"


def _appeared(target: Path) -> OutputError:
    return OutputError(f"{target}: appeared while this run was writing (another run?); nothing was replaced")


def _publish_folder(staging: Path, target: Path, overwrite: bool) -> None:
    if overwrite and target.exists():
        aside = target.parent / f".{target.name}.replaced-{os.getpid()}"
        target.rename(aside)
        try:
            staging.rename(target)
        except BaseException:
            aside.rename(target)
            raise
        shutil.rmtree(aside)
        return
    try:
        staging.rename(target)  # POSIX: replaces an empty folder only
    except OSError as error:
        if error.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise _appeared(target) from None
        raise


def _publish_file(staging: Path, target: Path, overwrite: bool) -> None:
    _refuse_special(target)  # again: what was checked before the work may have been replaced since
    if overwrite:
        os.replace(staging, target)
        return
    try:
        os.link(staging, target)  # fails if the target appeared meanwhile, where a rename would replace it
    except FileExistsError:
        raise _appeared(target) from None
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EXDEV):
            raise
        if target.exists():  # a file system without hard links: check, then rename
            raise _appeared(target) from None
        os.replace(staging, target)
        return
    staging.unlink()


@contextmanager
def atomic_directory(target: Path, overwrite: bool = False, inputs: Iterable[Path | None] = ()) -> Iterator[Path]:
    """Yield a fresh temporary folder beside `target`; on success it replaces `target`, on failure it vanishes
    (with any parent folder this call created). See `check_target` for the targets refused."""
    inputs = list(inputs)
    check_target(target, overwrite, inputs)
    created: list[Path] = []
    staging = _staging_path(target)

    def remove_staging() -> None:
        shutil.rmtree(staging, ignore_errors=True)
        _remove_created(created)

    try:
        with stopping.on_stop(remove_staging):
            _make_parents(target.parent, created)
            _refuse_concurrent_writer(target)
            shutil.rmtree(staging, ignore_errors=True)
            staging.mkdir()
            yield staging
            with _signals_deferred():  # a stop during the rename waits for it; the output is then whole
                _publish_folder(staging, target, overwrite)
                stopping.published(target)
    except BaseException:
        with _signals_deferred():
            remove_staging()
        raise


@contextmanager
def atomic_file(target: Path, overwrite: bool = False, inputs: Iterable[Path | None] = ()) -> Iterator[Path]:
    """Yield a temporary path beside `target`; on success it replaces `target`, on failure it vanishes (with any
    parent folder this call created). See `check_target_file` for the targets refused."""
    inputs = list(inputs)
    check_target_file(target, overwrite, inputs)
    created: list[Path] = []
    staging = _staging_path(target)

    def remove_staging() -> None:
        staging.unlink(missing_ok=True)
        _remove_created(created)

    try:
        with stopping.on_stop(remove_staging):
            _make_parents(target.parent, created)
            _refuse_concurrent_writer(target)
            yield staging
            with _signals_deferred():  # a stop during the rename waits for it; the output is then whole
                _publish_file(staging, target, overwrite)
                stopping.published(target)
    except BaseException:
        with _signals_deferred():
            remove_staging()
        raise
