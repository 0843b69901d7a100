"""Part `landmarks` of the kitti_sim study: objects as landmarks in the pose graph (iSAM2) against the pose graph
without them, on simulated KITTI drives.

Per sequence and detection profile (`vo` odometry, one seed): the drive is simulated once, then NeoSLAM runs it
with `experience_map.object_landmarks` off and on (pose-graph back end). Per run: ATE (SE(3)-aligned) of the
odometry and of the corrected trajectory, loop closures accepted (true, false: within 5 m horizontally, 100 frames
apart), the objects and landmarks of the map, and the wall time in the back end's solver calls (the batch pose graph
at loops, or every iSAM2 update) over the whole run.

    python -m benchmarks.kitti_sim --parts landmarks [--sequences 05 08 00 06] [--detectors real ideal]
                                   [--profiles vo] [--seeds 1] [--cache DIR]

`--quick`: KITTI 06 with the real profile only. `--cache DIR` keeps the simulated drives there and reuses them.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks.harness import data_root, markdown_table
from neoslam.config import NeoSLAMConfig, load_config
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.evaluation.loops import LoopCriteria, judge_closures
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.io.trajectory_files import read_trajectory
from neoslam.jobs import simulation_config
from neoslam.pipeline import NeoSLAM
from neoslam.sim.simulator import simulate

SEQUENCES = ["05", "08", "00", "06"]
DETECTORS = ["real", "ideal"]
COLUMNS = [
    "sequence",
    "detector",
    "landmarks",
    "ate_odometry_m",
    "ate_corrected_m",
    "loops_true",
    "loops_false",
    "objects",
    "landmark_objects",
    "backend_s",
    "run_s",
]


QUICK = "KITTI 06 with the real profile only"


def arguments(group: argparse._ArgumentGroup) -> None:
    group.add_argument("--cache", type=Path, help="landmarks: keep the simulated drives in this folder and reuse them")


def _config(profile: str, seed: int, detector: str, landmarks: bool) -> NeoSLAMConfig:
    config = simulation_config(load_config(environ={}), profile, seed, detector)
    experience_map = config.experience_map.model_copy(update={"backend": "pose-graph", "object_landmarks": landmarks})
    return config.model_copy(update={"experience_map": experience_map})


def _drive(folder: Path, sequence: str, profile: str, seed: int, detector: str) -> Path:
    """The simulated drive's folder, simulated unless it is there already."""
    path = folder / f"{sequence}_{detector}_{profile}_{seed}"
    if not (path / "dataset.yaml").exists():
        simulator = _config(profile, seed, detector, False).simulator
        poses = data_root() / "kitti" / "poses" / f"{sequence}.txt"
        truth = read_trajectory(poses, "kitti", None, frame_period=simulator.frame_period)
        write_dataset(path, simulate(truth, simulator, name=sequence, source=str(poses)))
    return path


def run_drive(path: Path, config: NeoSLAMConfig) -> dict:
    """NeoSLAM over one simulated drive; the figures of one row."""
    dataset = read_dataset(path)
    slam = NeoSLAM(config)
    start = time.perf_counter()
    for frame in dataset.frames():
        slam.step(frame)
    result = slam.result(np.zeros(len(dataset)))
    run_s = time.perf_counter() - start
    truth = dataset.ground_truth
    correct = judge_closures(result.session_closures(), truth.positions[:, :2], LoopCriteria())
    solver = result.experience_map.backend.landmark_solver
    return {
        "ate_odometry_m": absolute_trajectory_error(result.odometry, truth, "se3").rmse,
        "ate_corrected_m": absolute_trajectory_error(result.estimate, truth, "se3").rmse,
        "loops_true": int(correct.sum()),
        "loops_false": int((~correct).sum()),
        "objects": len(result.objects),
        "landmark_objects": 0 if solver is None else len(solver.landmarks),
        "backend_s": result.experience_map.backend.seconds,
        "run_s": run_s,
    }


def run_part(bench: harness.Run, args: argparse.Namespace) -> dict:
    profile = args.profiles[0] if args.profiles else "vo"
    seed = args.seeds[0] if args.seeds else 1
    sequences = ["06"] if args.quick else args.sequences or SEQUENCES
    detectors = ["real"] if args.quick else args.detectors or DETECTORS
    rows = []
    with tempfile.TemporaryDirectory(prefix="landmarks-") as temporary:
        folder = args.cache if args.cache is not None else Path(temporary)
        for sequence in sequences:
            for detector in detectors:
                path = _drive(folder, sequence, profile, seed, detector)
                for landmarks in (False, True):
                    figures = run_drive(path, _config(profile, seed, detector, landmarks))
                    rows.append({"sequence": sequence, "detector": detector, "landmarks": landmarks} | figures)
                    print(markdown_table(rows[-1:], COLUMNS).splitlines()[-1], file=sys.stderr, flush=True)
    title = f"{profile} odometry, seed {seed}; ATE RMSE (m) after SE(3) alignment; back end: solver seconds"
    bench.table("landmarks", rows, COLUMNS, title=title)
    return {"profile": profile, "seed": seed, "rows": rows}
