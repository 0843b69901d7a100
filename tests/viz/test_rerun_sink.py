"""The Rerun sink's thread (neoslam.viz.rerun_sink) against real sinks: a file gets every job however full the queue
is; a live view skips frames rather than wait; a sink that raises, or stops answering, is given up once, with one
call of `on_lost`, and costs the caller a bounded wait; the caller's thread stops on a signal within a second and
the process exits at its end, whatever the sink does (those two in processes of their own, against a TCP server
that accepts the connection and never reads)."""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

SLOW_JOB_S = 0.002
RUN_LIMIT_S = 120  # a probe process's whole life, loaded machine included; a hang meets this instead
STOP_WITHIN_S = 1.0  # the product's promise: from the signal to the process's exit
EXIT_WITHIN_S = 10.0  # from the probe's last line to its exit: the interpreter's shutdown, with the SDK's exit hook
SHORT_STALL_S = 1.0  # the probes' stall verdict (the product's is neoslam.viz.rerun_sink.STALL_S)
QUEUE_PUT_S = 0.5  # a put into the queue, on a loaded machine (the GIL's switch interval, the scheduler)
VERDICT_SLACK_S = 3.0  # the verdict's grace and slices, on a loaded machine


@pytest.fixture(scope="module")
def rr(extra):
    return extra("rerun", "viewer")


def _sink(open_stream, blocking: bool, **kwargs):
    from neoslam.viz.rerun_sink import RerunSink

    lost: list[tuple[int | None, str]] = []
    sink = RerunSink(open_stream, lambda frame, reason: lost.append((frame, reason)), blocking, **kwargs)
    return sink, lost


def _scalar(index: int, value: float, pause_s: float = 0.0):
    def log(recording) -> None:
        import rerun

        time.sleep(pause_s)
        recording.set_time("frame", sequence=index)
        recording.log("value", rerun.Scalars(value))

    return log


def _rows(rr, path: Path) -> int:
    return sum(chunk.num_rows for chunk in rr.chunk.RrdReader(path).stream() if not chunk.is_static)


def test_a_recording_to_a_file_gets_every_job_however_full_the_queue(rr, tmp_path: Path) -> None:
    path = tmp_path / "all.rrd"

    def open_file():
        recording = rr.RecordingStream("test")
        recording.save(path)
        return recording

    sink, lost = _sink(open_file, blocking=True, queue_frames=2)
    sink.start()
    frames = 200
    assert all(sink.submit(i, _scalar(i, float(i), SLOW_JOB_S)) for i in range(frames))
    assert sink.close() and not lost and sink.skipped == 0
    assert _rows(rr, path) == frames


def test_a_live_view_skips_frames_rather_than_wait(rr) -> None:
    release = threading.Event()

    def slow_viewer(recording) -> None:
        release.wait(RUN_LIMIT_S)

    sink, lost = _sink(lambda: rr.RecordingStream("test"), blocking=False, queue_frames=2, stall_s=RUN_LIMIT_S)
    sink.start()
    taken, slowest = [], 0.0
    for i in range(50):
        start = time.monotonic()
        taken.append(sink.submit(i, slow_viewer))
        slowest = max(slowest, time.monotonic() - start)
    release.set()
    assert slowest < QUEUE_PUT_S, slowest  # a queue put, never a wait for the viewer (which would take minutes)
    assert 2 <= sum(taken) <= 3 and sink.skipped == 50 - sum(taken)  # the job under way and a full queue
    assert sink.submit(50, _scalar(50, 1.0), wait=True)  # the final map waits for room
    assert sink.close() and not lost


def test_a_job_that_fails_gives_the_sink_up_once_with_its_error(rr) -> None:
    def broken(recording) -> None:
        raise ValueError("a broken archetype")

    sink, lost = _sink(lambda: rr.RecordingStream("test"), blocking=True)
    sink.start()
    assert sink.submit(0, _scalar(0, 1.0)) and sink.submit(1, broken)
    deadline = time.monotonic() + RUN_LIMIT_S
    while sink.submit(2, _scalar(2, 1.0)) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sink.lost and lost == [(2, "a broken archetype")]  # the frame the caller was at
    assert not sink.submit(3, _scalar(3, 1.0)) and not sink.close() and len(lost) == 1


@pytest.mark.slow
def test_a_viewer_that_never_answers_at_start_is_an_error(rr) -> None:
    from neoslam.viz.rerun_sink import SinkStartError

    port = _free_port()  # nothing listens there

    def open_nowhere():
        recording = rr.RecordingStream("test")
        recording.connect_grpc(f"rerun+http://127.0.0.1:{port}/proxy")
        return recording

    sink, lost = _sink(open_nowhere, blocking=False, stall_s=SHORT_STALL_S)
    start = time.monotonic()
    with pytest.raises(SinkStartError):
        sink.start(timeout_s=RUN_LIMIT_S)
    assert time.monotonic() - start < RUN_LIMIT_S and sink.lost and not lost


@pytest.mark.slow
def test_a_viewer_killed_mid_run_is_given_up_with_the_sdks_reason(rr, tmp_path: Path) -> None:
    port = _free_port()
    with _real_viewer(port) as viewer:

        def open_viewer():
            recording = rr.RecordingStream("test")
            recording.connect_grpc(f"rerun+http://127.0.0.1:{port}/proxy")
            return recording

        sink, lost = _sink(open_viewer, blocking=False, health_every_s=0.1)
        sink.start(timeout_s=RUN_LIMIT_S)
        frame, deadline = 0, time.monotonic() + RUN_LIMIT_S
        while not sink.lost and time.monotonic() < deadline:
            if frame == 20:
                viewer.kill()
                viewer.wait()
            sink.submit(frame, _scalar(frame, 1.0, 0.01))
            frame += 1
        assert len(lost) == 1 and lost[0][0] is not None and 20 <= lost[0][0] < frame, lost
        assert "gRPC" in lost[0][1], lost


# ------------------------------------------------------------------------ a sink that stops reading, in a process

PROBE = r"""
import json, sys, time
import numpy as np
from neoslam import stopping
from neoslam.viz.rerun_view import import_rerun
from neoslam.viz.rerun_sink import RerunSink

port, mode, stall_s = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
if mode == "signal":
    stopping.install()
rr = import_rerun()
say = lambda **kw: print(json.dumps(kw), flush=True)

def open_stream():
    recording = rr.RecordingStream("probe")
    recording.connect_grpc(f"rerun+http://127.0.0.1:{port}/proxy")
    return recording

def image(index):
    def log(recording):
        recording.set_time("frame", sequence=index)
        recording.log("image", rr.Tensor(np.random.default_rng(index).random((200, 200))))  # 320 kB
    return log

sink = RerunSink(open_stream, lambda frame, reason: say(lost=frame, reason=reason), True, stall_s=stall_s)
sink.start()
say(started=True)
slowest, frame = 0.0, 0
while mode == "signal" or not sink.lost:
    start = time.monotonic()
    sink.submit(frame, image(frame))
    slowest = max(slowest, time.monotonic() - start)
    frame += 1
say(slowest=slowest, closed=sink.close(), frames=frame)
"""


@pytest.fixture
def never_reads() -> Iterator[int]:
    """A TCP server that accepts every connection and never reads from it: the sender's writes block once the
    buffers are full (a viewer frozen, a link gone quiet)."""
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held: list[socket.socket] = []

    def accept() -> None:
        while True:
            try:
                held.append(server.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1]
    server.close()
    for connection in held:
        connection.close()


def _probe(port: int, mode: str) -> subprocess.Popen:
    env = {key: value for key, value in os.environ.items() if key != "RUST_LOG"}
    command = [sys.executable, "-c", PROBE, str(port), mode, str(SHORT_STALL_S)]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _next_line(process: subprocess.Popen) -> dict:
    line = process.stdout.readline()
    assert line, process.stderr.read()
    return json.loads(line)


@pytest.mark.slow
def test_a_sink_that_stops_reading_is_given_up_and_the_process_exits(rr, never_reads: int) -> None:
    process = _probe(never_reads, "exit")
    try:
        assert _next_line(process) == {"started": True}
        lost = _next_line(process)
        end = _next_line(process)
        ended = time.monotonic()
        process.wait(timeout=RUN_LIMIT_S)
        exit_s = time.monotonic() - ended
        stderr = process.stderr.read()
    finally:
        process.kill()
    assert lost["reason"] == f"no answer for {SHORT_STALL_S:g} s", lost
    assert end["closed"] is False and end["slowest"] < SHORT_STALL_S + VERDICT_SLACK_S, end  # bounded by the stall
    assert process.returncode == 0 and stderr == "", stderr  # no traceback, not one line of the SDK's own
    assert exit_s < EXIT_WITHIN_S, exit_s  # the SDK's exit hook would wait for the stream forever


@pytest.mark.slow
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_caller_within_a_second_whatever_the_sink(rr, never_reads: int, stop) -> None:
    # Moments before and after the stall verdict: the caller waits for room in the queue, then skips.
    moments = random.Random(f"sink {stop.name}")
    for moment in sorted(moments.uniform(0.0, 2 * SHORT_STALL_S + 1) for _ in range(3)):
        process = _probe(never_reads, "signal")
        try:
            assert _next_line(process) == {"started": True}
            time.sleep(moment)
            assert process.poll() is None
            sent = time.monotonic()
            process.send_signal(stop)
            process.wait(timeout=RUN_LIMIT_S)
            stop_s = time.monotonic() - sent
            stderr = process.stderr.read()
        finally:
            process.kill()
        print(f"{stop.name} {moment:.2f} s into the probe: stopped in {stop_s:.3f} s")  # shown by pytest -rP
        assert process.returncode == 128 + stop, (moment, process.returncode, stderr)
        assert stop_s < STOP_WITHIN_S, (moment, stop_s)
        assert "Traceback" not in stderr and stderr.strip().splitlines()[-1].startswith("neoslam: "), stderr


# ------------------------------------------------------------------------------------------------- helpers


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextmanager
def _real_viewer(port: int) -> Iterator[subprocess.Popen]:
    """The real Rerun server (`rerun --serve-grpc`, no window) listening on `port`; killed at the end."""
    import rerun_cli

    binary = Path(rerun_cli.__file__).with_name("rerun")
    if not binary.exists():
        pytest.skip(f"the Rerun viewer's binary is not at {binary}")
    command = [str(binary), "--serve-grpc", "--port", str(port)]
    viewer = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + RUN_LIMIT_S
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.1)
        yield viewer
    finally:
        viewer.kill()
        viewer.wait()
