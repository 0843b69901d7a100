"""A command that winds down itself (`stopping.graceful`): the first stop signal only sets its event; it is stopped
as any command is when it overstays its grace, or at a second signal; `leave` ends the console script at once."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.slow  # real processes

SCRIPT = textwrap.dedent(
    """
    import os, signal, sys, threading, time
    from neoslam import stopping
    stopping.install()
    stop = threading.Event()
    with stopping.graceful(stop, grace_s=float(sys.argv[1])) as state:
        print("ready", flush=True)
        stop.wait(30)
        print(f"wound down after signal {state.signum}", flush=True)
        time.sleep(float(sys.argv[2]))  # the wind-down's own work
    print("done", flush=True)
    stopping.leave(0)
    print("never printed", flush=True)
    """
)


def _start(grace_s: float, work_s: float) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(grace_s), str(work_s)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout.readline().strip() == "ready"
    return process


@pytest.mark.parametrize("number", [signal.SIGINT, signal.SIGTERM])
def test_a_first_signal_lets_the_command_wind_down_and_leave(number: int) -> None:
    process = _start(grace_s=5.0, work_s=0.1)
    process.send_signal(number)
    out, err = process.communicate(timeout=10)
    assert out.splitlines() == [f"wound down after signal {number}", "done"] and err == ""
    assert process.returncode == 0


def test_a_wind_down_that_overstays_its_grace_is_stopped_as_any_command() -> None:
    process = _start(grace_s=0.3, work_s=30.0)
    sent = time.monotonic()
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=10)
    assert time.monotonic() - sent < 2.0
    assert process.returncode == 128 + signal.SIGTERM and "stopped by SIGTERM" in err and "done" not in out


def test_a_second_signal_stops_at_once() -> None:
    process = _start(grace_s=30.0, work_s=30.0)
    process.send_signal(signal.SIGINT)
    time.sleep(0.5)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=10)
    assert process.returncode == 130 and "interrupted" in err
