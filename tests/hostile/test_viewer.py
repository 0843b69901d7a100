"""A viewer never costs a run: `python -m neoslam run DATA --rerun` in a process of its own, against a viewer that
is not there, fails to start, dies, stops reading or fills its disk.

No display, or a viewer that exits at start: refused before the run, in one line. The viewer killed mid-run, or one
that stops reading (frozen with SIGSTOP, or a server that accepts and never reads), or a recording whose disk fills:
one warning line, exit 0, the results folder whole. A stop signal at a random moment of such a run, or while the run
waits for a viewer that never listens: exit 128 + N within a second of the signal, nothing left behind.

The viewer is the one `--rerun` starts: a stand-in `rerun` first on PATH that runs the real Rerun server
(`rerun --serve-grpc`, no window), a TCP server that never reads, or nothing that listens, on the port it is given
(Rerun's 9876, which these tests take in turn through a lock file). The run's progress bar, read as it comes, says
how far it is. The moments are drawn with a fixed seed, so that a failure is repeatable.
"""

from __future__ import annotations

import json
import os
import random
import re
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import suppress
from pathlib import Path

import numpy as np
import pytest

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals, a shell script as the viewer"),
]

# The town route's first FRAMES frames: over 15 s of run at 150 frames a second (an idle 2-core machine), so that a
# signal STALL_S + 2 s after a tenth of them, or a viewer given up STALL_S after then, finds the run still going.
FRAMES = 2500
VIEWER_PORT = 9876  # where rerun-sdk's spawn() starts the viewer and connects
PORT_WAIT_S = 600  # another session of these tests holds the port meanwhile
RUN_LIMIT_S = 600  # a whole run on a loaded 2-core machine; a hang meets this instead
PROGRESS_SHARE = 0.1  # the viewer fails once the run has done this share of its frames: mid-run
STOP_WITHIN_S = 1.0  # the product's promise: from the signal to the process's exit
STALL_S = 5.0  # neoslam.viz.rerun_sink.STALL_S: a viewer that stops reading is given up after this long
RECORDING_LIMIT_BYTES = 1_000_000  # the disk that fills: a file size limit (the results' files are smaller)
RESULTS = ("metrics.json", "trajectory_tum.txt", "objects.csv", "experience_map.g2o", "config.yaml", "plots")
BAR = re.compile(r"^neoslam:\s+\d+%\|")  # tqdm's bar: "neoslam:  11%|█▏        | 34/300 [00:00<00:06, ...]"
BAR_FRAMES = re.compile(r"\|\s*(\d+)/(\d+) \[")
WARNING = re.compile(
    r"^neoslam: warning: the Rerun viewer went away at frame (\d+) \((.+)\); the run goes on without it$"
)

NEVER_READS = """
import socket, sys
server = socket.socket()
server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
server.bind(("127.0.0.1", int(sys.argv[1])))
server.listen(8)
held = []
while True:
    held.append(server.accept()[0])
"""


@pytest.fixture(scope="module")
def town(cli, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from neoslam.config import NeoSLAMConfig
    from neoslam.config.profiles import simulation_config
    from neoslam.io.trajectory_files import write_tum
    from neoslam.sim.routes import ROUTES, drive_route

    root = tmp_path_factory.mktemp("viewer")
    sim = simulation_config(NeoSLAMConfig(), "vo", 2, "ideal").simulator
    truth = drive_route(ROUTES["town"], sim.frame_period, sim.camera.height_above_ground)
    write_tum(root / "town.txt", truth.subset(np.arange(FRAMES)))
    args = ("--trajectory", root / "town.txt", "--noise", "vo", "--detector", "ideal", "--seed", 2)
    cli.ok("simulate", *args, "--out", root / "data", "-q")
    return root / "data"


class Viewer:
    """The stand-in viewer of one test: `bin` goes first on PATH; `pid()` once the run started it."""

    def __init__(self, root: Path, kind: str) -> None:
        import rerun_cli

        real = Path(rerun_cli.__file__).with_name("rerun")
        if not real.exists():
            pytest.skip(f"the Rerun viewer's binary is not at {real}")
        self.bin, self.pidfile = root / "bin", root / "viewer.pid"
        self.bin.mkdir()
        (root / "never_reads.py").write_text(NEVER_READS)
        serve = {
            "serves": f'exec "{real}" --serve-grpc --port "$PORT" >/dev/null 2>&1',
            "never-reads": f'exec "{sys.executable}" "{root / "never_reads.py"}" "$PORT" >/dev/null 2>&1',
            "dies-at-start": 'echo "Error: no window can be opened" >&2; exit 1',
            "never-listens": "exec sleep 3600",
        }[kind]
        script = self.bin / "rerun"
        script.write_text(
            "#!/bin/sh\n"
            f"PORT={VIEWER_PORT}\n"
            'for arg in "$@"; do case "$arg" in --port=*) PORT="${arg#--port=}";; esac; done\n'
            f'echo $$ > "{self.pidfile}"\n'
            f"{serve}\n"
        )
        script.chmod(0o755)

    def pid(self, timeout_s: float = RUN_LIMIT_S) -> int:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with suppress(FileNotFoundError, ValueError):
                return int(self.pidfile.read_text())
            time.sleep(0.05)
        raise AssertionError("the viewer was never started")

    def signal(self, signum: int) -> None:
        with suppress(ProcessLookupError):
            os.kill(self.pid(), signum)

    def kill(self) -> None:
        if self.pidfile.exists():
            self.signal(signal.SIGKILL)
            self.signal(signal.SIGCONT)  # a stopped process dies once continued


@pytest.fixture
def viewer(tmp_path: Path) -> Iterator[Callable[[str], Viewer]]:
    """`viewer(kind)`: the stand-in `rerun` ("serves", "never-reads", "dies-at-start", "never-listens"); Rerun's
    port is this test's until the end, when the viewer is killed."""
    import fcntl

    lock = open(Path(tempfile.gettempdir()) / f"neoslam-tests-rerun-port-{VIEWER_PORT}.lock", "w")  # noqa: SIM115
    deadline = time.monotonic() + PORT_WAIT_S
    while True:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except BlockingIOError:
            if time.monotonic() > deadline:
                pytest.skip(f"port {VIEWER_PORT} is held by another session of these tests")
            time.sleep(0.5)
    made: list[Viewer] = []
    try:
        with suppress(OSError), socket.create_connection(("127.0.0.1", VIEWER_PORT), timeout=1):
            pytest.skip(f"port {VIEWER_PORT} is in use (a Rerun viewer?)")

        def make(kind: str) -> Viewer:
            root = tmp_path / f"viewer{len(made)}"
            root.mkdir()
            made.append(Viewer(root, kind))
            return made[-1]

        yield make
    finally:
        for one in made:
            one.kill()
        _wait_until_free(VIEWER_PORT)  # the port is the next test's
        lock.close()


def _wait_until_free(port: int) -> None:
    deadline = time.monotonic() + PORT_WAIT_S
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
        except OSError:
            return
        time.sleep(0.1)


class Run:
    """`python -m neoslam run ...` with a progress bar (read as it comes: how far the run is) and the viewer's
    PATH; `lines()` is stderr without the bar's redraws."""

    def __init__(self, cwd: Path, args: list[object], viewer: Viewer | None, limit_bytes: int | None = None) -> None:
        env = {key: value for key, value in os.environ.items() if key != "RUST_LOG"}  # as a user runs it
        if viewer is not None:
            env["PATH"] = f"{viewer.bin}{os.pathsep}{env.get('PATH', '')}"
            env["DISPLAY"] = ":0"  # the stand-in opens no window; the check only asks whether there is a display

        def limit() -> None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

        command = [sys.executable, "-m", "neoslam", "run", *(os.fspath(a) for a in args)]
        self.process = subprocess.Popen(
            command,
            cwd=cwd,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            preexec_fn=limit if limit_bytes is not None else None,
        )
        self._chunks: list[str] = []
        self.frames = 0
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        fd = self.process.stderr.fileno()
        while chunk := os.read(fd, 65536):
            self._chunks.append(chunk.decode(errors="replace"))
            counts = BAR_FRAMES.findall(self._chunks[-1])
            if counts:
                self.frames = int(counts[-1][0])

    def wait_for_frames(self, frames: int) -> None:
        deadline = time.monotonic() + RUN_LIMIT_S
        while self.frames < frames:
            assert self.process.poll() is None, ("the run ended early", self.lines())
            assert time.monotonic() < deadline, "no progress"
            time.sleep(0.02)

    def stop(self, signum: int) -> float:
        """Send `signum`; the seconds from the signal to the process's exit."""
        assert self.process.poll() is None, ("the run ended before the signal", self.lines())
        sent = time.monotonic()
        self.process.send_signal(signum)
        self.process.wait(timeout=RUN_LIMIT_S)
        return time.monotonic() - sent

    def finish(self) -> int:
        self.process.wait(timeout=RUN_LIMIT_S)
        return self.process.returncode

    def lines(self) -> list[str]:
        self._reader.join(timeout=RUN_LIMIT_S)
        text = "".join(self._chunks)
        return [p for line in text.split("\n") for p in line.split("\r") if p.strip() and not BAR.match(p)]

    def kill(self) -> None:
        with suppress(ProcessLookupError):
            self.process.kill()


def _one_warning(run: Run) -> tuple[int, str]:
    lines = run.lines()
    assert not any("Traceback" in line for line in lines), lines
    assert len(lines) == 1 and WARNING.match(lines[0]), lines  # exactly one line, ours: not one of the SDK's
    frame, reason = WARNING.match(lines[0]).groups()
    return int(frame), reason


def _whole(out: Path) -> dict:
    for name in RESULTS:
        assert (out / name).exists(), name
    return json.loads((out / "metrics.json").read_text())


def test_without_a_display_a_bare_rerun_is_refused_before_the_run(
    process_cli, town: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for variable in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(variable, raising=False)
    result = process_cli.run("run", town, "--rerun", "--out", tmp_path / "out", "-q")
    process_cli.refused(result, "no display", "--rerun FILE.rrd")
    assert not (tmp_path / "out").exists()


def test_a_viewer_that_fails_to_start_is_refused_before_the_run(viewer, town: Path, tmp_path: Path) -> None:
    run = Run(tmp_path, [town, "--rerun", "--out", tmp_path / "out", "-q"], viewer("dies-at-start"))
    try:
        assert run.finish() == 2
    finally:
        run.kill()
    assert run.lines() == [
        "neoslam: error: --rerun: the Rerun viewer did not start (it exited with status 1: Error: no window can be "
        "opened); record to a file with --rerun FILE.rrd"
    ]
    assert not (tmp_path / "out").exists()


def test_a_viewer_killed_mid_run_costs_one_warning_line(viewer, town: Path, tmp_path: Path) -> None:
    shown = viewer("serves")
    run = Run(tmp_path, [town, "--rerun", "--out", tmp_path / "out"], shown)
    try:
        run.wait_for_frames(int(FRAMES * PROGRESS_SHARE))
        killed_at = run.frames
        shown.signal(signal.SIGKILL)
        assert run.finish() == 0, run.lines()
    finally:
        run.kill()
    frame, reason = _one_warning(run)
    assert killed_at <= frame < FRAMES and "gRPC" in reason, (killed_at, frame, reason)
    assert _whole(tmp_path / "out")["frames"] == FRAMES


def test_a_viewer_that_stops_reading_costs_one_warning_line_and_the_run_exits(
    viewer, town: Path, tmp_path: Path
) -> None:
    frozen = viewer("serves")
    run = Run(tmp_path, [town, "--rerun", "--out", tmp_path / "out"], frozen)
    try:
        run.wait_for_frames(int(FRAMES * PROGRESS_SHARE))
        frozen.signal(signal.SIGSTOP)  # alive, connected, reading nothing: the SDK's writes block
        assert run.finish() == 0, run.lines()  # and at the end, no wait in the SDK's exit hook
    finally:
        run.kill()
    frame, reason = _one_warning(run)
    assert reason == f"no answer for {STALL_S:g} s" and frame < FRAMES, (frame, reason)
    assert _whole(tmp_path / "out")["frames"] == FRAMES


def test_a_recording_whose_disk_fills_costs_one_warning_line(town: Path, tmp_path: Path, extra) -> None:
    extra("rerun", "viewer")
    recording = tmp_path / "run.rrd"
    run = Run(tmp_path, [town, "--rerun", recording, "--out", tmp_path / "out"], None, RECORDING_LIMIT_BYTES)
    try:
        assert run.finish() == 0, run.lines()
    finally:
        run.kill()
    lines = run.lines()
    assert len(lines) == 1 and "Traceback" not in lines[0], lines
    assert lines[0].startswith(f"neoslam: warning: the Rerun recording {recording} failed at frame "), lines
    assert lines[0].endswith(f"the run goes on without it, {recording} is not written"), lines
    assert _whole(tmp_path / "out")["frames"] == FRAMES
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no recording, whole or partial


# A stop at a random moment: the viewer stops reading mid-run (frozen, or a server that never reads), or never
# listens (the run waits for it, before its first frame); the moments fall before and after the viewer is given up
# (STALL_S after it stopped answering).
STOPS = [
    *[("never-reads", m) for m in (0.0, STALL_S + 1.0)],
    ("frozen", 2.0),
    ("never-listens", 2.0),
]


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("kind,around", STOPS, ids=[f"{kind}-{around:g}s" for kind, around in STOPS])
def test_a_signal_stops_a_run_within_a_second_whatever_its_viewer_does(
    viewer, town: Path, tmp_path: Path, stop: signal.Signals, kind: str, around: float
) -> None:
    moment = around + random.Random(f"viewer {kind} {around} {stop.name}").uniform(0.0, 1.0)
    shown = viewer("serves" if kind == "frozen" else kind)
    folder = tmp_path / "run"
    folder.mkdir()
    run = Run(folder, [town, "--rerun", "--out", "out"], shown)
    try:
        if kind == "never-listens":
            shown.pid()  # the run waits for the viewer to listen, which it never does
        else:
            run.wait_for_frames(int(FRAMES * PROGRESS_SHARE))
            if kind == "frozen":
                shown.signal(signal.SIGSTOP)
        time.sleep(moment)
        stop_s = run.stop(stop)
    finally:
        run.kill()
    print(f"{stop.name} {moment:.2f} s into a {kind} viewer: stopped in {stop_s:.3f} s")  # shown by pytest -rP
    lines = run.lines()
    expected = "interrupted" if stop == signal.SIGINT else f"stopped by {stop.name}"
    assert run.process.returncode == 128 + stop, (moment, run.process.returncode, lines)
    assert stop_s < STOP_WITHIN_S, (kind, moment, stop_s)
    assert lines[-1] == f"neoslam: {expected}; no output written" and not any("Traceback" in x for x in lines), lines
    assert list(folder.iterdir()) == [], (moment, list(folder.iterdir()))
