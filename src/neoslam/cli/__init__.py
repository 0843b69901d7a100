"""The `neoslam` command: it parses arguments and calls `neoslam.commands`, nothing more.

`app` (neoslam.cli.app) holds the commands, which register on it from their modules: `runs` (simulate, run, detect,
evaluate, dump-config), `maps` (route), `sweeps` (sweep) and `live` (ros2, ros2-play, ros2-record); `common` holds
what they share. Importing this package registers them all.
"""

from __future__ import annotations

from neoslam import stopping
from neoslam.cli.app import app

# isort: off
from neoslam.cli import runs, maps, sweeps, live  # registered in this order, the order of `neoslam --help`
# isort: on

__all__ = ["app", "entry", "live", "maps", "runs", "sweeps"]


def entry() -> None:
    """The app, stopped cleanly by Ctrl-C, SIGTERM and SIGHUP at any point (see neoslam.stopping), and ended as soon
    as it returns (`stopping.finish`)."""
    stopping.install()
    try:
        app()
    except SystemExit as done:
        stopping.finish(done.code if isinstance(done.code, int) else 0 if done.code is None else 1)
        raise
