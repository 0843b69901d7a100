"""A 4-cell sweep (the first 200 poses of the block route, noise vo and heavy, seeds 1 and 2) on the local pool and
on a local Ray instance gives the same table bytes; a sweep stopped by Ctrl-C keeps its finished cells and resumes
with the others; a failing cell is recorded with its one-line error while the others complete."""

from __future__ import annotations

import csv
import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from contextlib import suppress
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from neoslam.cli import app
from neoslam.errors import OutputError
from neoslam.sweep import InProcess, LocalPool, RayCluster, load_spec, parse_spec, run_sweep
from neoslam.sweep.cells import code_version
from neoslam.sweep.runner import Task, run_task
from neoslam.sweep.spec import KNOWN_METRICS
from neoslam.sweep.table import flatten, split_timing

SPEC = {
    "name": "tiny",
    "sources": [{"route": "block", "frames": 200}],
    "noise": ["vo", "heavy"],
    "seeds": [1, 2],
    "metrics": ["ate_rmse_m.corrected", "keyframes"],
}
TABLES = ("sweep.csv", "sweep.parquet")


def _environment() -> dict[str, str]:
    """This process's environment without NEOSLAM_* config variables: a CLI run resolves the same configs."""
    return {k: v for k, v in os.environ.items() if not (k.startswith("NEOSLAM_") and "__" in k)}


def _skip_if_the_source_changed() -> None:
    """Other processes (a Ray worker, the CLI) read neoslam's source when they start: edited meanwhile, their cells
    carry another code version, and rightly run again. Nothing to compare then."""
    if code_version.__wrapped__() != code_version():
        pytest.skip("neoslam's source files changed while the test ran")


class Counting(InProcess):
    """This process, counting the cells it runs."""

    def __init__(self) -> None:
        self.cells: list[str] = []

    def run(self, tasks, done) -> None:
        self.cells += [c.id for t in tasks for c in t.cells]
        super().run(tasks, done)


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spec") / "tiny.yaml"
    path.write_text(yaml.safe_dump(SPEC, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def pooled(spec_file: Path, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("pool") / "sweep"
    return out, run_sweep(load_spec(spec_file), out, LocalPool(2), progress=False, environ={})


@pytest.mark.slow
def test_pool_sweep_writes_a_row_per_cell(pooled) -> None:
    out, result = pooled
    assert (result.ran, result.reused, result.failed) == (4, 0, [])
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [(r["noise"], r["seed"]) for r in rows] == [("vo", "1"), ("vo", "2"), ("heavy", "1"), ("heavy", "2")]
    assert {r["status"] for r in rows} == {"ok"} and {r["frames"] for r in rows} == {"200"}
    assert float(rows[2]["ate_rmse_m.odometry"]) > float(rows[0]["ate_rmse_m.odometry"])  # heavy drifts more
    assert not any(c.startswith("timing.") for c in rows[0])  # timing lives in timing.csv
    timing = list(csv.DictReader((out / "timing.csv").open()))
    assert [t["cell"] for t in timing] == [r["cell"] for r in rows] and float(timing[0]["wall_s"]) > 0
    for row in rows:
        folder = out / "cells" / row["cell"]
        assert json.loads((folder / "metrics.json").read_text())["frames"] == 200
        assert json.loads((folder / "cell.json").read_text())["seed"] == int(row["seed"])
        assert not (folder / "results").exists()  # keep_results: false
    import pyarrow.parquet as pq

    table = pq.read_table(out / "sweep.parquet")
    assert table.column_names == list(rows[0])
    assert table.column("ate_rmse_m.corrected").to_pylist() == [float(r["ate_rmse_m.corrected"]) for r in rows]
    summary = (out / "summary.md").read_text()
    assert "| noise | cells | failed | ate_rmse_m.corrected | keyframes |" in summary
    assert result.summary == summary
    assert json.loads((out / "sweep.json").read_text()) == {"format": "neoslam-sweep", "version": 1, "name": "tiny"}


@pytest.mark.slow
def test_the_known_metrics_are_the_numbers_a_run_measures(pooled) -> None:
    metrics = pooled[1].records[0].metrics
    computed, _ = split_timing(flatten(metrics))
    numbers = {k for k, v in computed.items() if not isinstance(v, str)}  # None: a figure the drive did not support
    assert numbers == set(KNOWN_METRICS)


@pytest.mark.slow
def test_ray_gives_the_same_table(pooled, spec_file: Path, tmp_path: Path, extra) -> None:
    ray = extra("ray", "cluster")
    out, _ = pooled
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=100 * 1024**2, log_to_driver=False)
    try:
        # check_code=False: these workers are this machine's; the code check has its own test (below), and other
        # work on this checkout must not fail the comparison.
        executor = RayCluster(check_code=False)
        result = run_sweep(load_spec(spec_file), tmp_path / "ray", executor, progress=False, environ={})
    finally:
        ray.shutdown()
    _skip_if_the_source_changed()
    assert result.ran == 4 and [r.error for r in result.failed] == []
    for name in TABLES:
        assert (tmp_path / "ray" / name).read_bytes() == (out / name).read_bytes(), name
    hosts = {row["host"] for row in csv.DictReader((tmp_path / "ray" / "timing.csv").open())}
    assert hosts  # timing (host, wall time) is kept apart from the compared table


def _live_members(group: int) -> list[int]:
    """Processes of a process group that are still running (zombies left aside)."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == group and fields[0] != "Z":
            members.append(int(stat.parent.name))
    return members


@pytest.mark.slow
def test_interrupted_sweep_resumes_with_the_missing_cells(pooled, spec_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    neoslam = Path(sys.executable).with_name("neoslam")
    command = [str(neoslam), "sweep", str(spec_file), "--out", str(out), "--workers", "1", "--quiet"]
    process = subprocess.Popen(
        command, env=_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    deadline = time.monotonic() + 240
    while not _finished_cells(out) and process.poll() is None:
        assert time.monotonic() < deadline, "no cell finished in time"
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGINT)  # Ctrl-C reaches the whole foreground group: the workers too
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGINT, stderr
    assert "interrupted" in stderr and "run the same command to resume" in stderr
    assert "Traceback" not in stderr
    deadline = time.monotonic() + 20
    while _live_members(process.pid):  # the pool's workers end with it
        assert time.monotonic() < deadline, f"processes left: {_live_members(process.pid)}"
        time.sleep(0.2)
    done = _finished_cells(out)
    assert 1 <= len(done) < 4
    assert not list((out / "cells").glob(".*partial*"))  # only whole cells
    assert not (out / "sweep.csv").exists()  # the tables come when the sweep ends

    _skip_if_the_source_changed()
    executor = Counting()
    result = run_sweep(load_spec(spec_file), out, executor, progress=False, environ={})
    assert len(executor.cells) == 4 - len(done) and not set(executor.cells) & set(done)
    assert (result.ran, result.reused) == (4 - len(done), len(done))
    for name in TABLES:
        assert (out / name).read_bytes() == (pooled[0] / name).read_bytes(), name

    again = Counting()
    run_sweep(load_spec(spec_file), out, again, progress=False, environ={})
    assert again.cells == []  # nothing changed: nothing runs


def _finished_cells(out: Path) -> list[str]:
    """The cells published whole (a cell is written in a hidden staging folder first, which `*` also matches)."""
    return sorted(p.parent.name for p in (out / "cells").glob("*/metrics.json") if not p.parent.name.startswith("."))


def _children(parent: int) -> list[int]:
    """Running processes whose parent is `parent` (zombies left aside)."""
    children = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == parent and fields[0] != "Z":
            children.append(int(stat.parent.name))
    return children


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads the process table from /proc")
def test_workers_end_when_the_sweep_is_killed(spec_file: Path, tmp_path: Path) -> None:
    neoslam = Path(sys.executable).with_name("neoslam")
    command = [str(neoslam), "sweep", str(spec_file), "--out", str(tmp_path / "out"), "--workers", "2", "--quiet"]
    process = subprocess.Popen(command, env=_environment(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while len(workers := _children(process.pid)) < 3:  # two workers and multiprocessing's resource tracker
            assert process.poll() is None and time.monotonic() < deadline, "the workers did not start"
            time.sleep(0.1)
        time.sleep(1.0)  # into their cells
        process.kill()  # SIGKILL: the sweep's process cannot end its workers itself
        process.wait()
        deadline = time.monotonic() + 5
        while left := [pid for pid in workers if _running(pid)]:
            assert time.monotonic() < deadline, f"workers left: {left}"
            time.sleep(0.1)
    finally:
        with suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)  # whatever is left of the group, if the test failed


@pytest.mark.slow
def test_a_deleted_cell_runs_again_alone(pooled, spec_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    shutil.copytree(pooled[0], out)
    gone = sorted((out / "cells").iterdir())[1]
    shutil.rmtree(gone)
    executor = Counting()
    run_sweep(load_spec(spec_file), out, executor, progress=False, environ={})
    assert executor.cells == [gone.name]
    assert (out / "sweep.csv").read_bytes() == (pooled[0] / "sweep.csv").read_bytes()


@pytest.mark.slow
def test_a_failing_cell_is_recorded_and_the_others_complete(tmp_path: Path) -> None:
    poses = [f"{0.1 * i:.1f} {0.5 * i:.2f} 0 0 0 0 0 1" for i in range(40)]
    poses[6] = "0.6 nan 0 0 0 0 0 1"
    (tmp_path / "broken.txt").write_text("\n".join(poses) + "\n")
    values = SPEC | {"noise": ["vo"], "seeds": [1]}
    values["sources"] = [{"trajectory": "broken.txt", "format": "tum"}, *SPEC["sources"]]
    spec = parse_spec(values, "failing.yaml", tmp_path)
    executor = Counting()
    result = run_sweep(spec, tmp_path / "out", executor, progress=False, environ={})
    rows = list(csv.DictReader((tmp_path / "out" / "sweep.csv").open()))
    assert [(r["source"], r["status"]) for r in rows] == [("broken", "failed"), ("block", "ok")]
    error = rows[0]["error"]
    assert error.startswith(f"{tmp_path / 'broken.txt'}:7: ") and "\n" not in error  # the user's file, its line
    assert "neoslam-sweep-" not in error  # never the temporary copy
    assert rows[1]["error"] == "" and float(rows[1]["ate_rmse_m.corrected"]) >= 0
    detail = (tmp_path / "out" / "cells" / rows[0]["cell"] / "error.txt").read_text()
    assert detail.startswith(error + "\n") and "Traceback" in detail
    assert "Failed cells:" in result.summary and error in result.summary
    retried = Counting()
    run_sweep(spec, tmp_path / "out", retried, progress=False, environ={})
    assert retried.cells == [rows[0]["cell"]]  # a failed cell is tried again, a done one is not


def test_a_worker_under_other_code_refuses_its_cells(tmp_path: Path) -> None:
    from neoslam.sweep import expand

    spec = parse_spec(SPEC, "tiny.yaml", tmp_path)
    plan = expand(spec, environ={})
    task = Task(plan.sources["block"], plan.cells[:2], code_version="0.0.1+elsewhere")
    outcomes = run_task(task)
    assert [o.metrics for o in outcomes] == [None, None]
    assert outcomes[0].error.startswith("RuntimeError: this worker runs neoslam ")
    assert "the sweep 0.0.1+elsewhere: install the same version" in outcomes[0].error


def test_cli_keeps_results_and_exits_1_on_failed_cells(tmp_path: Path) -> None:
    (tmp_path / "broken.txt").write_text("0 0 0 0 0 0 0 1\n0.1 0 0 0 1 0 0 1\n")  # not a rotation
    spec = tmp_path / "s.yaml"
    values = {"name": "cli", "sources": [{"trajectory": "broken.txt"}], "keep_results": True}
    spec.write_text(yaml.safe_dump(values))
    runner = CliRunner()
    result = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out"), "--workers", "0", "--quiet"])
    assert result.exit_code == 1, result.output
    assert "1 cells (1 run, 0 reused, 1 failed)" in result.output
    assert "cells failed" in result.output and (tmp_path / "out" / "sweep.csv").is_file()

    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(values | {"name": "another"}))
    refused = runner.invoke(app, ["sweep", str(other), "--out", str(tmp_path / "out"), "--workers", "0"])
    assert refused.exit_code == 2
    assert refused.output.strip() == f"neoslam: error: {tmp_path / 'out'}: holds the sweep 'cli', not 'another'; " \
        "name another folder"  # fmt: skip
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "notes.txt").write_text("mine\n")
    refused = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "busy"), "--workers", "0"])
    assert refused.exit_code == 2 and "holds no sweep" in refused.output
    refused = runner.invoke(app, ["sweep", str(spec), "--out", str(tmp_path), "--workers", "0"])
    assert refused.exit_code == 2 and "holds the input" in refused.output


@pytest.mark.slow
def test_kept_results_come_back_whole(tmp_path: Path) -> None:
    spec = parse_spec(SPEC | {"noise": ["vo"], "seeds": [1], "keep_results": True}, "keep.yaml", tmp_path)
    result = run_sweep(spec, tmp_path / "out", InProcess(), progress=False, environ={})
    results = result.records[0].folder / "results"
    assert (results / "trajectory_tum.txt").is_file() and (results / "plots" / "map_2d.png").is_file()
    assert json.loads((results / "metrics.json").read_text()) == result.records[0].metrics
    with (tmp_path / "out" / ".lock").open("w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)  # another sweep holds the folder
        with pytest.raises(OutputError, match="another sweep is running in this folder"):
            run_sweep(spec, tmp_path / "out", InProcess(), progress=False, environ={})


def test_ray_missing_is_one_line_before_any_work(tmp_path: Path, spec_file: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed
    result = CliRunner().invoke(app, ["sweep", str(spec_file), "--out", str(tmp_path / "out"), "--ray", "auto"])
    assert result.exit_code == 2
    assert result.output.strip() == 'neoslam: error: the --ray option needs Ray: pip install "neoslam[cluster]" ' \
        '(or pip install "ray>=2.9")'  # fmt: skip
    assert not (tmp_path / "out").exists()
    refused = CliRunner().invoke(app, ["sweep", str(spec_file), "--out", str(tmp_path / "out"), "--workers", "-1"])
    assert refused.exit_code == 2 and "--workers must be 0 (this process) or more" in refused.output
