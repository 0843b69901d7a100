"""`python -m neoslam.cli`: the command line, as the `neoslam` console script runs it."""

from __future__ import annotations

from neoslam.cli import entry

entry()
