"""Where a live view goes (`--rerun`): the value's checks before any work, the Rerun SDK's import, the viewer's
start.

A bare `--rerun` starts the Rerun viewer (or uses one already listening on Rerun's port) and streams to it;
`--rerun FILE.rrd` records to a file. Without a display the viewer cannot open its window: refused before the run.

The viewer is started here, not with rerun-sdk's `spawn()`: that call holds the GIL while it waits for the viewer to
listen (measured with rerun-sdk 0.41: 6 s for a viewer that dies at start), which freezes every Python thread, the
signal handler's included. Here the wait is Python's own (sleeps, socket connects), which lets other threads run.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import IO, Any

from neoslam.errors import ConfigError

__all__ = [
    "SPAWN",
    "VIEWER_PORT",
    "ViewerStartError",
    "check_rerun_target",
    "has_display",
    "import_rerun",
    "recording_target",
    "start_viewer",
    "viewer_url",
]

SPAWN = "spawn"  # the --rerun value that spawns the viewer instead of recording to a file
INSTALL_HINT = 'pip install "neoslam[viewer]"'
VIEWER_EXECUTABLE = "rerun"  # the viewer, looked up on PATH (the viewer extra installs it)
VIEWER_PORT = 9876  # Rerun's gRPC port: a viewer already listening there is used, as rerun-sdk's spawn() does
VIEWER_ARGS = ("--memory-limit=75%", "--expect-data-soon")  # rerun-sdk's spawn() defaults
VIEWER_START_S = 15.0  # until the viewer listens (rerun-sdk waits 5 s; a loaded machine takes longer)
POLL_S = 0.1
LAST_WORDS_CHARS = 200  # of a viewer that exited at start, quoted in the error
# The variables a Linux (or BSD) desktop sets; the viewer's window library (winit) looks for the same three.
DISPLAY_VARIABLES = ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")
ALWAYS_A_DISPLAY = ("darwin", "win32", "cygwin")  # sys.platform values whose desktop needs no variable
SDK_LOG_FILTER = "off"  # RUST_LOG while the SDK loads: its own stderr lines about a lost sink are replaced by ours

_viewers: list[subprocess.Popen] = []  # the viewers this process started: kept, so that none is reaped too early


class ViewerStartError(RuntimeError):
    """The viewer exited or did not listen in time; the reason as the message."""


def import_rerun() -> Any:
    """The rerun module, or one line saying how to install it. The SDK reads RUST_LOG once, as it loads, and by
    default prints several lines of its own (warnings, errors) when its sink fails; the view reports that in one
    line instead, so the SDK loads with its log off unless the user set RUST_LOG. The variable is restored at once,
    so that a viewer started later logs as the user asked."""
    loaded = sys.modules.get("rerun")
    if loaded is not None:
        return loaded
    quiet = "RUST_LOG" not in os.environ
    if quiet:
        os.environ["RUST_LOG"] = SDK_LOG_FILTER
    try:
        import rerun
    except ImportError:
        raise ConfigError(f"--rerun needs the Rerun viewer, an optional extra: {INSTALL_HINT}") from None
    finally:
        if quiet:
            os.environ.pop("RUST_LOG", None)
    return rerun


def has_display(environ: Mapping[str, str] | None = None, platform: str | None = None) -> bool:
    """Whether a window can be opened: always on macOS and Windows; elsewhere (X11, Wayland) when the desktop's
    variables are set. Defaults: this process's environment and platform."""
    environ = os.environ if environ is None else environ
    platform = sys.platform if platform is None else platform
    return platform in ALWAYS_A_DISPLAY or any(environ.get(name) for name in DISPLAY_VARIABLES)


def check_rerun_target(target: str | None) -> None:
    """Before any work: the --rerun value is SPAWN or a file ending .rrd, a spawned viewer has a display to open
    its window on and its executable on PATH, and Rerun is installed."""
    if target is None:
        return
    if target != SPAWN and not target.endswith(".rrd"):
        raise ConfigError(f"--rerun takes no value (spawn the viewer) or a file ending .rrd, not {target!r}")
    if target == SPAWN and not has_display():
        raise ConfigError(
            "--rerun: no display to open the Rerun viewer on (neither DISPLAY nor WAYLAND_DISPLAY is set); "
            "record to a file with --rerun FILE.rrd and open it where there is one (rerun FILE.rrd)"
        )
    import_rerun()
    if target == SPAWN and shutil.which(VIEWER_EXECUTABLE) is None:
        raise viewer_missing()


def recording_target(target: str | None, out: Path, staging: Path) -> str | None:
    """Where the recording is written: a file inside the results folder goes into its staging folder (the folder
    appears whole, with the recording, when the run is done); any other target is kept."""
    if target is None or target == SPAWN:
        return target
    path, folder = Path(target).resolve(), out.resolve()
    return str(staging / path.relative_to(folder)) if folder in path.parents else target


def viewer_missing() -> ConfigError:
    return ConfigError(
        f"--rerun: the Rerun viewer (`{VIEWER_EXECUTABLE}`) is not on PATH; the viewer extra installs it into the "
        'environment (pip install "neoslam[viewer]", then run with that environment\'s bin folder on PATH), or '
        "record to a file with --rerun FILE.rrd"
    )


def viewer_url(port: int | None = None) -> str:
    """The gRPC address of the viewer on this machine (default: `VIEWER_PORT`)."""
    return f"rerun+http://127.0.0.1:{VIEWER_PORT if port is None else port}/proxy"


def start_viewer(port: int | None = None) -> None:
    """Start the Rerun viewer listening on `port` (default `VIEWER_PORT`) unless one already listens there, and
    wait until it does. The viewer outlives the run (a session of its own: a Ctrl-C of the run leaves its window
    open) and its output stays out of the run's; ViewerStartError with its last line when it exits at start."""
    port = VIEWER_PORT if port is None else port
    if _listening(port):
        return
    executable = shutil.which(VIEWER_EXECUTABLE)
    if executable is None:
        raise viewer_missing()
    with tempfile.TemporaryFile() as said:
        process = subprocess.Popen(
            [executable, f"--port={port}", *VIEWER_ARGS],
            stdin=subprocess.DEVNULL,
            stdout=said,
            stderr=said,
            env={**os.environ, "RERUN_APP_ONLY": "true"},  # as rerun-sdk's spawn(): no analytics prompt
            **_detached(),
        )
        _viewers.append(process)
        deadline = time.monotonic() + VIEWER_START_S
        while not _listening(port):
            status = process.poll()
            if status is not None:
                raise ViewerStartError(f"it exited with status {status}{_last_words(said)}")
            if time.monotonic() > deadline:
                raise ViewerStartError(f"it did not listen on port {port} within {VIEWER_START_S:g} s")
            time.sleep(POLL_S)


def _listening(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=POLL_S).close()
    except OSError:
        return False
    return True


def _detached() -> dict[str, Any]:
    if sys.platform == "win32":
        return {"creationflags": subprocess.CREATE_NEW_PROCESS_GROUP}
    return {"start_new_session": True}


def _last_words(said: IO[bytes]) -> str:
    said.seek(0)
    lines = said.read().decode(errors="replace").strip().splitlines()
    return f": {lines[-1][:LAST_WORDS_CHARS]}" if lines else ""
