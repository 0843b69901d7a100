"""What every benchmark shares: its arguments, the data folder, worker pools, markdown tables and the stamped JSON
result of a run (the figures with the command, commit, machine and load that made them).

A benchmark is a module `benchmarks/NAME.py` with a docstring (its first line is the description), `QUICK` (what
`--quick` runs), `arguments(parser)` (its own options) and `main(argv)`, which starts a `Run`, prints its tables
through it and ends with `run.finish(figures)`:

    run = harness.start(__name__, __doc__, QUICK, arguments, argv)
    run.table("drives", rows, ["sequence", "ate_m"], title="Corrected ATE (m):")
    run.finish({"rows": rows})

`python -m benchmarks.NAME [--quick] [--workers N] [--out FILE]` writes `benchmarks/results/NAME.json` (or
`NAME.quick.json` with --quick); `python -m benchmarks.render` puts the stored tables into docs/benchmarks/.
"""

from __future__ import annotations

import argparse
import datetime as dt
import importlib.metadata
import json
import math
import multiprocessing
import os
import pkgutil
import platform
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from multiprocessing.pool import Pool
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().parent / "results"
# the libraries whose versions can move a figure (the numerics, the detector's runtime, the back end's solver)
LIBRARIES = ("numpy", "scipy", "torch", "opencv-python-headless", "opencv-python", "gtsam", "pydantic", "neoslam")
NOT_BENCHMARKS = {"harness", "render"}  # modules of the package that are not benchmarks (nor are _helpers)

Arguments = Callable[[argparse.ArgumentParser], None]


def benchmark_names() -> list[str]:
    """Every benchmark module of the package, by name."""
    return sorted(
        m.name
        for m in pkgutil.iter_modules([str(Path(__file__).resolve().parent)])
        if not m.name.startswith("_") and m.name not in NOT_BENCHMARKS
    )


def data_root() -> Path:
    """NEOSLAM_DATA, default ../shared/data beside the repository."""
    return Path(os.environ.get("NEOSLAM_DATA", REPO_ROOT.parent / "shared" / "data")).resolve()


def require_data(*parts: str) -> Path:
    """A path under the data folder that must exist; otherwise one line and exit code 2, before any work."""
    path = data_root().joinpath(*parts)
    if not path.exists():
        print(f"benchmark: missing {path} (set NEOSLAM_DATA to the shared data folder)", file=sys.stderr)
        raise SystemExit(2)
    return path


def cell(value: Any) -> str:
    """A table cell: floats to three decimals, anything else as it prints."""
    return f"{value:.3f}" if isinstance(value, float) else str(value)


def markdown_table(rows: list[dict[str, Any]], columns: list[str]) -> str:
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(row.get(c, "")) for c in columns) + " |" for row in rows]
    return "\n".join(lines)


def default_workers() -> int:
    return os.cpu_count() or 1


@contextmanager
def pool(workers: int) -> Iterator[Pool]:
    """Worker processes, each started fresh (spawn) and used for one task: a run's figures then do not depend on
    what ran before it in the same process."""
    with multiprocessing.get_context("spawn").Pool(max(1, workers), maxtasksperchild=1) as workers_pool:
        yield workers_pool


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(REPO_ROOT), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def git_state() -> dict[str, Any]:
    """The commit and whether the tree differs from it (stored results themselves do not count)."""
    status = _git("status", "--porcelain", "--", ".", ":(exclude)benchmarks/results")
    return {"commit": _git("rev-parse", "HEAD"), "dirty": None if status is None else bool(status)}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _ram_gb() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / 1024**2, 1)
    except OSError:
        pass
    return None


def machine() -> dict[str, Any]:
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return {
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "ram_gb": _ram_gb(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "libraries": versions,
    }


def load_average() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def command_line(name: str, argv: list[str]) -> str:
    """The command that made a result, as stored and quoted in the docs: without `--out PATH`, which names a file of
    the machine that ran it and changes no figure."""
    kept: list[str] = []
    skip = False
    for argument in argv:
        if skip:
            skip = False
        elif argument == "--out":
            skip = True
        elif not argument.startswith("--out="):
            kept.append(argument)
    return shlex.join(["python", "-m", f"benchmarks.{name}", *kept])


def jsonable(value: Any) -> Any:
    """Plain JSON values: numpy scalars and arrays to Python, NaN and infinities to null, paths to strings."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return jsonable(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def make_parser(description: str, quick: str, arguments: Arguments | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=description,
        epilog=f"--quick runs {quick}",
    )
    parser.add_argument("--quick", action="store_true", help="a small run, for a smoke test")
    parser.add_argument(
        "--workers", type=int, default=default_workers(), help="worker processes, where it has any (one per core)"
    )
    parser.add_argument(
        "--out", type=Path, help="the JSON result (default: benchmarks/results/NAME.json, NAME.quick.json with --quick)"
    )
    parser.add_argument("--no-save", action="store_true", help="print the tables only, write no JSON result")
    if arguments is not None:
        arguments(parser)
    return parser


@dataclass
class Run:
    """One run of a benchmark: its arguments, the tables it printed, and its stamp."""

    name: str
    args: argparse.Namespace
    argv: list[str]
    started: dt.datetime = field(default_factory=lambda: dt.datetime.now(dt.UTC))
    load_start: list[float] | None = field(default_factory=load_average)
    clock: float = field(default_factory=time.perf_counter)
    git: dict[str, Any] = field(default_factory=git_state)  # at the start: the code that ran
    tables: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def quick(self) -> bool:
        return bool(self.args.quick)

    @property
    def out(self) -> Path:
        if self.args.out is not None:
            return self.args.out
        return RESULTS / f"{self.name}{'.quick' if self.quick else ''}.json"

    def table(self, key: str, rows: list[dict[str, Any]], columns: list[str], title: str | None = None) -> None:
        """Print a markdown table (after its title) and keep it for the result, where the docs take it from."""
        if title is not None:
            print(title + "\n")
        print(markdown_table(rows, columns) + "\n", flush=True)
        self.tables[key] = {"title": title, "columns": columns, "rows": [{c: r.get(c) for c in columns} for r in rows]}

    def stamp(self) -> dict[str, Any]:
        return {
            "benchmark": self.name,
            "quick": self.quick,
            "command": command_line(self.name, self.argv),
            "started": self.started.isoformat(timespec="seconds"),
            "wall_s": round(time.perf_counter() - self.clock, 1),
            "git": self.git,
            "machine": machine(),
            "load_average": {"start": self.load_start, "end": load_average()},
        }

    def finish(self, figures: dict[str, Any]) -> dict[str, Any]:
        """Write the stamped result (unless --no-save); the figures are what the benchmark measured, whole."""
        result = self.stamp() | {"tables": self.tables, "figures": figures}
        result = jsonable(result)
        if not self.args.no_save:
            self.out.parent.mkdir(parents=True, exist_ok=True)
            self.out.write_text(json.dumps(result, indent=1) + "\n")
            print(f"result: {self.out}", file=sys.stderr)
        return result


def start(
    module: str,
    doc: str | None,
    quick: str,
    arguments: Arguments | None = None,
    argv: list[str] | None = None,
    data: tuple[tuple[str, ...], ...] = (),
) -> Run:
    """Parse the arguments of the benchmark `module` (its __name__), check the data it needs, and start the clock."""
    if module == "__main__":  # run as `python -m benchmarks.NAME`: the module's own name is in its spec
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        module = spec.name if spec is not None else Path(sys.argv[0]).stem
    name = module.rsplit(".", 1)[-1]
    argv = list(sys.argv[1:] if argv is None else argv)
    description = " ".join((doc or name).strip().split("\n\n")[0].split())  # the docstring's first paragraph
    args = make_parser(description, quick, arguments).parse_args(argv)
    for parts in data:
        require_data(*parts)
    return Run(name, args, argv)
