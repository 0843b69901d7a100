"""Whole-system trajectories, for the figures of the docs: each drive run as `neoslam run` runs it, its paths and
objects kept for drawing.

The simulated drives are the real KITTI ground truth of 00, 02, 05, 06 and 08 (and any built-in route named, such as
`town`), simulated as `neoslam simulate` does with the `vo` odometry and the `real` detection profile, seed 1;
`real` is the real KITTI 06 frames of kitti_06_51, through the front end with the default detector. For each: the
ground truth, the odometry and the corrected trajectory of the final map (both aligned to the truth as the ATE aligns
them, `evaluation.alignment`), the frames at which a loop closure was accepted (true or false against the ground
truth, by the evaluation's criteria), the map's objects by class, and the ATE of the odometry and of the corrected
trajectory as the run's metrics.json gives them.
Paths keep at most POINTS points (every k-th frame) and positions are rounded to 1 cm, so that the result stays
small; the figures and the table come from the same run.

    python -m benchmarks.trajectories [--quick] [--drives 00 05 real] [--workers N] [--out FILE]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import harness
from benchmarks.harness import require_data
from neoslam.commands.run_metrics import run_metrics
from neoslam.commands.simulate import record
from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.opening import ImageInputs, open_dataset
from neoslam.datasets.simulated import write_dataset
from neoslam.evaluation.report import closure_verdicts
from neoslam.evaluation.trajectory_metrics import align
from neoslam.pipeline import run
from neoslam.sim.routes import ROUTES
from neoslam.types import Trajectory

DRIVES = ["00", "02", "05", "06", "08", "real"]
QUICK_DRIVES = ["06", "real"]
REAL = "real"  # the real frames of kitti_06_51
REAL_SEQUENCE = "06"
NOISE, DETECTION, SEED = "vo", "real", 1
POINTS = 400  # the most points a drawn path keeps
DECIMALS = 2  # positions rounded to 1 cm
MAX_OBJECTS = 800  # the most objects a drive keeps for drawing (the most observed)


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--drives",
        nargs="+",
        default=None,
        help=f"KITTI sequences (simulated from their ground truth), built-in routes, or `{REAL}` "
        f"(default {' '.join(DRIVES)}; --quick: {' '.join(QUICK_DRIVES)})",
    )


def _dataset(name: str, folder: Path) -> tuple[Any, NeoSLAMConfig, str]:
    """The dataset of a drive as `neoslam run` opens it, its configuration and what it is."""
    if name == REAL:
        config = NeoSLAMConfig()
        root = require_data("kitti_06_51")
        return open_dataset(root, config, ImageInputs(sequence=REAL_SEQUENCE)), config, "real images (kitti_06_51)"
    config = simulation_config(NeoSLAMConfig(), NOISE, SEED, DETECTION)
    if name in ROUTES:
        recording = record(config, route=name)
    else:
        recording = record(config, trajectory=require_data("kitti", "poses", f"{name}.txt"))
    write_dataset(folder / "dataset", recording)
    kind = f"simulated ({NOISE} odometry, {DETECTION} detection, seed {SEED})"
    return open_dataset(folder / "dataset", config, ImageInputs()), config, kind


def _path(trajectory: Trajectory, step: int) -> list[list[float]]:
    """The x, y of every `step`-th pose (and the last), rounded."""
    positions = trajectory.positions[:, :2]
    keep = np.unique(np.r_[np.arange(0, len(positions), step), len(positions) - 1])
    return np.round(positions[keep], DECIMALS).tolist()


def run_drive(name: str) -> dict[str, Any]:
    """One drive: run it as `neoslam run` does, with its metrics.json figures, and keep what its figure draws."""
    with tempfile.TemporaryDirectory(prefix="neoslam-trajectories-") as folder:
        dataset, config, kind = _dataset(name, Path(folder))
        started = time.perf_counter()
        result = run(dataset.frames(), config, total=len(dataset), progress=False, session_name=dataset.name)
        metrics = run_metrics(dataset, result, config, time.perf_counter() - started)
    truth = dataset.ground_truth
    if truth is None:
        raise SystemExit(f"{name}: the drive has no ground truth to draw against")
    closures = result.session_closures()
    verdicts = closure_verdicts(closures, truth, config.evaluation) if closures else np.zeros(0, dtype=bool)
    step = max(1, int(np.ceil(len(truth) / POINTS)))
    alignment = config.evaluation.alignment  # as the ATE aligns
    aligned_estimate, transform = align(result.estimate, truth, alignment)
    aligned_odometry, _ = align(result.odometry, truth, alignment)
    objects = sorted(result.objects, key=lambda o: (-o.observations, o.id))[:MAX_OBJECTS]
    # The map's objects and closures are in the estimate's frame: moved as the estimate is onto the truth.
    placed = transform.apply_to_points(np.array([o.position for o in objects]).reshape(-1, 3))
    query = np.array([c.query_frame for c in closures], dtype=int)
    closure_positions = aligned_estimate.positions[query, :2]
    return {
        "drive": name,
        "kind": kind,
        "frames": len(truth),
        "route_m": round(float(truth.path_length()), 1),
        "ate_odometry_m": metrics["ate_rmse_m"]["odometry"],
        "ate_m": metrics["ate_rmse_m"]["corrected"],
        "closures": len(closures),
        "false_closures": int(np.count_nonzero(~verdicts)),
        "objects": len(result.objects),
        "paths": {
            "truth": _path(truth, step),
            "odometry": _path(aligned_odometry, step),
            "corrected": _path(aligned_estimate, step),
        },
        "closure_points": np.round(closure_positions, DECIMALS).tolist(),
        "closure_true": verdicts.astype(bool).tolist(),
        "object_points": np.round(placed[:, :2], DECIMALS).tolist(),
        "object_labels": [o.label for o in objects],
    }


COLUMNS = ["drive", "kind", "frames", "route_m", "ate_odometry_m", "ate_m", "closures", "false_closures", "objects"]
QUICK = f"the drives {' and '.join(QUICK_DRIVES)}"


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv=argv)
    args = run.args
    drives = args.drives or (QUICK_DRIVES if args.quick else DRIVES)
    if REAL in drives:
        require_data("kitti_06_51")
        require_data("models")
    with harness.pool(min(args.workers, len(drives))) as workers:
        rows = workers.map(run_drive, drives, chunksize=1)
    run.table("drives", rows, COLUMNS, "## Drives (the figure's)")
    run.finish({"drives": rows})


if __name__ == "__main__":
    main()
