"""Ctrl-C, SIGTERM or SIGHUP at a random moment of a run's first seconds, while Python imports torch, GTSAM and
onnxruntime: always one line and 128 + the signal's number, and nothing left behind.

A stop that raised an exception into those imports turned into an ImportError, an abort in pybind11 or a
traceback; the console script's handler (neoslam.stopping) exits without raising, from its first line. The
moments are drawn with a fixed seed, so that a failure is repeatable.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPETITIONS = 8  # per signal; the moments spread over the start-up
EARLIEST_S, LATEST_S = 0.05, 3.0  # after Python's own start-up (tens of ms), through the heavy imports and into the run
STOP_WITHIN_S = 10
BAR_SHOWN_S = 5  # the default scenario shows its first bar after 2-3 s of start-up and runs for 10 s or more


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_at_any_moment_of_start_up_is_one_line_and_128_plus_n(tmp_path: Path, stop: signal.Signals) -> None:
    moments = random.Random(f"start-up {stop.name}").sample(
        range(int(EARLIEST_S * 100), int(LATEST_S * 100)), REPETITIONS
    )
    expected = "interrupted" if stop == signal.SIGINT else f"stopped by {stop.name}"
    for moment in sorted(m / 100 for m in moments):
        folder = tmp_path / f"at-{moment:.2f}"
        folder.mkdir()
        command = [sys.executable, "-m", "neoslam", "run", "--out", "results", "-q"]
        process = subprocess.Popen(command, cwd=folder, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
        try:
            time.sleep(moment)
            process.send_signal(stop)
            _, stderr = process.communicate(timeout=STOP_WITHIN_S)
        finally:
            process.kill()
        assert process.returncode == 128 + stop, (moment, process.returncode, stderr)
        assert stderr.splitlines() == [f"neoslam: {expected}; no output written"], (moment, stderr)
        assert list(folder.iterdir()) == [], (moment, list(folder.iterdir()))


def test_a_stop_while_the_progress_bar_shows_prints_its_line_on_a_line_of_its_own(tmp_path: Path) -> None:
    # The bar's line ends in a carriage return, not a newline: without one before it, the note would be glued to it.
    command = [sys.executable, "-m", "neoslam", "run", "--out", "results"]
    process = subprocess.Popen(command, cwd=tmp_path, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        time.sleep(BAR_SHOWN_S)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=STOP_WITHIN_S)
    finally:
        process.kill()
    assert process.returncode == 128 + signal.SIGINT, stderr
    assert stderr.splitlines()[-1] == "neoslam: interrupted; no output written", stderr[-300:]
    assert list(tmp_path.iterdir()) == []


def test_an_open_progress_bar_is_seen_by_the_stop_handler() -> None:
    from tqdm import tqdm

    from neoslam.stopping import _progress_bar_open

    assert not _progress_bar_open()
    with tqdm(total=3, disable=False, file=sys.stderr) as bar:
        bar.update()
        assert _progress_bar_open()
    assert not _progress_bar_open()


@pytest.mark.parametrize("delay_s", [0.0, 0.1, 0.4])
def test_a_signal_once_the_outputs_are_written_never_says_no_output_and_never_kills_silently(
    tmp_path: Path, delay_s: float
) -> None:
    """The command ends as soon as it has returned (no seconds of interpreter shutdown, in which Python gives the
    signals back their default action): a stop after its output appeared finds it gone (exit 0) or says the
    outputs are complete (130), or, between the output's rename and the command's return, names the output."""
    command = [sys.executable, "-m", "neoslam", "simulate", "--route", "block", "--out", "o", "-q"]
    process = subprocess.Popen(command, cwd=tmp_path, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "o").exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        time.sleep(delay_s)
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=STOP_WITHIN_S)
    finally:
        process.kill()
    assert process.returncode in (0, 130), (process.returncode, stderr)
    if process.returncode == 130:
        assert stderr.splitlines()[-1] in (  # after the output's rename, or after the command returned
            "neoslam: interrupted; wrote o before it stopped",
            "neoslam: interrupted; after the command had finished: its outputs are complete",
        ), stderr
    assert (tmp_path / "o" / "dataset.yaml").is_file()
