"""Part 7 of the sessions study, lifelong mapping: one route driven again and again must end with the same map, not a
growing copy of it.

KITTI 00's ground truth is cut where it comes back within 1.2 m of its start and driven 1, 2 and 4 times in a row
(`neoslam.sim.passes.join_passes`: the joins are continuous, timestamps run on), simulated (`vo` odometry, the
`real` detection profile, one seed) in one world of objects, the same for every pass count (built along one pass).
Each drive is run through NeoSLAM frame by frame in a fresh process. Per drive: ATE (SE(3)-aligned) of the
odometry and of the corrected trajectory, the map's objects, keyframes, experiences and links at the end of each
pass, peak memory (the process's peak RSS; and its growth while NeoSLAM ran, the dataset already in memory),
median milliseconds per frame over the drive and per pass, and the accepted closures judged against ground truth
(true within 5 m horizontally and 100 frames apart). Ground truth is read here for judging only.

    python -m benchmarks.sessions --parts 7 [--lifelong-sequence 00 | --lifelong-route block] [--passes 1 2 4]
                                  [--seed 1]

`--quick`: the built-in block route (ideal detection profile) instead, a few seconds a drive.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks.harness import data_root
from neoslam.config import load_config
from neoslam.config.profiles import simulation_config
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.evaluation.loops import LoopCriteria, judge_closures
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.io.trajectory_files import read_trajectory
from neoslam.pipeline import NeoSLAM
from neoslam.sim.passes import join_passes
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate
from neoslam.types import Trajectory

PASSES = [1, 2, 4]


QUICK = "the built-in block route (ideal detection profile) instead of KITTI 00"


def arguments(group: argparse._ArgumentGroup) -> None:
    group.add_argument("--lifelong-sequence", default="00", help="KITTI sequence driven again and again (default 00)")
    group.add_argument("--lifelong-route", help="a built-in route instead of a KITTI sequence (block, town)")
    group.add_argument("--passes", nargs="+", type=int, default=PASSES, help="pass counts (default 1 2 4)")


def _config(job: dict):
    return simulation_config(load_config(environ={}), job["profile"], job["seed"], job["detector"])


def _source(job: dict) -> Trajectory:
    sim = _config(job).simulator
    if job["route"]:
        return drive_route(ROUTES[job["route"]], sim.frame_period, sim.camera.height_above_ground)
    poses = data_root() / "kitti" / "poses" / f"{job['sequence']}.txt"
    return read_trajectory(poses, "kitti", None, frame_period=sim.frame_period)


def simulate_drive(job: dict) -> dict:
    """Simulate the drive of `job["passes"]` passes into job["folder"]; the world is built along one pass."""
    source = _source(job)
    drive = join_passes(source, job["passes"])
    one = join_passes(source, 1)
    name = f"{job['route'] or job['sequence']}x{job['passes']}"
    recording = simulate(drive.trajectory, _config(job).simulator, name, name, world_along=one.trajectory)
    write_dataset(Path(job["folder"]), recording)
    return {"frames_per_pass": drive.frames_per_pass, "world_objects": len(recording.world)}


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def _map_counts(slam: NeoSLAM) -> dict:
    experience_map = slam.experience_map
    return {
        "objects": len(slam.object_map.objects(experience_map.graph.poses)),
        "keyframes": len(slam.loop_detector.index),
        "experiences": len(experience_map.experiences),
        "links": len(experience_map.graph.links),
        "hebbian_keyframes": len(slam.hebbian),
        "peak_rss_mb": _rss_mb(),
    }


def run_drive(job: dict) -> dict:
    """NeoSLAM over the simulated drive, in this (fresh) process; counts at the end of every pass."""
    dataset = read_dataset(Path(job["folder"]))
    config = _config(job)
    frames_per_pass = job["frames_per_pass"]
    slam = NeoSLAM(config)
    rss_before = _rss_mb()
    times, per_pass = [], []
    for frame in dataset.frames():
        start = time.perf_counter()
        slam.step(frame)
        times.append(time.perf_counter() - start)
        if (frame.index + 1) % frames_per_pass == 0:
            per_pass.append(_map_counts(slam))
    result = slam.result(np.asarray(times))
    truth = dataset.ground_truth
    correct = judge_closures(result.loop_closures, truth.positions[:, :2], LoopCriteria())
    passes = job["passes"]
    ms = 1e3 * np.asarray(times).reshape(passes, frames_per_pass)
    estimate = result.estimate
    pass_ate = [
        absolute_trajectory_error(estimate.subset(rows), truth.subset(rows), "se3").rmse
        for rows in np.arange(passes * frames_per_pass).reshape(passes, frames_per_pass)
    ]
    final = per_pass[-1]
    return {
        "passes": passes,
        "frames": len(dataset),
        "world_objects": job["world_objects"],
        "ate_odometry_m": absolute_trajectory_error(result.odometry, truth, "se3").rmse,
        "ate_corrected_m": absolute_trajectory_error(estimate, truth, "se3").rmse,
        "ate_corrected_last_pass_m": pass_ate[-1],
        "objects": len(result.objects),
        "keyframes": final["keyframes"],
        "experiences": final["experiences"],
        "links": final["links"],
        "closures_true": int(correct.sum()),
        "closures_false": int((~correct).sum()),
        "peak_rss_mb": _rss_mb(),
        "slam_rss_growth_mb": _rss_mb() - rss_before,
        "ms_per_frame_median": float(np.median(ms)),
        "ms_per_frame_by_pass": [round(float(np.median(row)), 3) for row in ms],
        "ms_per_frame_p95_by_pass": [round(float(np.percentile(row, 95)), 3) for row in ms],
        "by_pass": per_pass,
        "ate_corrected_by_pass_m": [round(float(a), 3) for a in pass_ate],
    }


def run_part(bench: harness.Run, args: argparse.Namespace) -> dict:
    """The drives of every pass count, each simulated and run in a fresh process; prints the tables."""
    route = args.lifelong_route or ("block" if args.quick else None)
    detector = "ideal" if args.quick else "real"
    profile = "vo"
    base = {"route": route, "sequence": args.lifelong_sequence, "seed": args.seed, "profile": profile,
            "detector": detector}  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [base | {"passes": p, "folder": str(Path(tmp) / f"x{p}")} for p in args.passes]
        # a fresh process per drive: its peak memory is the drive's own
        with harness.pool(args.workers) as pool:
            simulated = pool.map(simulate_drive, jobs, chunksize=1)
        with harness.pool(args.workers) as pool:
            rows = pool.map(run_drive, [j | s for j, s in zip(jobs, simulated, strict=True)], chunksize=1)
    name = route or f"KITTI {args.lifelong_sequence}"
    print(f"## {name} driven {', '.join(map(str, args.passes))} times (simulated, {profile} odometry, "
          f"{detector} detection profile, seed {args.seed})\n")  # fmt: skip
    columns = ["passes", "frames", "ate_odometry_m", "ate_corrected_m", "ate_corrected_last_pass_m", "objects",
               "world_objects", "keyframes", "experiences", "links", "closures_true", "closures_false",
               "peak_rss_mb", "slam_rss_growth_mb", "ms_per_frame_median"]  # fmt: skip
    bench.table("lifelong", rows, columns)
    longest = max(rows, key=lambda r: r["passes"])
    by_pass = [
        {"pass": p + 1, **counts, "ms_per_frame_median": ms, "ms_per_frame_p95": p95, "ate_corrected_m": ate}
        for p, (counts, ms, p95, ate) in enumerate(
            zip(longest["by_pass"], longest["ms_per_frame_by_pass"], longest["ms_per_frame_p95_by_pass"],
                longest["ate_corrected_by_pass_m"], strict=True)
        )
    ]  # fmt: skip
    pass_columns = ["pass", "objects", "keyframes", "experiences", "links", "hebbian_keyframes", "peak_rss_mb",
                    "ms_per_frame_median", "ms_per_frame_p95", "ate_corrected_m"]  # fmt: skip
    title = f"The {longest['passes']}-pass drive at the end of each pass:"
    bench.table("lifelong_by_pass", by_pass, pass_columns, title=title)
    single = next((r for r in rows if r["passes"] == 1), None)
    if single is not None:
        print(
            f"Objects after {longest['passes']} passes: {longest['objects']} against {single['objects']} after one "
            f"({100.0 * (longest['objects'] / max(single['objects'], 1) - 1):+.1f} %); corrected ATE "
            f"{longest['ate_corrected_m']:.2f} m against {single['ate_corrected_m']:.2f} m."
        )
    return {"drive": name, "profile": profile, "detector": detector, "seed": args.seed, "rows": rows}
