"""Places from few, far, noisy objects: loop recall, false closures and where revisits are lost, on simulated drives
of the real KITTI trajectories, the place recognition's steps each switched off in turn; and the oracle floor of ATE.

Each cell simulates a drive (`neoslam simulate`: odometry profile --profile, detection profile --detector, a share
--moving of the street's objects moving) and measures it:

1. The pipeline with the defaults: loop recall and false closures as metrics.json counts them (after the
   experience map's gate; recall over the keyframes' frames), corrected ATE. Every keyframe the pipeline makes is
   recorded, with the odometer, as the loop detector receives it.
2. The pipeline with `matching.search_radius` unlimited (every stored keyframe a candidate, wherever the estimate
   is): false closures and recall.
3. The oracle floor: the same odometry and pose graph with every true revisit closed at its true relative pose
   (a detector that reads ground truth, here only, never in the SLAM path) and no gate: the ATE loop closure alone
   can reach with this odometry and back end.
4. The loop detector replayed over the recorded keyframes (every keyframe stored after its query, as with
   reuse_places off), with the defaults and with each step off: `fixed` (the verification in metres, not by the
   objects' covariances; no evidence test), `no places` (a retrieved keyframe matched alone, the query alone),
   `signature` (retrieval by the label and distance histogram instead of object triangles), and `unlimited radius`.
   Detector-level recall and false closures; for the defaults, the missed revisit keyframes by stage
   (benchmarks._loop_misses); for the defaults and the unlimited radius, the retrieval rank of the true place.

    python -m benchmarks.places [--quick] [--seeds 1 2 3] [--sequences 00 05 town] [--profile vo|heavy]
                                [--detector real|ideal] [--moving 0.2] [--config FILE.yaml] [--out FILE]
                                [--sweep-dir DIR] [--workers N] [--ray ADDRESS]

Default: KITTI 00, 02, 05, 06, 08 and the town route (its repeated-layout trap), seeds 1-6 (36 drives, about 25 min
on 2 cores), `vo`, `real`, static streets.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._loop_misses import CLASSES, replay
from benchmarks._sweep import SPECS, config_file, drive_runs, sweep_options, with_changes
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig, load_config
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.loops import LoopCriteria, evaluate_closures, true_revisits
from neoslam.evaluation.report import loop_metrics
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import invert_pose
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.keyframes import KeyframeStep
from neoslam.pipeline import NeoSLAM
from neoslam.sweep import load_spec
from neoslam.types import Keyframe, LoopClosure

SEQUENCES = ["00", "02", "05", "06", "08", "town"]
SEEDS, QUICK_SEEDS = [1, 2, 3, 4, 5, 6], [1]
SPEC = SPECS / "places.yaml"
UNLIMITED_M = 1e5  # matching.search_radius that takes every stored keyframe
VARIANTS = {
    "defaults": {},
    "fixed": {"matching": {"tolerances": "fixed", "min_inlier_ratio": 0.7, "max_contradictions": 2}},
    "no places": {"matching": {"place_radius": 0.0, "query_radius": 0.0}},
    "signature": {"matching": {"retrieval": "signature"}},
    "unlimited radius": {"matching": {"search_radius": UNLIMITED_M}},
}


def _with(config: NeoSLAMConfig, changes: dict) -> NeoSLAMConfig:
    """The config with some sections' fields replaced (checked)."""
    data = config.model_dump()
    for section, fields in changes.items():
        data[section] = data[section] | fields
    return NeoSLAMConfig.model_validate(data)


class _TrueClosures(LoopClosureDetector):
    """The oracle: each keyframe that truly revisits a place closes a loop with the stored keyframe nearest to it in
    truth, at the true relative pose. Benchmarks only: it reads ground truth."""

    def __init__(self, config: NeoSLAMConfig, truth: np.ndarray) -> None:
        super().__init__(config.keyframes, config.matching)
        self.truth = truth
        self.criteria = LoopCriteria(config.evaluation.loop_max_distance, config.evaluation.loop_min_frame_gap)

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        stored = [
            k for k in self.index.keyframes if k.frame_index <= keyframe.frame_index - self.criteria.min_frame_gap
        ]
        if not stored:
            return []
        positions = self.truth[[k.frame_index for k in stored], :2, 3]
        distance = np.linalg.norm(positions - self.truth[keyframe.frame_index, :2, 3], axis=1)
        nearest = int(np.argmin(distance))
        if distance[nearest] > self.criteria.max_distance_m:
            return []
        match = stored[nearest]
        relative = invert_pose(self.truth[match.frame_index]) @ self.truth[keyframe.frame_index]
        return [LoopClosure(keyframe.frame_index, match.frame_index, keyframe.id, match.id, 1.0, 0, relative)]


def _run(config: NeoSLAMConfig, dataset, detector: LoopClosureDetector | None = None):
    """The pipeline over the dataset (optionally with another loop detector); returns it and every keyframe made,
    with the odometer, as the detector received them."""
    slam = NeoSLAM(config)
    if detector is not None:
        slam.loop_detector = detector
    made: list[tuple[Keyframe, float]] = []

    def recorded(step: KeyframeStep) -> None:
        if step.keyframe is not None:
            made.append((step.keyframe, step.odometer_m))

    slam.keyframes.observers.append(recorded)
    start = time.perf_counter()
    for frame in dataset.frames():
        slam.step(frame)
    return slam, made, time.perf_counter() - start


def _pipeline_figures(slam: NeoSLAM, dataset, config: NeoSLAMConfig) -> dict:
    truth = dataset.ground_truth
    result = slam.result(np.zeros(0))
    loops = loop_metrics(result.loop_closures, truth, config.evaluation, result.keyframe_frames)
    estimate = result.estimate
    return {
        "recall": loops["recall"],
        "accepted": loops["accepted"],
        "false": loops["false_positive"],
        "revisits": loops["revisit_frames"],
        "ate_m": float(absolute_trajectory_error(estimate, truth, "se3").rmse),
    }


def _detector_figures(keyframes, odometers, config: NeoSLAMConfig, truth: np.ndarray, classify: bool) -> dict:
    result = replay(keyframes, odometers, config, truth, classify)
    frames = [k.frame_index for k in keyframes]
    criteria = LoopCriteria(config.evaluation.loop_max_distance, config.evaluation.loop_min_frame_gap)
    stats = evaluate_closures(result.closures, truth[:, :2, 3], criteria, frames)
    figures = {
        "recall": stats.recall,
        "accepted": stats.accepted,
        "false": stats.false_positive,
        "revisits": stats.revisit_frames,
        "query_ms_median": 1e3 * statistics.median(result.query_s) if result.query_s else 0.0,
    }
    if classify:
        figures["misses"] = dict(result.misses)
        figures["ranks"] = result.ranks
    return figures


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: the pipeline with the defaults, with the search radius unlimited and with true closures, and
    the detector replayed with each variant (JSON)."""
    dataset = read_dataset(data)
    truth = dataset.ground_truth.poses
    slam, made, seconds = _run(config, dataset)
    keyframes, odometers = [k for k, _ in made], [o for _, o in made]
    unlimited = _with(config, VARIANTS["unlimited radius"])
    oracle_config = _with(config, {"experience_map": {"closure_gate": "none"}})
    oracle, _, _ = _run(oracle_config, dataset, _TrueClosures(oracle_config, truth))
    result = {
        "pipeline": _pipeline_figures(slam, dataset, config) | {"loop_s": seconds},
        "pipeline_unlimited": _pipeline_figures(_run(unlimited, dataset)[0], dataset, unlimited),
        "oracle_ate_m": _pipeline_figures(oracle, dataset, oracle_config)["ate_m"],
        "odometry_ate_m": float(absolute_trajectory_error(dataset.odometry(), dataset.ground_truth, "se3").rmse),
        "keyframes": len(keyframes),
        "keyframe_revisits": int(
            true_revisits(truth[:, :2, 3], LoopCriteria(), [k.frame_index for k in keyframes]).sum()
        ),
    }
    every = _with(config, {"experience_map": {"reuse_places": False}})
    for name, changes in VARIANTS.items():
        classify = name in ("defaults", "unlimited radius")
        result[name] = _detector_figures(keyframes, odometers, _with(every, changes), truth, classify)
    return result


def _revisits(truth: np.ndarray, keyframes: list[Keyframe]) -> int:
    return int(true_revisits(truth[:, :2, 3], LoopCriteria(), [k.frame_index for k in keyframes]).sum())


def _pooled(runs: list[dict], key: str) -> dict:
    """Recall pooled over the drives (recalled / revisits), false closures summed."""
    revisits = sum(r[key]["revisits"] for r in runs)
    recalled = sum(round(r[key]["recall"] * r[key]["revisits"]) for r in runs if r[key]["recall"] is not None)
    return {"recall": recalled / revisits if revisits else None, "false": sum(r[key]["false"] for r in runs)}


def _median(values) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def tables(runs: list[dict]) -> dict[str, list[dict]]:
    """Per sequence (medians over seeds, false closures summed) and pooled: the pipeline, the variants, the
    stages, the ranks."""
    rows, variants, stages = [], [], []
    groups = {s: [r for r in runs if r["sequence"] == s] for s in dict.fromkeys(r["sequence"] for r in runs)}
    for sequence, mine in [*groups.items(), ("all", runs)]:
        pooled = _pooled(mine, "pipeline")
        rows.append(
            {
                "sequence": sequence,
                "seeds": len(mine),
                "recall_median": _median(r["pipeline"]["recall"] for r in mine),
                "recall_min": min(
                    (r["pipeline"]["recall"] for r in mine if r["pipeline"]["recall"] is not None), default=None
                ),
                "recall_pooled": pooled["recall"],
                "false": pooled["false"],
                "false_unlimited": _pooled(mine, "pipeline_unlimited")["false"],
                "recall_unlimited": _median(r["pipeline_unlimited"]["recall"] for r in mine),
                "ate_odometry_m": _median(r["odometry_ate_m"] for r in mine),
                "ate_m": _median(r["pipeline"]["ate_m"] for r in mine),
                "ate_oracle_m": _median(r["oracle_ate_m"] for r in mine),
            }
        )
        variant_row = {"sequence": sequence}
        for name in VARIANTS:
            pooled = _pooled(mine, name)
            variant_row[f"{name} recall"] = pooled["recall"]
            variant_row[f"{name} false"] = pooled["false"]
        variants.append(variant_row)
        misses = sum((Counter(r["defaults"]["misses"]) for r in mine), Counter())
        revisits = sum(r["defaults"]["revisits"] for r in mine)
        ranks = np.array([rank for r in mine for rank in r["defaults"]["ranks"]])
        stage_row = {"sequence": sequence, "revisit keyframes": revisits}
        stage_row |= {name: misses[name] / revisits if revisits else None for name in CLASSES}
        stage_row["true place first"] = float(np.mean(ranks == 0)) if len(ranks) else None
        stage_row["in top 10"] = float(np.mean((ranks >= 0) & (ranks < 10))) if len(ranks) else None
        whole = np.array([rank for r in mine for rank in r["unlimited radius"].get("ranks", [])])
        stage_row["in top 10, whole map"] = float(np.mean((whole >= 0) & (whole < 10))) if len(whole) else None
        stages.append(stage_row)
    return {"pipeline": rows, "variants": variants, "stages": stages}


QUICK = "KITTI 05 and the town route, seed 1"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, nargs="+", help=f"simulation seeds (default {SEEDS})")
    parser.add_argument("--sequences", nargs="+", help=f"drives (default {' '.join(SEQUENCES)})")
    parser.add_argument("--profile", default="vo", help="odometry noise profile (default vo)")
    parser.add_argument("--detector", default="real", help="detection profile: real (default) or ideal")
    parser.add_argument("--moving", type=float, default=0.0, help="share of the street's objects that move")
    parser.add_argument("--config", type=Path, help="a NeoSLAM config file (YAML) under every run")
    sweep_options(parser)


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    args = run.args
    sequences = args.sequences or (["05", "town"] if args.quick else SEQUENCES)
    seeds = args.seeds or (QUICK_SEEDS if args.quick else SEEDS)
    changes = config_file(args)
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"route": n} if n == "town" else {"kitti": n} for n in sequences],
        noise=[args.profile],
        detectors=[args.detector],
        seeds=seeds,
        overrides={"defaults": {"simulator": {"world": {"moving_fraction": args.moving}}}},
        metrics=["keyframes"],
        data_root=data_root(),
        **changes,
    )
    runs = drive_runs(spec, args, measure, "places")
    base = load_config(args.config, environ={})
    out = tables(runs)
    street = f"{args.moving:.0%} of objects moving" if args.moving else "static streets"
    print(f"## Simulated drives: odometry {args.profile}, detection profile {args.detector}, {street}, seeds {seeds}\n")
    print("Pipeline (defaults): loop recall at the keyframes' frames (median and min over seeds, and pooled), false")
    print("closures (summed), the same with the search radius unlimited, and ATE RMSE (m, SE(3)-aligned, medians) of")
    print("the odometry, the corrected map and the oracle floor (every true revisit closed at its true pose):\n")
    run.table("pipeline", out["pipeline"], list(out["pipeline"][0]))
    print("Loop detector replayed over the same keyframes (every keyframe stored), each step off in turn; recall")
    print("pooled, false closures summed:\n")
    run.table("variants", out["variants"], list(out["variants"][0]))
    print("Revisit keyframes the detector (defaults) missed, by stage, as shares of the revisit keyframes; and how")
    print(f"often the true place is the first retrieved, or among the first {base.matching.candidates} places (also")
    print("with the search radius unlimited: every stored keyframe a candidate):\n")
    run.table("stages", out["stages"], list(out["stages"][0]))
    run.finish({"runs": runs, **out})


if __name__ == "__main__":
    main()
