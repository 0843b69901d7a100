"""Sweeps on this machine: wall time of one spec run serially (one worker process) against the local pool (one
worker per core), and the per-cell overhead of Ray tasks (a local Ray instance with as many CPUs) against the pool.

    python -m benchmarks.sweep_scaling [--quick] [--full [--sequences 07 ...] [--seeds 1 ...]] [--workers N]
                                       [--no-ray] [--out FILE]

Default spec: the block route cut to 400 poses, noise vo and heavy, seeds 1-4 (8 cells). `--quick`: 200 poses,
seeds 1-2 (4 cells). `--full`: the 12 drives of `benchmarks/specs/kitti_sim.yaml` (72 runs: six settings on each
drive's simulation), a long measurement (about an hour on two idle cores); `--sequences` and `--seeds` cut it down.
Every run starts from an empty sweep
folder (nothing resumed), and the serial, pool and Ray tables are checked to be the same bytes. The load average
is printed: on a shared machine the ratio says as much about the other jobs as about the sweep.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import harness
from benchmarks._sweep import SPECS, with_changes
from benchmarks.harness import data_root
from neoslam.sweep import LocalPool, RayCluster, expand, load_spec, parse_spec, run_sweep

QUICK = "the block route cut to 200 poses, seeds 1-2 (4 cells)"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--full", action="store_true", help="the kitti_sim spec (long)")
    parser.add_argument("--no-ray", action="store_true", help="skip the Ray measurement")
    parser.add_argument("--sequences", nargs="+", help="with --full: only these KITTI sequences")
    parser.add_argument("--seeds", nargs="+", type=int, help="with --full: only these seeds")


def _spec(args):
    if args.full:
        changes = {"data_root": data_root()}
        if args.sequences:
            changes["sources"] = [{"kitti": args.sequences}]
        if args.seeds:
            changes["seeds"] = args.seeds
        return with_changes(load_spec(SPECS / "kitti_sim.yaml"), **changes)
    frames, seeds = (200, [1, 2]) if args.quick else (400, [1, 2, 3, 4])
    values = {"name": "scaling", "sources": [{"route": "block", "frames": frames}], "noise": ["vo", "heavy"]}
    return parse_spec(values | {"seeds": seeds}, "sweep_scaling")


def _timed(spec, executor, folder: Path) -> tuple[float, bytes, int]:
    start = time.perf_counter()
    result = run_sweep(spec, folder, executor, progress=sys.stderr.isatty(), environ={})
    wall = time.perf_counter() - start
    for record in result.failed[:3]:
        print(f"- {executor.name}: failed cell {record.cell.id}: {record.error}")
    return wall, (folder / "sweep.csv").read_bytes(), len(result.failed)


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(__name__, __doc__, QUICK, arguments, argv, data=())
    args = bench.args
    spec = _spec(args)
    load_before = os.getloadavg()
    rows, tables = [], {}
    with tempfile.TemporaryDirectory(prefix="sweep-scaling-") as tmp:
        runs = [("serial", LocalPool(1), 1), ("pool", LocalPool(args.workers), args.workers)]
        for name, executor, workers in runs:
            wall, tables[name], failed = _timed(spec, executor, Path(tmp) / name)
            rows.append({"run": name, "executor": "local pool", "workers": workers, "wall_s": wall, "failed": failed})
        ray_init_s = None
        if not args.no_ray:
            try:
                import ray
            except ImportError:
                print('Ray is not installed (pip install "neoslam[cluster]"): no Ray row.\n')
            else:
                start = time.perf_counter()
                ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False)
                ray_init_s = time.perf_counter() - start
                try:
                    # This machine's workers run this checkout: no code check (a file edited meanwhile would fail it).
                    executor = RayCluster(check_code=False)
                    wall, tables["ray"], failed = _timed(spec, executor, Path(tmp) / "ray")
                finally:
                    ray.shutdown()
                rows.append({"run": "ray", "executor": "local Ray", "workers": args.workers, "wall_s": wall,
                             "failed": failed})  # fmt: skip
    cells = len({c.id for c in expand(spec, environ={}).cells})
    serial = rows[0]["wall_s"]
    pool = rows[1]["wall_s"]
    for row in rows:
        row |= {"cells": cells, "s_per_cell": row["wall_s"] / cells, "speed_up_vs_serial": serial / row["wall_s"]}
    same = len(set(tables.values())) == 1
    columns = ["run", "executor", "workers", "cells", "failed", "wall_s", "s_per_cell", "speed_up_vs_serial"]
    print(f"## Sweep {spec.name}: {cells} cells, serial against the pool" + (" and Ray" if "ray" in tables else ""))
    print()
    bench.table("executors", rows, columns)
    load_after = os.getloadavg()
    print(f"\nLoad average (1, 5, 15 min) before {load_before[0]:.1f} {load_before[1]:.1f} {load_before[2]:.1f}, "
          f"after {load_after[0]:.1f} {load_after[1]:.1f} {load_after[2]:.1f}; {os.cpu_count()} cores.")  # fmt: skip
    print(f"Serial / pool wall time: {serial / pool:.2f}.")
    overhead = None
    if "ray" in tables:
        ray_wall = rows[2]["wall_s"]
        overhead = (ray_wall - pool) / cells
        print(f"Ray: {ray_init_s:.1f} s to start the local instance (not counted), then {ray_wall:.1f} s against the "
              f"pool's {pool:.1f} s: {overhead:+.2f} s per cell.")  # fmt: skip
    print(f"Tables the same bytes on every executor: {'yes' if same else 'NO'}.")
    bench.finish(
        {"rows": rows, "ray_init_s": ray_init_s, "ray_overhead_s_per_cell": overhead, "same_tables": same,
         "load_before": load_before, "load_after": load_after},
    )  # fmt: skip


if __name__ == "__main__":
    main()
