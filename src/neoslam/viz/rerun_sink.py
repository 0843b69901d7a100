"""A Rerun recording stream that a run never waits on for long: one worker thread owns the stream and makes every
call to the Rerun SDK; the caller's thread (the SLAM loop) only hands it jobs through a bounded queue.

Why: the SDK's calls block in native code when its sink stops answering, and a Python signal handler runs only in
the main thread, between bytecodes, so a main thread inside such a call never stops, whatever signal it gets.
Measured with rerun-sdk 0.41: `flush()` (default timeout 1e38 s) waits forever for a spawned viewer that died at
start; `disconnect()` and the SDK's own exit hook (atexit) wait forever for a viewer that accepts the connection and
never reads, and for a file whose disk is full; `connect_grpc()` waits 5 s for a viewer that is not listening. Here
the caller's thread waits only on Python locks and queues, in slices of `WAIT_SLICE_S`, so a stop signal reaches it
within a slice, and never longer than the sink goes on answering. (These calls release the GIL while they wait;
`spawn()` does not, which is why neoslam.viz.rerun_target starts the viewer itself.)

The sink is judged by the worker's calls: one that raises (a severed gRPC connection, a write error) or one that
has not returned `stall_s` after it began means the sink went away. The worker asks the sink for a flush every
`HEALTH_EVERY_S` (a severed connection shows only there) and at the end. A sink that went away is given up once:
`on_lost(frame, reason)` is called, later jobs are dropped, and the SDK's exit hook, which would wait for the
stream, is unregistered (the stream is left to the operating system).

Two ways to meet a full queue: a live viewer (`blocking=False`) skips the frame, so a slow viewer slows nothing; a
recording to a file (`blocking=True`) waits for room while the worker makes progress, so a healthy sink gets every
job, and gives the sink up when it stops answering.
"""

from __future__ import annotations

import queue
import sys
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from typing import Any

from neoslam.errors import NeoSLAMError

__all__ = ["QUEUE_FRAMES", "STALL_S", "RerunSink", "SinkStartError"]

QUEUE_FRAMES = 64  # ~3 s of a camera at 20 Hz; each job holds copies of its frame's data, the map's O(frames)
STALL_S = 5.0  # a call not back in this long: the sink went away (a healthy viewer answers in milliseconds)
START_WAIT_S = 30.0  # opening: a viewer's start (rerun_target.VIEWER_START_S), its connection, a first flush
HEALTH_EVERY_S = 1.0  # how often the worker flushes: the one call that reports a severed connection
WAIT_SLICE_S = 0.1  # the caller's waits: a signal delivered to another thread is seen within a slice
STALL_GRACE_S = 1.0  # the caller's own stall verdict comes after the worker's flush timeout, which says more
ABORT_WAIT_S = 1.0  # a run that failed waits this long for the stream to close before leaving it


class SinkStartError(Exception):
    """The stream could not be opened or its sink did not answer its first flush; the reason as the message."""


_END = object()  # after the last job: flush, close the sink (a file gets its footer)
_ABORT = object()  # stop at once, without the final flush


def _reason(error: BaseException, stall_s: float) -> str:
    text = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
    return f"no answer for {stall_s:g} s" if "timed out" in text.lower() else text


def _forget_sdk_exit_hook() -> None:
    """The SDK flushes its streams in an atexit hook and waits for them: for a sink that stopped answering, forever.
    Without the hook a stream given up on ends with the process."""
    rerun = sys.modules.get("rerun")
    unregister = getattr(rerun, "unregister_shutdown", None)
    if unregister is not None:
        with suppress(Exception):
            unregister()


class RerunSink:
    """`open_stream()` (run in the worker) returns the RecordingStream; `start()` waits until its sink answers;
    `submit(frame, log)` has the worker call `log(stream)`; `close()` after the last frame; `abort()` when the run
    failed. Call these from one thread (the one that drives the run)."""

    def __init__(
        self,
        open_stream: Callable[[], Any],
        on_lost: Callable[[int | None, str], None],
        blocking: bool,
        queue_frames: int = QUEUE_FRAMES,
        stall_s: float = STALL_S,
        health_every_s: float = HEALTH_EVERY_S,
    ) -> None:
        self._open_stream = open_stream
        self._on_lost = on_lost
        self._blocking = blocking
        self._stall_s = stall_s
        self._health_every_s = health_every_s
        self._jobs: queue.Queue[Any] = queue.Queue(maxsize=queue_frames)
        self._started = threading.Event()
        self._finished = threading.Event()
        # Written by the worker, read by the caller (single assignments: atomic under the GIL).
        self._failure: str | None = None
        self._busy_since: float | None = None  # when the worker's current SDK call began
        self._frame: int | None = None  # the latest frame the caller submitted (taken or not): where it noticed
        self._start_error: BaseException | None = None  # what opening the stream raised
        self._lost = False  # the caller's verdict, final
        self.skipped = 0  # frames a full queue left out (live viewer only)
        self._thread = threading.Thread(target=self._work, name="neoslam-rerun", daemon=True)

    # ------------------------------------------------------------------------------------------ caller's thread

    @property
    def lost(self) -> bool:
        """Whether the sink was given up (after which every job is dropped)."""
        return self._lost

    def start(self, timeout_s: float = START_WAIT_S) -> None:
        """Open the stream in the worker and wait until its sink answers a first flush; SinkStartError if it fails
        or does not answer within `timeout_s` (the worker is then left alone). A NeoSLAMError that `open_stream`
        raised (a missing viewer) is raised as it is."""
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self._started.wait(WAIT_SLICE_S):
            if time.monotonic() > deadline:
                self._give_up_silently()
                raise SinkStartError(f"no answer within {timeout_s:g} s")
        if self._failure is not None:
            self._give_up_silently()
            if isinstance(self._start_error, NeoSLAMError):
                raise self._start_error
            raise SinkStartError(self._failure)

    def ready(self, frame: int) -> bool:
        """Whether a job for `frame` submitted now is taken: the sink is healthy and, for a live viewer, the queue
        has room. Lets the caller skip the cost of building a frame's job that would be dropped."""
        self._frame = frame
        if not self._healthy():
            return False
        if self._blocking or not self._jobs.full():
            return True
        self.skipped += 1
        return False

    def submit(self, frame: int, log: Callable[[Any], None], wait: bool = False) -> bool:
        """Hand the worker a frame's job; False when it was not taken (sink given up, or a live viewer's queue
        full). A recording to a file, or a job submitted with `wait` (the final map), waits for room for as long as
        the worker makes progress."""
        self._frame = frame
        if not self._healthy():
            return False
        if not (self._blocking or wait):
            try:
                self._jobs.put_nowait(log)
            except queue.Full:
                self.skipped += 1
                return False
            return True
        return self._put(log)

    def close(self) -> bool:
        """After the last job: wait while the worker drains the queue, flushes and closes the sink; give the sink up
        when it stops answering. True when everything submitted reached the sink."""
        if not self._healthy() or not self._put(_END):
            return False
        while not self._finished.wait(WAIT_SLICE_S):
            if not self._healthy():
                return False
        return self._healthy()

    def abort(self) -> None:
        """The run failed or was interrupted: drop what is queued, let the worker close the stream for a moment,
        then leave it. No warning: the run's own error is what the user needs to see."""
        if self._lost or not self._thread.is_alive():
            return
        self._lost = True
        self._drain()
        with suppress(queue.Full):
            self._jobs.put_nowait(_ABORT)
        deadline = time.monotonic() + ABORT_WAIT_S
        while not self._finished.wait(WAIT_SLICE_S):
            if time.monotonic() > deadline:
                _forget_sdk_exit_hook()
                return

    def _put(self, item: Any) -> bool:
        while True:
            try:
                self._jobs.put(item, timeout=WAIT_SLICE_S)
                return True
            except queue.Full:
                if not self._healthy():
                    return False

    def _healthy(self) -> bool:
        """The caller's verdict: False once the worker failed or one of its calls is overdue (then given up)."""
        if self._lost:
            return False
        reason = self._failure
        busy = self._busy_since
        if reason is None and busy is not None and time.monotonic() - busy > self._stall_s + STALL_GRACE_S:
            reason = f"no answer for {self._stall_s:g} s"
        if reason is None:
            return True
        self._give_up_silently()
        self._on_lost(self._frame, reason)
        return False

    def _give_up_silently(self) -> None:
        self._lost = True
        self._drain()
        with suppress(queue.Full):
            self._jobs.put_nowait(_ABORT)  # a worker that comes back stops at once
        _forget_sdk_exit_hook()

    def _drain(self) -> None:
        with suppress(queue.Empty):
            while True:
                self._jobs.get_nowait()

    # ------------------------------------------------------------------------------------------- worker thread

    def _work(self) -> None:
        try:
            self._busy_since = time.monotonic()
            recording = self._open_stream()
            recording.flush(timeout_sec=self._stall_s)
        except Exception as error:  # whatever the SDK raises, the caller reports it in one line
            # Without its traceback (and those it was raised from) the error holds no frame, so a stream half
            # opened is dropped here, in the worker, never by the caller's thread: the SDK's clean-up can block.
            error.__context__ = error.__cause__ = None
            self._start_error = error.with_traceback(None)
            self._failure = _reason(error, self._stall_s)
            self._busy_since = None
            self._started.set()
            return
        self._busy_since = None
        self._started.set()
        try:
            self._serve(recording)
        finally:
            # The stream's own clean-up (the SDK's __del__: a flush, a disconnect) runs here, never in the caller.
            del recording
            self._finished.set()

    def _serve(self, recording: Any) -> None:
        last_flush = time.monotonic()
        while True:
            job = self._jobs.get()
            if job is _ABORT or self._lost:
                return
            try:
                if job is _END:
                    self._busy_since = time.monotonic()
                    recording.flush(timeout_sec=self._stall_s)
                    recording.disconnect()
                    return
                self._busy_since = time.monotonic()
                job(recording)
                if time.monotonic() - last_flush >= self._health_every_s:
                    self._busy_since = time.monotonic()
                    recording.flush(timeout_sec=self._stall_s)
                    last_flush = time.monotonic()
            except Exception as error:  # any failure of the sink (or of a job) ends the view, not the run
                self._failure = _reason(error, self._stall_s)
                return
            finally:
                self._busy_since = None
