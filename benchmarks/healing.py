"""A map that heals: a wrong loop closure injected into a simulated drive is withdrawn and the map recovers.

Each cell simulates a drive of a real KITTI trajectory or the town route (`neoslam simulate`: odometry --profile,
`real` detection profile, static streets) and runs the pipeline three times:

1. clean, the defaults: corrected ATE, and the loop links the map withdrew (each a true closure the map disagreed
   with: a false withdrawal);
2. with one wrong closure injected: at the first keyframe past the middle of the drive the loop detector also
   reports a closure with a stored keyframe at least WRONG_MIN_M away in truth (the one whose cells are nearest the
   current, among those the map's closure gate accepts), fitted as if the robot stood where that keyframe was (what
   an aliased place gives). It goes through the pipeline like any closure: the gate, the link, the cells' recall;
   whether the map withdrew it, what else it withdrew, the ATE;
3. the same with the withdrawal off (`experience_map.withdraw_sigmas: 0`, the robust kernel alone).

Ground truth chooses the wrong place and judges; the pipeline never reads it. Targets: every injected closure
withdrawn, its ATE within 5 % of the clean run's, no true closure withdrawn.

    python -m benchmarks.healing [--quick] [--seeds 1 2 3] [--sequences 00 05 06 town] [--profile vo|heavy]
                                 [--config FILE.yaml]
                                 [--workers N] [--out FILE] [--sweep-dir DIR] [--ray ADDRESS]

Default: KITTI 00, 05, 06 and the town route, seeds 1-3, `vo` (12 drives, 36 runs, about 25 min on 2 cores).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._sweep import SPECS, config_file, drive_runs, sweep_options, with_changes
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.report import loop_metrics
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.loop.detector import LoopClosureDetector
from neoslam.mapping.experience_map import CellState
from neoslam.pipeline import NeoSLAM
from neoslam.sweep import load_spec
from neoslam.types import Keyframe, LoopClosure

SEQUENCES = ["00", "05", "06", "town"]
SEEDS, QUICK_SEEDS = [1, 2, 3], [1]
SPEC = SPECS / "healing.yaml"
WRONG_MIN_M = 30.0  # the injected closure's stored keyframe is at least this far from the query in truth
ATE_TOLERANCE = 1.05  # target: the healed run's ATE within 5 % of the clean run's


class _WrongClosure(LoopClosureDetector):
    """The default loop detector, which at the first keyframe past `at_frame` also reports one wrong closure.
    Benchmarks only: it reads ground truth to choose a wrong place."""

    def __init__(self, slam: NeoSLAM, truth: np.ndarray, at_frame: int) -> None:
        super().__init__(slam.config.keyframes, slam.config.matching)
        self.slam, self.truth, self.at_frame = slam, truth, at_frame
        self.injected: LoopClosure | None = None

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        closures = super().query(keyframe, odometer_m)
        if self.injected is None and keyframe.frame_index >= self.at_frame:
            self.injected = self._wrong(keyframe)
            if self.injected is not None:
                return [self.injected, *closures]
        return closures

    def _wrong(self, keyframe: Keyframe) -> LoopClosure | None:
        """A closure with the stored keyframe WRONG_MIN_M or more away in truth whose cells are nearest the current
        among those the map's gate accepts, fitted as if the robot stood at that keyframe."""
        experience_map = self.slam.experience_map
        cells = CellState(self.slam.grid_cells.centre, self.slam.head_direction.centre)
        here = self.truth[keyframe.frame_index, :3, 3]
        candidates = []
        dims = experience_map.grid_dims
        for stored in self.index.keyframes:
            experience = experience_map.keyframe_experiences.get(stored.id)
            far = np.linalg.norm(self.truth[stored.frame_index, :3, 3] - here) >= WRONG_MIN_M
            if experience is not None and far and experience_map.cells_agree(cells, experience):
                apart = np.abs(experience_map.experiences[experience].grid_cell - cells.grid) % dims
                candidates.append((float(np.linalg.norm(np.minimum(apart, dims - apart))), stored))
        if not candidates:
            return None
        _, stored = min(candidates, key=lambda pair: (pair[0], pair[1].id))
        return LoopClosure(keyframe.frame_index, stored.frame_index, keyframe.id, stored.id, 1.0, 0, np.eye(4))


def _run(config: NeoSLAMConfig, dataset, inject: bool) -> dict:
    """The pipeline over the drive (with one wrong closure injected); its ATE, false closures and withdrawals."""
    truth = dataset.ground_truth
    slam = NeoSLAM(config)
    injector = None
    if inject:
        injector = _WrongClosure(slam, truth.poses, len(truth.poses) // 2)
        slam.loop_detector = injector
    for frame in dataset.frames():
        slam.step(frame)
    result = slam.result(np.zeros(0))
    experience_map = slam.experience_map
    wrong = _injected_links(slam, injector.injected) if injector and injector.injected else set()
    withdrawn = set(experience_map.withdrawn_links)
    loops = loop_metrics(result.loop_closures, truth, config.evaluation, result.keyframe_frames)
    return {
        "ate_m": float(absolute_trajectory_error(result.estimate, truth, "se3").rmse),
        "false": loops["false_positive"],
        "recall": loops["recall"],
        "injected": bool(wrong),
        "injected_withdrawn": bool(wrong) and wrong <= withdrawn,
        "true_withdrawn": len(withdrawn - wrong),
    }


def _injected_links(slam: NeoSLAM, closure: LoopClosure) -> set[int]:
    """The loop links the injected closure made (between its stored keyframe's experience and the query's)."""
    experience_map = slam.experience_map
    stored = experience_map.keyframe_experiences.get(closure.match_keyframe)
    query = experience_map.keyframe_experiences.get(closure.query_keyframe)
    return {
        index
        for index, link in enumerate(experience_map.graph.links)
        if link.kind == "loop" and {link.source, link.target} == {stored, query}
    }


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: the drive clean, with a wrong closure injected, and injected with the withdrawal off (JSON)."""
    dataset = read_dataset(data)
    kept = config.model_copy(update={"experience_map": config.experience_map.model_copy(update={"withdraw_sigmas": 0})})
    return {
        "clean": _run(config, dataset, inject=False),
        "healed": _run(config, dataset, inject=True),
        "kept": _run(kept, dataset, inject=True),
    }


def _median(values) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def tables(runs: list[dict]) -> list[dict]:
    """Per sequence and over all: injections made and withdrawn, true closures withdrawn (clean and injected runs),
    median ATE of the three runs and the healed run's worst ratio to its clean run."""
    rows = []
    groups = {s: [r for r in runs if r["sequence"] == s] for s in dict.fromkeys(r["sequence"] for r in runs)}
    for sequence, mine in [*groups.items(), ("all", runs)]:
        injected = [r for r in mine if r["healed"]["injected"]]
        ratios = [r["healed"]["ate_m"] / r["clean"]["ate_m"] for r in injected]
        rows.append(
            {
                "sequence": sequence,
                "drives": len(mine),
                "injected": len(injected),
                "withdrawn": sum(r["healed"]["injected_withdrawn"] for r in injected),
                "true withdrawn, clean": sum(r["clean"]["true_withdrawn"] for r in mine),
                "true withdrawn, injected": sum(r["healed"]["true_withdrawn"] for r in mine),
                "ate clean m": _median(r["clean"]["ate_m"] for r in mine),
                "ate healed m": _median(r["healed"]["ate_m"] for r in injected),
                "ate kept m": _median(r["kept"]["ate_m"] for r in injected),
                "healed / clean, worst": max(ratios, default=None),
                "within 5 %": sum(ratio <= ATE_TOLERANCE for ratio in ratios),
                "false clean": sum(r["clean"]["false"] for r in mine),
            }
        )
    return rows


QUICK = "KITTI 05, seed 1"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, nargs="+", help=f"simulation seeds (default {SEEDS})")
    parser.add_argument("--sequences", nargs="+", help=f"drives (default {' '.join(SEQUENCES)})")
    parser.add_argument("--profile", default="vo", help="odometry noise profile (default vo)")
    parser.add_argument("--config", type=Path, help="a NeoSLAM config file (YAML) under every run")
    sweep_options(parser)


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    args = run.args
    sequences = args.sequences or (["05"] if args.quick else SEQUENCES)
    seeds = args.seeds or (QUICK_SEEDS if args.quick else SEEDS)
    changes = config_file(args)
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"route": n} if n == "town" else {"kitti": n} for n in sequences],
        noise=[args.profile],
        seeds=seeds,
        data_root=data_root(),
        **changes,
    )
    runs = drive_runs(spec, args, measure, "healing")
    rows = tables(runs)
    profile = f"odometry {args.profile}, `real` profile, seeds {seeds}"
    profile += f", config {args.config.name}" if args.config is not None else ""
    print(f"## One wrong closure injected into simulated drives: {profile}\n")
    print("Injections made and withdrawn; true closures the map withdrew (clean runs, injected runs); ATE RMSE (m,")
    print("SE(3)-aligned, medians) clean, healed and with the withdrawal off; the healed run's worst ATE ratio to its")
    print("clean run and how many are within 5 %; false closures of the clean runs:\n")
    run.table("healing", rows, list(rows[0]))
    run.finish({"runs": runs, "healing": rows})


if __name__ == "__main__":
    main()
