"""Part `landmarks` of the kitti_sim study: objects as landmarks in the pose graph (iSAM2) against the pose graph
without them, on simulated KITTI drives.

Per sequence and detection profile (`vo` odometry, one seed): the drive is simulated once, then NeoSLAM runs it with
`experience_map.object_landmarks` off and on (pose-graph back end): the sweep `benchmarks/specs/landmarks.yaml` with
`measure` below as each cell's measurement (--workers, --ray and --sweep-dir as for the part `steps`). Per run: ATE
(SE(3)-aligned) of the odometry and of the corrected trajectory, loop closures accepted (true, false: within 5 m
horizontally, 100 frames apart), the objects and landmarks of the map, and the wall time in the back end's solver
calls (the batch pose graph at loops, or every iSAM2 update) over the whole run.

    python -m benchmarks.kitti_sim --parts landmarks [--sequences 05 08 00 06] [--detectors real ideal]
                                   [--profiles vo] [--seeds 1]

`--quick`: KITTI 06 with the real profile only.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._sweep import SPECS, run_spec, with_changes
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.loops import LoopCriteria, judge_closures
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.pipeline import NeoSLAM
from neoslam.sweep import load_spec

SPEC = SPECS / "landmarks.yaml"
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
    """No options of its own: the study's --sequences, --profiles, --seeds, --detectors and the sweep's."""


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: NeoSLAM over one simulated drive, in this process; the figures of one row."""
    dataset = read_dataset(data)
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
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"kitti": sequences}],
        noise=[profile],
        detectors=detectors,
        seeds=[seed],
        metrics=COLUMNS[3:],
        data_root=data_root(),
    )
    figures: dict[tuple, dict] = {}
    with run_spec(spec, args, measure=measure) as sweep:
        for record in sweep.failed:
            print(f"- failed: {record.cell.source} {record.cell.detector} {record.cell.override}: {record.error}")
        for record in sweep.records:
            if record.status == "ok":
                figures[(record.cell.source, record.cell.detector, record.cell.override == "with")] = record.metrics
    rows = [
        {"sequence": sequence, "detector": detector, "landmarks": landmarks} | figures[(sequence, detector, landmarks)]
        for sequence in sequences
        for detector in detectors
        for landmarks in (False, True)
        if (sequence, detector, landmarks) in figures
    ]
    title = f"{profile} odometry, seed {seed}; ATE RMSE (m) after SE(3) alignment; back end: solver seconds"
    bench.table("landmarks", rows, COLUMNS, title=title)
    return {"profile": profile, "seed": seed, "rows": rows}
