"""Odometry accuracy of the simulator's noise profiles on real KITTI trajectories.

For each sequence, profile and seed: `neoslam simulate` (in-process) then `neoslam run`, and the odometry ATE,
RPE and KITTI drift from metrics.json. Prints one row per run and the median over seeds.

    python -m benchmarks.odometry [--quick] [--out FILE] [--sequences 05 00] [--seeds 1 2 3] [--profiles vo heavy]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from benchmarks import harness
from benchmarks.harness import data_root
from neoslam.commands.run import run_dataset
from neoslam.commands.simulate import record, simulate_dataset
from neoslam.config import NOISE_PROFILES, load_config
from neoslam.config.profiles import simulation_config

QUICK = "seed 1 only"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sequences", nargs="+", default=["05"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--profiles", nargs="+", default=list(NOISE_PROFILES))


def measure(sequence: str, profile: str, seed: int, workdir: Path) -> dict:
    poses = data_root() / "kitti" / "poses" / f"{sequence}.txt"
    config = simulation_config(load_config(environ={}), profile, seed)
    start = time.perf_counter()
    recording = record(config, trajectory=poses, fmt="kitti")
    simulate_dataset(workdir / "data", recording, overwrite=True)
    simulate_s = time.perf_counter() - start
    metrics = run_dataset(workdir / "data", workdir / "out", config, overwrite=True, progress=False)
    odometry = metrics["trajectory"]["odometry"]
    return {
        "sequence": sequence,
        "profile": profile,
        "seed": seed,
        "frames": metrics["frames"],
        "ate_odometry_m": odometry["ate_rmse_m"],
        "rpe_100m_m": odometry["rpe_translation_rmse_m"],
        "kitti_t_percent": odometry["kitti_translation_percent"],
        "kitti_r_deg_100m": odometry["kitti_rotation_deg_per_100m"],
        "simulate_s": simulate_s,
        "run_s": metrics["timing"]["wall_s"],
    }


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    args = run.args
    seeds = args.seeds[:1] if args.quick else args.seeds
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for sequence in args.sequences:
            for profile in args.profiles:
                for seed in seeds:
                    rows.append(measure(sequence, profile, seed, Path(tmp)))
    medians = []
    for sequence in args.sequences:
        for profile in args.profiles:
            group = [r for r in rows if r["sequence"] == sequence and r["profile"] == profile]
            medians.append(
                {"sequence": sequence, "profile": profile, "seeds": len(group)}
                | {
                    k: statistics.median(r[k] for r in group)
                    for k in ("ate_odometry_m", "kitti_t_percent", "kitti_r_deg_100m", "rpe_100m_m")
                }
            )
    columns = ["sequence", "profile", "seed", "frames", "ate_odometry_m", "rpe_100m_m", "kitti_t_percent",
               "kitti_r_deg_100m", "simulate_s", "run_s"]  # fmt: skip
    run.table("runs", rows, columns)
    run.table(
        "medians",
        medians,
        ["sequence", "profile", "seeds", "ate_odometry_m", "rpe_100m_m", "kitti_t_percent", "kitti_r_deg_100m"],
        title="Median over seeds:",
    )
    run.finish({"runs": rows, "medians": medians})


if __name__ == "__main__":
    main()
