"""How the `neoslam` command stops on Ctrl-C, SIGTERM or SIGHUP, at any moment from its first line.

The handler never raises into the running code: an exception raised in the middle of an extension module's import
(torch, GTSAM, onnxruntime take seconds to load) turns into an ImportError or an abort instead of a clean stop.
It runs the clean-ups of the outputs being written at that moment (a staging folder removed, the parents a run
created), stops the worker processes the command started, prints one line and exits with 128 + the signal's number
(130 for Ctrl-C, 143 for SIGTERM) at once, without the interpreter's shutdown.

A command that must wind down itself, such as the live node that commits its map and writes its results when it is
stopped, runs inside `graceful(event, grace_s)`: there the first signal only sets the event, and the command stops
as above if it has not finished `grace_s` later or on a second signal.

Only the console script installs the handler (`install`); as a library, NeoSLAM leaves the signals alone and an
interrupted call unwinds with KeyboardInterrupt as usual, its outputs removed on the way. Standard library only:
this module is imported before anything heavy.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager, suppress
from dataclasses import dataclass
from itertools import count

__all__ = [
    "STOP_SIGNALS",
    "Graceful",
    "finish",
    "graceful",
    "install",
    "installed",
    "leave",
    "on_stop",
    "published",
    "stop_note",
]

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
DEFAULT_NOTE = "no output written"
FINISHED_NOTE = "after the command had finished: its outputs are complete"
# Extensions whose exit hooks must run: ray's stops the processes of the local cluster it started.
_EXIT_HOOKS_NEEDED = ("ray",)

_cleanups: dict[int, Callable[[], object]] = {}
_notes: dict[int, Callable[[], object]] = {}
_ids = count()
_installed = False
_graceful: Graceful | None = None
_finished = False
_published: list[str] = []  # outputs written whole (neoslam.io.atomic), for the line a stop prints


def installed() -> bool:
    """Whether the console script's handler is in place (False when NeoSLAM is used as a library)."""
    return _installed


def install() -> None:
    """Stop on SIGINT, SIGTERM and SIGHUP from now on: clean up, one line, exit 128 + N."""
    global _installed
    for number in STOP_SIGNALS:
        signal.signal(number, _stop)
    _installed = True


@contextmanager
def _registered(table: dict[int, Callable[[], object]], entry: Callable[[], object]) -> Iterator[None]:
    key = next(_ids)
    table[key] = entry
    try:
        yield
    finally:
        table.pop(key, None)


def leave(code: int = 0) -> None:
    """End the console script at once with `code`, its output flushed, without the interpreter's shutdown (which
    takes seconds once torch, onnxruntime and DDS are loaded): for a command whose every file is written and closed
    and that promised to stop quickly. As a library call (no handler installed) it does nothing."""
    if not _installed:
        return
    for stream in (sys.stdout, sys.stderr):
        with suppress(OSError, ValueError):
            stream.flush()
    os._exit(code)


def finish(code: int) -> None:
    """The console script's command has returned with `code`, every output written and closed: end now, without
    the interpreter's shutdown. That takes a second or more with torch and onnxruntime loaded, and Python gives the
    stop signals back their default action in it, so a Ctrl-C then killed the process with no word. Until the
    process ends a stop says the outputs are complete. Where an extension's exit hook must run (ray's), the
    shutdown runs as usual. As a library call (no handler installed) it does nothing."""
    global _finished
    if not _installed:
        return
    _finished = True
    if any(name in sys.modules for name in _EXIT_HOOKS_NEEDED):
        return
    leave(code)


def published(path: object) -> None:
    """An output is written whole: a stop from now on names it instead of saying "no output written" (the console
    script only: a library's stops are its caller's)."""
    if _installed:
        _published.append(str(path))


def on_stop(cleanup: Callable[[], None]) -> AbstractContextManager[None]:
    """Run `cleanup` if the command is stopped while the body runs (latest first, with the others registered)."""
    return _registered(_cleanups, cleanup)


def stop_note(note: Callable[[], str | None]) -> AbstractContextManager[None]:
    """While the body runs, a stop prints `note()` after the reason instead of "no output written" (None: keep it):
    what a stopped command leaves, such as a sweep's finished cells."""
    return _registered(_notes, note)


@dataclass
class Graceful:
    """A command winding down itself: the event a first stop signal sets, the grace it then has, and the signal."""

    event: threading.Event
    grace_s: float
    signum: int | None = None
    timer: threading.Timer | None = None


@contextmanager
def graceful(event: threading.Event, grace_s: float) -> Iterator[Graceful]:
    """While the body runs, a stop signal sets `event` (and the yielded record's `signum`) and the body winds down
    itself; it is stopped as any command is `grace_s` seconds after the signal if it has not left the body by then,
    or at a second signal. Without the console script's handler (a library call) no signal reaches it: Ctrl-C
    raises KeyboardInterrupt as usual."""
    global _graceful
    state = Graceful(event, grace_s)
    _graceful = state
    try:
        yield state
    finally:
        _graceful = None
        if state.timer is not None:
            state.timer.cancel()


def _stop(signum: int, _frame: object) -> None:
    state = _graceful
    if state is not None and state.signum is None:
        state.signum = signum
        state.event.set()
        state.timer = threading.Timer(state.grace_s, _stop_now, args=(signum,))
        state.timer.daemon = True
        state.timer.start()
        return
    _stop_now(signum)


def _stop_now(signum: int) -> None:
    if threading.current_thread() is threading.main_thread():  # (a graceful stop's timer cannot, nor needs to)
        for number in STOP_SIGNALS:  # a second Ctrl-C must not cut the clean-up short
            signal.signal(number, signal.SIG_IGN)
    for key in sorted(_cleanups, reverse=True):
        with suppress(Exception):
            _cleanups[key]()
    _stop_children()
    note = FINISHED_NOTE if _finished else DEFAULT_NOTE
    if _published and not _finished:
        note = f"wrote {', '.join(_published)} before it stopped"
    for key in sorted(_notes, reverse=True) if not _finished else ():
        with suppress(Exception):
            given = _notes[key]()
            if given:
                note = given
                break
    why = "interrupted" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}"
    with suppress(OSError):
        sys.stdout.flush()
    start = "\n" if _progress_bar_open() else ""  # a bar's line ends in no newline: the note gets its own line
    with suppress(OSError):
        os.write(2, f"{start}neoslam: {why}; {note}\n".encode(errors="backslashreplace"))
    os._exit(128 + signum)


def _progress_bar_open() -> bool:
    """Whether a tqdm progress bar is on stderr now (tqdm is looked up, never imported, here)."""
    tqdm_module = sys.modules.get("tqdm.std")
    return bool(tqdm_module is not None and getattr(tqdm_module.tqdm, "_instances", None))


def _stop_children() -> None:
    """The worker processes this command started (a sweep's pool) end with it, not after their current task."""
    multiprocessing = sys.modules.get("multiprocessing")
    if multiprocessing is None:
        return
    with suppress(Exception):
        for child in multiprocessing.active_children():
            child.kill()
