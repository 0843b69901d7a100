"""The hostile suite: what a careful but unlucky user does to NeoSLAM (special files, signals at any moment, bytes
that are no format at all), each as a test that makes real files and, where a hang or a lost file is the risk, a
real process with a time limit."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

HANG_LIMIT_S = 60  # a refusal takes the CLI's start-up and a moment; a hang meets this limit instead


class ProcessCLI:
    """The CLI in a process of its own (the console script's entry, `python -m neoslam`), with a time limit."""

    @staticmethod
    def run(*args: object, cwd: Path | None = None, timeout: float = HANG_LIMIT_S) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "neoslam", *(os.fspath(a) for a in args)]
        return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=os.environ.copy())

    @staticmethod
    def refused(result: subprocess.CompletedProcess, *parts: str) -> str:
        """Exit code 2, one line on stderr naming every part, no traceback; returns the line."""
        assert "Traceback" not in result.stderr, result.stderr
        lines = result.stderr.splitlines()
        assert result.returncode == 2, (result.returncode, result.stderr)
        assert len(lines) == 1 and lines[0].startswith("neoslam: error: "), result.stderr
        for part in parts:
            assert part in lines[0], (part, lines[0])
        return lines[0]


@pytest.fixture(scope="session")
def process_cli() -> ProcessCLI:
    return ProcessCLI()


@pytest.fixture
def fifo(tmp_path: Path):
    """`fifo(name)`: a named pipe in the test's folder (nothing ever writes to it: a reader would block)."""

    def make(name: str) -> Path:
        path = tmp_path / name
        os.mkfifo(path)
        return path

    return make


@pytest.fixture
def zero_link(tmp_path: Path):
    """`zero_link(name)`: a symbolic link to /dev/zero (endless bytes: a reader without a bound reads forever)."""

    def make(name: str) -> Path:
        path = tmp_path / name
        path.symlink_to("/dev/zero")
        return path

    return make
