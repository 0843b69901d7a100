"""One task of a sweep, run wherever an executor puts it: make or open the dataset once, run each of its cells in a
temporary folder, and return each cell's metrics (or its one-line error), timing and, if asked, its results folder
packed as bytes. A task writes nothing outside its temporary folder: the sweep's process stores what it returns, so a
cell that ran on another machine is stored as one that ran here.

Heavy modules (torch, the pipeline) are imported inside the functions, after a worker has limited its threads."""

from __future__ import annotations

import ctypes
import io
import json
import os
import shutil
import signal
import socket
import sys
import tarfile
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from neoslam.errors import NeoSLAMError
from neoslam.sweep.cells import Cell, Source, code_version

__all__ = ["Task", "Outcome", "Measure", "run_task", "run_pipeline", "single_threaded", "one_line"]

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent ends

# measure(dataset, config, out, inputs) -> metrics (a JSON-able dict). `out` is a fresh path a measure may write its
# results folder to (kept when the spec keeps results); `inputs` the ImageInputs of a dataset source.
Measure = Callable[..., dict[str, Any]]


@dataclass(frozen=True)
class Task:
    """Cells that share one dataset (one simulation, or one dataset folder), run one after another."""

    source: Source
    cells: list[Cell]
    keep_results: bool = False
    measure: Measure | None = None  # None: run_pipeline
    code_version: str | None = None  # set: refuse to run under other code (a cluster's workers)


@dataclass
class Outcome:
    cell_id: str
    metrics: dict[str, Any] | None
    error: str | None = None
    detail: str | None = None  # the traceback, kept in the cell's folder
    timing: dict[str, Any] = field(default_factory=dict)
    results: bytes | None = None  # the results folder as a tar.gz


def single_threaded() -> None:
    """One thread per cell: a sweep runs one cell per core, and a cell's numbers must not depend on where it ran
    (the thread count can change the order of floating-point sums)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    import torch

    torch.set_num_threads(1)


def worker_init(parent: int | None = None) -> None:
    """A local pool worker: Ctrl-C reaches the whole process group; the sweep's process alone handles it. SIGTERM
    ends the worker with its task's temporary folder; so does the end of `parent`, the sweep's process, however it
    ended (killed with SIGKILL, it cannot end its workers itself)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _end_worker)
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    if parent is not None:
        _end_with(parent)


_working_in: list[str] = []  # the temporary folder of the task this process runs


def _end_worker(signum: int, _frame: object) -> None:
    for folder in _working_in:
        shutil.rmtree(folder, ignore_errors=True)
    os._exit(128 + signum)


def _end_with(parent: int) -> None:
    """SIGTERM to this process when `parent` ends: from the kernel on Linux (PR_SET_PDEATHSIG), elsewhere from a
    thread that looks for a new parent twice a second. The kernel's signal follows the parent's thread that started
    this process: the pool starts its workers from the thread that then waits for them."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            if libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) == 0:
                if os.getppid() != parent:  # it ended before the kernel was told
                    os.kill(os.getpid(), signal.SIGTERM)
                return
        except (OSError, AttributeError):
            pass
    threading.Thread(target=_watch_parent, args=(parent,), name="end-with-parent", daemon=True).start()


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os.kill(os.getpid(), signal.SIGTERM)


def one_line(error: BaseException, replacements: dict[str, str] | None = None) -> str:
    """The error as the CLI would print it, with temporary paths replaced by what the user named."""
    if isinstance(error, OSError) and error.filename:
        text = f"{error.filename}: {error.strerror}"
    elif isinstance(error, NeoSLAMError):
        text = str(error)
    else:
        text = f"{type(error).__name__}: {error}"
    for temporary, original in (replacements or {}).items():
        text = text.replace(temporary, original)
    return " ".join(text.split()) or type(error).__name__


def run_pipeline(dataset: Path, config, out: Path, inputs) -> dict[str, Any]:
    """The default measurement: `neoslam run` on the dataset (results folder at `out`), its metrics."""
    from neoslam.commands.run import run_dataset

    return run_dataset(dataset, out, config, progress=False, inputs=inputs)


def _plain(value: Any) -> Any:
    """numpy scalars and arrays in a measure's metrics, as JSON takes them."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"a measure returned {type(value).__name__}, which JSON cannot hold")


def _first_lines(data: bytes, count: int) -> bytes:
    """The file up to its `count`-th pose line (comments kept): line numbers in messages stay the original's."""
    kept, poses = [], 0
    for line in data.splitlines(keepends=True):
        kept.append(line)
        stripped = line.strip()
        if stripped and not stripped.startswith(b"#"):
            poses += 1
            if poses == count:
                break
    return b"".join(kept)


def _simulate(source: Source, config, folder: Path, names: dict[str, str]) -> Path:
    """The source's simulated dataset, written to folder/dataset."""
    from neoslam.commands.simulate import record, simulate_dataset

    if source.kind == "route":
        if source.frames is None:
            recording = record(config, route=source.route)
        else:
            import numpy as np

            from neoslam.sim.routes import ROUTES, drive_route
            from neoslam.sim.simulator import simulate

            sim, route = config.simulator, ROUTES[source.route]
            truth = drive_route(route, sim.frame_period, sim.camera.height_above_ground)
            truth = truth.subset(np.arange(min(source.frames, len(truth))))
            recording = simulate(truth, sim, name=source.route, source=f"route:{source.route}", route=route)
    else:
        inputs = folder / "input"
        inputs.mkdir()
        poses = inputs / source.path.name
        data = source.data if source.frames is None else _first_lines(source.data, source.frames)
        poses.write_bytes(data)
        names[str(poses)] = str(source.path)
        times = None
        if source.times_data is not None:
            times = inputs / ("times-" + source.times.name)
            times_data = source.times_data
            times.write_bytes(times_data if source.frames is None else _first_lines(times_data, source.frames))
            names[str(times)] = str(source.times)
        recording = record(config, trajectory=poses, fmt=source.fmt, times=times)
    simulate_dataset(folder / "dataset", recording)
    return folder / "dataset"


def _pack(folder: Path) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        for path in sorted(folder.rglob("*")):
            archive.add(path, arcname=str(path.relative_to(folder)), recursive=False)
    return buffer.getvalue()


def _failed(cell: Cell, error: BaseException, names: dict[str, str], timing: dict[str, Any]) -> Outcome:
    detail = "".join(traceback.format_exception(error))
    for temporary, original in names.items():
        detail = detail.replace(temporary, original)
    return Outcome(cell.id, None, one_line(error, names), detail, dict(timing))


@contextmanager
def _working(folder: str) -> Iterator[None]:
    _working_in.append(folder)
    try:
        yield
    finally:
        _working_in.remove(folder)


def run_task(task: Task) -> list[Outcome]:
    """Run the task's cells; an error fails its cell (or, while making the dataset, all of them), never the task."""
    single_threaded()
    where = {"host": socket.gethostname(), "pid": os.getpid()}
    if task.code_version is not None and task.code_version != code_version():
        problem = RuntimeError(
            f"this worker runs neoslam {code_version()}, the sweep {task.code_version}: install the same version"
        )
        return [_failed(cell, problem, {}, where) for cell in task.cells]
    from neoslam.datasets.opening import ImageInputs

    measure = task.measure or run_pipeline
    source = task.source
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="neoslam-sweep-") as temporary, _working(temporary):
        folder = Path(temporary)
        names: dict[str, str] = {}
        start = time.perf_counter()
        try:
            if source.simulated:
                dataset = _simulate(source, task.cells[0].config, folder, names)
                inputs = ImageInputs()
            else:
                dataset = source.path
                inputs = ImageInputs(source.sequence, source.detections, source.odometry)
        except Exception as error:
            return [_failed(cell, error, names | {temporary: "<cell>"}, where) for cell in task.cells]
        names[temporary] = "<cell>"
        simulate_s = time.perf_counter() - start
        for cell in task.cells:
            out = folder / cell.id
            timing = where | {"simulate_s": round(simulate_s, 3), "cells_sharing_dataset": len(task.cells)}
            start = time.perf_counter()
            try:
                metrics = json.loads(json.dumps(measure(dataset, cell.config, out, inputs), default=_plain))
                results = _pack(out) if task.keep_results and out.is_dir() else None
            except Exception as error:
                timing["wall_s"] = round(time.perf_counter() - start, 3)
                outcomes.append(_failed(cell, error, names, timing))
                continue
            finally:
                shutil.rmtree(out, ignore_errors=True)
            timing["wall_s"] = round(time.perf_counter() - start, 3)
            outcomes.append(Outcome(cell.id, metrics, timing=timing, results=results))
    return outcomes
