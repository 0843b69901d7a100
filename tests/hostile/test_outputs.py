"""Output folders through the CLI: never at an input, the working folder or a link; never half-written, never over
what another run wrote; SIGINT, SIGTERM and SIGHUP stop a run within a second and leave nothing behind."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from neoslam.errors import OutputError
from neoslam.io.atomic import atomic_directory, atomic_file

STOP_WITHIN_S = 1.0


def _fingerprint(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
        for p in sorted(folder.rglob("*"))
    }


def _no_partials(folder: Path) -> None:
    assert not [p for p in folder.rglob(".*") if "partial" in p.name or "replaced" in p.name]


@pytest.fixture(scope="module")
def dataset(cli, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small simulated dataset (the built-in block route) inside a folder of its own."""
    folder = tmp_path_factory.mktemp("inputs") / "block"
    cli.ok("simulate", "--route", "block", "--seed", "1", "--out", folder, "-q")
    return folder


@pytest.fixture()
def kitti_root(tmp_path: Path) -> Path:
    """A folder that looks like a KITTI odometry root: the output check must refuse before anything is read."""
    root = tmp_path / "kitti"
    (root / "sequences" / "06" / "image_0").mkdir(parents=True)
    (root / "sequences" / "06" / "image_0" / "000000.png").write_bytes(b"image")
    return root


@pytest.mark.slow
@pytest.mark.parametrize("where", ["itself", "parent", "inside"])
def test_run_refuses_an_output_at_its_dataset(cli, dataset: Path, where: str) -> None:
    out = {"itself": dataset, "parent": dataset.parent, "inside": dataset / "results"}[where]
    before = _fingerprint(dataset.parent)
    cli.one_line_error(cli.invoke("run", dataset, "--out", out, "--overwrite", "-q"), str(out), "input")
    assert _fingerprint(dataset.parent) == before


def test_run_refuses_an_output_reached_through_a_link(cli, dataset: Path, tmp_path: Path) -> None:
    link = tmp_path / "link"
    link.symlink_to(dataset.parent, target_is_directory=True)
    before = _fingerprint(dataset)
    cli.one_line_error(cli.invoke("run", link / dataset.name, "--out", dataset, "--overwrite", "-q"), "input")
    assert _fingerprint(dataset) == before


@pytest.mark.parametrize("where", ["root", "inside"])
def test_run_refuses_an_output_at_a_kitti_root(cli, kitti_root: Path, where: str) -> None:
    out = kitti_root if where == "root" else kitti_root / "sequences"
    before = _fingerprint(kitti_root)
    cli.one_line_error(cli.invoke("run", kitti_root, "--sequence", "06", "--out", out, "--overwrite", "-q"), "input")
    assert _fingerprint(kitti_root) == before


def test_detect_refuses_an_output_inside_its_root(cli, kitti_root: Path) -> None:
    out = kitti_root / "sequences" / "06" / "image_0" / "000000.png"
    cli.one_line_error(cli.invoke("detect", kitti_root, "--sequence", "06", "--out", out, "--overwrite", "-q"), "input")
    assert out.read_bytes() == b"image"


def test_simulate_refuses_the_folder_of_its_trajectory(cli, tmp_path: Path) -> None:
    folder = tmp_path / "poses"
    folder.mkdir()
    trajectory = folder / "t.txt"
    trajectory.write_text("".join(f"{i * 0.1} {i} 0 0 0 0 0 1\n" for i in range(20)))
    before = _fingerprint(folder)
    args = ("simulate", "--trajectory", trajectory, "--format", "tum", "--out", folder, "--overwrite", "-q")
    cli.one_line_error(cli.invoke(*args), str(folder), "input")
    assert _fingerprint(folder) == before


def test_run_refuses_an_output_at_its_config_or_detections(cli, dataset: Path, tmp_path: Path) -> None:
    config = tmp_path / "my.yaml"
    config.write_text("seed: 3\n")
    cli.one_line_error(cli.invoke("run", dataset, "--config", config, "--out", config, "--overwrite", "-q"), "input")
    assert config.read_text() == "seed: 3\n"


def test_evaluate_refuses_json_over_an_input(cli, tmp_path: Path) -> None:
    tum = tmp_path / "t.txt"
    tum.write_text("".join(f"{i * 0.1} {i} 0 0 0 0 0 1\n" for i in range(10)))
    cli.one_line_error(cli.invoke("evaluate", tum, tum, "--json", tum), "input")
    assert tum.read_text().count("\n") == 10


@pytest.mark.parametrize("overwrite", [False, True])
def test_the_working_folder_and_its_parents_are_refused(
    cli, dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, overwrite: bool
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text("mine")
    monkeypatch.chdir(work)
    flag = ["--overwrite"] if overwrite else []
    for out in (".", "..", str(work)):
        cli.one_line_error(cli.invoke("run", dataset, "--out", out, *flag, "-q"), "working folder")
    assert (work / "notes.txt").read_text() == "mine" and sorted(p.name for p in work.iterdir()) == ["notes.txt"]


def test_an_empty_working_folder_is_refused_before_the_run(
    cli, dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    cli.one_line_error(cli.invoke("run", dataset, "--out", ".", "-q"), "working folder")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("dangling", [False, True])
def test_a_linked_output_is_refused_before_any_work(cli, dataset: Path, tmp_path: Path, dangling: bool) -> None:
    real = tmp_path / "real"
    if not dangling:
        real.mkdir()
    link = tmp_path / "results"
    link.symlink_to(real, target_is_directory=True)
    start = time.perf_counter()
    cli.one_line_error(cli.invoke("run", dataset, "--out", link, "--overwrite", "-q"), str(link), "symbolic link")
    assert time.perf_counter() - start < 5.0  # refused up front, not after the run (functional bound, not speed)
    assert link.is_symlink() and real.exists() != dangling
    _no_partials(tmp_path)


def test_a_failed_run_leaves_no_parent_folders(cli, tmp_path: Path) -> None:
    missing = tmp_path / "no-such-dataset"
    cli.one_line_error(cli.invoke("run", missing, "--out", tmp_path / "a" / "b" / "c", "-q"), str(missing))
    assert list(tmp_path.iterdir()) == []


def test_a_folder_that_appears_meanwhile_is_not_replaced(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with pytest.raises(OutputError, match="appeared"), atomic_directory(target) as staging:
        (staging / "mine.txt").write_text("mine")
        target.mkdir()
        (target / "theirs.txt").write_text("theirs")
    assert sorted(p.name for p in target.iterdir()) == ["theirs.txt"]
    _no_partials(tmp_path)


def test_a_file_that_appears_meanwhile_is_not_replaced(tmp_path: Path) -> None:
    target = tmp_path / "out.jsonl"
    with pytest.raises(OutputError, match="appeared"), atomic_file(target) as staging:
        staging.write_text("mine")
        target.write_text("theirs")
    assert target.read_text() == "theirs"
    _no_partials(tmp_path)


def _start_default_run(out: Path, cwd: Path) -> subprocess.Popen:
    """The default scenario (simulate the town, run, evaluate): long enough to be stopped in the middle."""
    command = [sys.executable, "-m", "neoslam.cli", "run", "--out", str(out), "-q"]
    return subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_staging(out: Path, process: subprocess.Popen, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not list(out.parent.glob(f".{out.name}.partial-*")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the run never started writing"
        time.sleep(0.05)
    time.sleep(1.0)  # into the simulation and run


@pytest.mark.slow
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_stops_a_run_within_a_second_and_leaves_nothing(tmp_path: Path, stop: signal.Signals) -> None:
    out = tmp_path / "parent" / "results"
    process = _start_default_run(out, tmp_path)
    try:
        _wait_for_staging(out, process)
        sent = time.monotonic()
        process.send_signal(stop)
        _, stderr = process.communicate(timeout=30)
        stopped_s = time.monotonic() - sent
    finally:
        process.kill()
    assert process.returncode == 128 + stop, stderr
    assert stderr.count("\n") == 1 and "no output written" in stderr, stderr
    assert stopped_s < STOP_WITHIN_S, f"took {stopped_s:.2f} s to stop"
    assert list(tmp_path.iterdir()) == []  # neither the results nor the parent folder the run created


@pytest.mark.slow
def test_a_second_run_on_the_same_output_is_refused_while_the_first_writes(tmp_path: Path) -> None:
    out = tmp_path / "results"
    first = _start_default_run(out, tmp_path)
    try:
        _wait_for_staging(out, first)
        second = subprocess.run(
            [sys.executable, "-m", "neoslam.cli", "run", "--out", str(out), "-q"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
            env=os.environ,
        )
        assert second.returncode == 2 and "another run" in second.stderr, second.stderr
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=30)
    finally:
        first.kill()
    assert list(tmp_path.iterdir()) == []


def test_a_staging_left_by_a_killed_run_is_removed_by_the_next_one(tmp_path: Path) -> None:
    """SIGKILL leaves `.OUT.partial-PID` (no clean-up runs): the next run into OUT removes it once its process is
    gone; one of a live process is another run writing, and refused."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "results"
    left = tmp_path / f".results.partial-{dead.pid}"
    (left / "plots").mkdir(parents=True)
    (left / "metrics.json").write_text("{")
    left_file = tmp_path / f".map.db.partial-{dead.pid}"
    left_file.write_bytes(b"half")
    with atomic_directory(out) as staging:
        (staging / "metrics.json").write_text("{}")
    with atomic_file(tmp_path / "map.db") as staging:
        staging.write_bytes(b"whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.db", "results"]
    live = tmp_path / f".again.partial-{os.getppid()}"
    live.mkdir()
    with pytest.raises(OutputError, match="another run"), atomic_directory(tmp_path / "again"):
        pass
    assert live.is_dir()
