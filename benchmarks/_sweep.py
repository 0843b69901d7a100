"""Benchmarks as sweeps: the options every sweep-based benchmark takes, and running its spec."""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from neoslam.sweep import SweepResult, make_executor, parse_spec, run_sweep
from neoslam.sweep.spec import Spec

SPECS = Path(__file__).resolve().parent / "specs"


def sweep_options(parser: argparse.ArgumentParser) -> None:
    """Beside the harness's --workers (local worker processes, one per core by default)."""
    parser.add_argument("--sweep-dir", type=Path, help="sweep folder to keep (and resume); default: a temporary one")
    parser.add_argument("--ray", metavar="ADDRESS", help="run the cells as Ray tasks on this cluster")


def config_file(args: argparse.Namespace) -> dict[str, Path]:
    """The spec change that puts the --config file under every cell (none without one)."""
    return {"config": args.config.resolve()} if args.config is not None else {}


def with_changes(spec: Spec, **changes) -> Spec:
    """The spec with some fields replaced, checked again."""
    values = spec.model_dump(exclude_unset=True) | changes
    return parse_spec(values, spec.origin, spec.base_dir)


@contextmanager
def run_spec(spec: Spec, args: argparse.Namespace, measure=None) -> Iterator[SweepResult]:
    """Run the spec (the defaults of the config, whatever NEOSLAM_* variables are set) into --sweep-dir or a
    temporary folder, which lasts as long as the block."""
    executor = make_executor(args.ray, args.workers)
    progress = sys.stderr.isatty()
    if args.sweep_dir is not None:
        yield run_sweep(spec, args.sweep_dir, executor, progress=progress, measure=measure, environ={})
        return
    with tempfile.TemporaryDirectory(prefix=f"{spec.name}-") as folder:
        yield run_sweep(spec, Path(folder) / "sweep", executor, progress=progress, measure=measure, environ={})


def drive_runs(spec: Spec, args: argparse.Namespace, measure, name: str) -> list[dict]:
    """Run a spec whose cells are drives: each drive's measurement with its sequence and seed, a failed cell
    printed as one line; exits when no drive ran."""
    runs = []
    with run_spec(spec, args, measure=measure) as sweep:
        for record in sweep.failed:
            print(f"- failed: {record.cell.source} seed {record.cell.seed}: {record.error}")
        for record in sweep.records:
            if record.status == "ok":
                runs.append({"sequence": record.cell.source, "seed": record.cell.seed, **dict(record.metrics)})
    if not runs:
        sys.exit(f"{name}: no drive ran (the errors above; tracebacks in the cells' error.txt)")
    return runs
