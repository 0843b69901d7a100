"""Run a sweep into a folder, resuming what an earlier run of it left:

```
DIR/
  sweep.json        format neoslam-sweep, version, the sweep's name (a folder holds one sweep)
  spec.yaml         the spec of the last run
  cells/CELL-ID/    one folder per cell, written whole or not at all:
    cell.json         its labels, code version, measurement and resolved config
    metrics.json      what it measured (or error.txt: its one-line error, then the traceback)
    timing.json       wall time, simulation time, host
    results/          its results folder, when the spec keeps results
  sweep.csv         a row per cell, in the spec's order (labels, status, error, metrics; no timing)
  sweep.parquet     the same table
  timing.csv        wall times, frame rates and host per cell
  summary.md        medians and ranges by the spec's columns
```

A cell whose folder holds metrics.json under the same id (inputs, resolved config, code version, measurement) is
not run again; a failed cell is (its error may have been the machine's), and so is a cell whose files do not read
back (cut short by a full disk, edited by hand): a line names the file, and a fresh run replaces its folder.
"""

from __future__ import annotations

import fcntl
import hashlib
import inspect
import io
import json
import os
import shutil
import sys
import tarfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from neoslam.errors import OutputError
from neoslam.io.atomic import atomic_directory, atomic_file, check_target
from neoslam.sweep.cells import DEFAULT_MEASURE, Cell, Plan, axes_that_vary, expand
from neoslam.sweep.executors import Executor, LocalPool
from neoslam.sweep.runner import Measure, Outcome, Task
from neoslam.sweep.spec import Spec
from neoslam.sweep.table import flatten, split_timing, summary_markdown, write_tables

__all__ = ["CellRecord", "SweepResult", "run_sweep", "measure_name", "FORMAT", "VERSION"]

FORMAT, VERSION = "neoslam-sweep", 1
MARKER = "sweep.json"
# What a sweep folder holds, each a file but `cells`: anything else under these names is refused before any work.
OUTPUT_FILES = (MARKER, "spec.yaml", ".lock", "sweep.csv", "sweep.parquet", "timing.csv", "summary.md")
STOPPED = "not run (the sweep was stopped)"


@dataclass(frozen=True)
class CellRecord:
    """A cell of the spec and what its folder holds."""

    cell: Cell
    status: str  # ok, failed
    error: str | None
    metrics: dict[str, Any] | None
    timing: dict[str, Any]
    folder: Path

    @property
    def row(self) -> dict[str, Any]:
        """Labels, status, error and the metrics a cell computes (no timing): a row of sweep.csv."""
        computed, _ = split_timing(flatten(self.metrics or {}))
        head = {"cell": self.cell.id, **self.cell.labels(), "status": self.status, "error": self.error}
        return head | computed

    @property
    def timing_row(self) -> dict[str, Any]:
        _, machine = split_timing(flatten(self.metrics or {}))
        run = {k: v for k, v in self.timing.items() if k != "pid"}
        return {"cell": self.cell.id, **self.cell.labels(), **run, **machine}


@dataclass(frozen=True)
class SweepResult:
    plan: Plan
    records: list[CellRecord]
    ran: int  # cells run now (unique ids)
    reused: int  # cells found done
    paths: dict[str, Path]
    summary: str
    wall_s: float
    notices: list[str] = field(default_factory=list)  # cells found unreadable, run again

    @property
    def failed(self) -> list[CellRecord]:
        return [r for r in self.records if r.status != "ok"]

    @property
    def rows(self) -> list[dict[str, Any]]:
        return [r.row for r in self.records]


def measure_name(measure: Measure | None) -> str:
    """What names a measurement in the cells' ids: the function and a hash of the file that defines it."""
    if measure is None:
        return DEFAULT_MEASURE
    try:
        source = Path(inspect.getsourcefile(measure) or "")
        digest = hashlib.sha256(source.read_bytes()).hexdigest()[:12]
    except (TypeError, OSError):
        source, digest = Path("?"), "unknown"
    return f"{source.name}:{measure.__qualname__}:{digest}"


def _check_folder(out: Path, spec: Spec, inputs: list[Path]) -> None:
    """A new or empty folder, or one holding this sweep (resumed); anything else is refused."""
    check_target(out, overwrite=True, inputs=inputs)
    if not out.is_dir() or not any(out.iterdir()):
        return
    marker = out / MARKER
    if not marker.is_file():
        raise OutputError(f"{out}: folder exists and holds no sweep ({MARKER}); name a new or empty folder")
    try:
        held = json.loads(marker.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, OSError):
        raise OutputError(f"{marker}: not a sweep marker; name another folder") from None
    if not isinstance(held, dict) or held.get("format") != FORMAT:
        raise OutputError(f"{marker}: not a sweep marker; name another folder")
    if held.get("name") != spec.name:
        raise OutputError(f"{out}: holds the sweep {held.get('name')!r}, not {spec.name!r}; name another folder")
    _check_contents(out)


def _check_contents(out: Path) -> None:
    """The names a sweep writes, each what the sweep would make of it: a folder where a table goes (or a link)
    would stop the sweep at its end, after every cell ran."""
    for name in (*OUTPUT_FILES, "cells"):
        path = out / name
        if path.is_symlink():
            raise OutputError(f"{path}: is a symbolic link, not the sweep's; move it away or name another folder")
        if name == "cells" and path.exists() and not path.is_dir():
            raise OutputError(f"{path}: is not a folder, so it holds no cells; move it away or name another folder")
        if name != "cells" and path.is_dir():
            raise OutputError(f"{path}: is a folder, not the sweep's file; move it away or name another folder")


@contextmanager
def _locked(out: Path) -> Iterator[None]:
    """One sweep at a time in a folder."""
    with open(out / ".lock", "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(f"{out}: another sweep is running in this folder; wait for it") from None
        yield


def _dump(path: Path, payload: Any) -> None:
    path.write_text(json.dumps(payload, indent=2) + "\n")


def _write_json(path: Path, payload: Any) -> None:
    with atomic_file(path, overwrite=True) as staging:
        _dump(staging, payload)


def _start_folder(out: Path, spec: Spec) -> None:
    (out / "cells").mkdir(parents=True, exist_ok=True)
    for stale in (out / "cells").glob(".*.partial-*"):  # a killed sweep's half-written cell (the lock is ours)
        shutil.rmtree(stale, ignore_errors=True)
    _write_json(out / MARKER, {"format": FORMAT, "version": VERSION, "name": spec.name})
    with atomic_file(out / "spec.yaml", overwrite=True) as staging:
        staging.write_text(yaml.safe_dump(spec.model_dump(mode="json", exclude_unset=True), sort_keys=False))


def _store(out: Path, plan: Plan, cells: Mapping[str, Cell], outcome: Outcome) -> None:
    cell = cells[outcome.cell_id]
    with atomic_directory(out / "cells" / cell.id, overwrite=True) as staging:
        about = {"id": cell.id, **cell.labels(), "code_version": plan.code_version, "measure": plan.measure}
        _dump(staging / "cell.json", about | {"config": cell.config.model_dump(mode="json")})
        if outcome.metrics is not None:
            _dump(staging / "metrics.json", outcome.metrics)
        else:
            (staging / "error.txt").write_text(f"{outcome.error}\n\n{outcome.detail or ''}")
        _dump(staging / "timing.json", outcome.timing)
        if outcome.results is not None:
            with tarfile.open(fileobj=io.BytesIO(outcome.results), mode="r:gz") as archive:
                archive.extractall(staging / "results", filter="data")


class _Unreadable(Exception):
    """A file of a cell's folder that does not read back as what the sweep wrote."""

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(f"{path}: {problem}")


def _json_object(path: Path) -> dict[str, Any]:
    try:
        value = json.loads(path.read_bytes().decode("utf-8"))
    except OSError as error:
        raise _Unreadable(path, f"cannot be read ({error.strerror})") from None
    except UnicodeDecodeError:
        raise _Unreadable(path, "not text (not UTF-8)") from None
    except json.JSONDecodeError as error:
        raise _Unreadable(path, f"not valid JSON ({error.msg}, line {error.lineno} column {error.colno})") from None
    if not isinstance(value, dict):
        raise _Unreadable(path, f"holds a JSON {type(value).__name__}, not an object")
    return value


def _record(out: Path, cell: Cell) -> CellRecord | None:
    """What the cell's folder holds (None: no cell finished there); _Unreadable when a file of it is damaged."""
    folder = out / "cells" / cell.id
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise _Unreadable(folder, "is not a cell folder")
    timing = _json_object(folder / "timing.json") if (folder / "timing.json").exists() else {}
    if (folder / "metrics.json").exists():
        return CellRecord(cell, "ok", None, _json_object(folder / "metrics.json"), timing, folder)
    if (folder / "error.txt").exists():
        try:
            error = (folder / "error.txt").read_text(errors="replace").split("\n", 1)[0]
        except OSError as problem:
            raise _Unreadable(folder / "error.txt", f"cannot be read ({problem.strerror})") from None
        return CellRecord(cell, "failed", error, None, timing, folder)
    return None


def _discard(folder: Path) -> None:
    """A damaged cell's entry that the fresh run could not replace: a link or a file where its folder goes."""
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        folder.unlink()


def _finished(out: Path, cells: Mapping[str, Cell], notice: Callable[[str], None]) -> tuple[dict, list[str]]:
    """The records of the cells done under these ids (a failed one runs again), and a line for each cell whose
    folder does not read back (it runs again too)."""
    present = set(os.listdir(out / "cells"))
    done: dict[str, CellRecord] = {}
    notices = []
    for cell_id, cell in cells.items():
        if cell_id not in present:
            continue
        try:
            record = _record(out, cell)
        except _Unreadable as error:
            notices.append(f"{error}; running the cell again")
            notice(notices[-1])
            _discard(out / "cells" / cell_id)
            continue
        if record is not None and record.status == "ok":
            done[cell_id] = record
    return done, notices


def _fresh_record(out: Path, cell: Cell) -> CellRecord:
    """The record of a cell this run tried: stored now, or not run if the sweep was stopped."""
    try:
        record = _record(out, cell)
    except _Unreadable as error:
        return CellRecord(cell, "failed", str(error), None, {}, out / "cells" / cell.id)
    return record or CellRecord(cell, "failed", STOPPED, None, {}, out / "cells" / cell.id)


def _to_stderr(message: str) -> None:
    print(f"neoslam: {message}", file=sys.stderr, flush=True)


def _tasks(plan: Plan, cells: list[Cell], workers: int, keep: bool, measure: Measure | None, remote: bool) -> list:
    """Cells that drive one simulated dataset go together (it is made once); groups are split while there are
    fewer tasks than workers."""
    groups: dict[str, list[Cell]] = {}
    for cell in cells:
        groups.setdefault(cell.simulation or cell.id, []).append(cell)
    parts = list(groups.values())
    while len(parts) < workers and any(len(p) > 1 for p in parts):
        largest = max(range(len(parts)), key=lambda i: len(parts[i]))
        group = parts.pop(largest)
        half = (len(group) + 1) // 2
        parts[largest:largest] = [group[:half], group[half:]]
    version = plan.code_version if remote else None
    return [Task(plan.sources[p[0].source], p, keep, measure, version) for p in parts]


def run_sweep(
    spec: Spec,
    out: Path,
    executor: Executor | None = None,
    progress: bool = True,
    measure: Measure | None = None,
    environ: Mapping[str, str] | None = None,
    read: list[Path] | None = None,
    notice: Callable[[str], None] = _to_stderr,
) -> SweepResult:
    """Run the spec's cells that `out` does not hold yet on `executor` (default: a local pool, one worker per core),
    then write the tables. `measure(dataset, config, out, inputs) -> metrics` replaces `neoslam run` per cell (the
    spec's metrics are then its own, unchecked); `environ`: the NEOSLAM_* variables (default the process's); `read`:
    further files the output must not replace (the spec file); `notice`: where a line goes for each cell found
    damaged and run again (default: standard error)."""
    from tqdm import tqdm

    start = time.perf_counter()
    executor = executor or LocalPool()
    plan = expand(spec, environ, measure_name(measure))
    _check_folder(out, spec, [*plan.inputs, *(read or [])])
    out.mkdir(parents=True, exist_ok=True)
    with _locked(out):
        _start_folder(out, spec)
        unique = {cell.id: cell for cell in plan.cells}
        held, notices = _finished(out, unique, notice)
        todo = [cell for cell_id, cell in unique.items() if cell_id not in held]
        tasks = _tasks(plan, todo, executor.workers, spec.keep_results, measure, executor.remote)
        bar = tqdm(total=len(todo), desc=spec.name, unit="cell", disable=not progress, dynamic_ncols=True)
        failed = 0

        def done(outcomes: list[Outcome]) -> None:
            nonlocal failed
            for outcome in outcomes:
                _store(out, plan, unique, outcome)
                failed += outcome.metrics is None
            bar.update(len(outcomes))
            if failed:
                bar.set_postfix(failed=failed)

        try:
            executor.run(tasks, done)
        finally:
            bar.close()
        by_id = held | {cell.id: _fresh_record(out, cell) for cell in todo}
        records = [replace(by_id[cell.id], cell=cell) for cell in plan.cells]
        columns = spec.columns or axes_that_vary(plan.cells)
        bad = sum(r.status != "ok" for r in records)
        title = f"Sweep {spec.name}: {len(records)} cells, {bad} failed"
        summary = summary_markdown(title, [r.row for r in records], columns, spec.metrics)
        paths = write_tables(out, [r.row for r in records], [r.timing_row for r in records], summary)
    return SweepResult(plan, records, len(todo), len(unique) - len(todo), paths, summary,
                       time.perf_counter() - start, notices)  # fmt: skip
