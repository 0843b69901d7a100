"""Loop closure by object keyframes: precision and recall on simulated KITTI drives, and query time against map size.

(a) Accuracy: `neoslam simulate` (profile vo, or --profile) on KITTI 00, 02, 05, 06 and 08 for several seeds, then
    the pipeline (default config, or --config);
    closures judged against ground truth (true when within 5 m horizontally and 100 frames apart; 3-D precision
    too), recall over the keyframes that truly revisit a place. Also the default town scenario, whose repeated
    layout must give no false closure. Each drive is run three times: with our keyframe neighbourhood (30 m), with
    the paper's (e_max = 1.5 m around the current object, and no minimum number of objects: with ours, 4, such a
    small neighbourhood never makes a keyframe, since street objects stand metres apart), and with ours but without
    the last two checks of the verification (contradicted objects, heading drift), whose closures show what those
    checks see: contradicted objects and the heading drift of the fit, of true and of false closures. Revisit
    keyframes left without a true closure are sorted by why (`_loop_misses.py`).
(b) Speed: median query time (retrieval + matching + verification) with 100 ... 20,000 keyframes stored, built by
    laying the keyframes of the drives of (a), each in a world of its own, far apart, and again from the first when
    all are laid, each copy's objects moved by a smooth random field of its own (distinct places; at the largest
    size also with exact copies, every place stored about ten times over); revisits and new places apart; within the
    drift-bounded search radius and over the whole map (every stored keyframe a candidate: a later session, a lost
    robot); the retrieval index's memory; and at the largest map also with the exact eigenvector (power iteration
    run to 1e-9, at most 100 products). The rows' queries are timed in turn, one of each row after another, so that
    the rows compare within one run (benchmarks._loop_speed).

    python -m benchmarks.loops [--quick] [--seeds N ...] [--sequences 08 town ...] [--profile vo|heavy]
                               [--config FILE.yaml] [--out FILE] [--sweep-dir DIR] [--workers N] [--ray ADDRESS]

The drives of (a) are one sweep, `benchmarks/specs/loops.yaml` (`neoslam sweep`, with this file's `measure` as each
cell's measurement): on a local pool, one worker per core, or Ray tasks (`--ray`: the workers need this folder on
their PYTHONPATH); `--sweep-dir DIR` keeps the sweep folder, and running again resumes it.

Seeds 1-10 were looked at while the verification was designed (the contradiction and heading-drift checks);
seeds 11 and up were not: `--seeds 11 12 13 14 15 16` measures on drives held out from that design.
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._loop_misses import CLASSES as MISS_CLASSES
from benchmarks._loop_misses import replay
from benchmarks._loop_speed import MAP_SIZES, QUERIES, QUICK_MAP_SIZES, query_speed
from benchmarks._sweep import SPECS, config_file, run_spec, sweep_options, with_changes
from benchmarks.harness import data_root
from neoslam.config import KeyframeConfig, MatchingConfig, NeoSLAMConfig, load_config
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.loops import LoopCriteria, evaluate_closures, judge_closures
from neoslam.geometry import invert_pose, rotation_angle
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.matching import contradictions
from neoslam.pipeline import NeoSLAM
from neoslam.sweep import load_spec
from neoslam.types import Keyframe, LoopClosure

SEQUENCES = ["00", "02", "05", "06", "08"]
SEEDS = [1, 2, 3, 4, 5, 6]
SPEC = SPECS / "loops.yaml"  # overrides: ours, paper_keyframes (e_max = 1.5 m), without_last_checks
VARIANTS = ("ours", "paper_keyframes", "without_last_checks")


def _every_keyframe_stored(config: NeoSLAMConfig) -> NeoSLAMConfig:
    """The detector is judged on every keyframe: none is merged into a stored one it recognises (lifelong mapping,
    experience_map.reuse_places), so that each is queried, stored and classified here, whatever it matched."""
    experience_map = config.experience_map.model_copy(update={"reuse_places": False})
    return config.model_copy(update={"experience_map": experience_map})


def _drive(config: NeoSLAMConfig, data: Path) -> tuple[NeoSLAM, np.ndarray, list[float], set[int]]:
    """Run the pipeline on a dataset; returns it, the true poses, the wall time of each loop query and the ids of
    the keyframes the detector relocalised."""
    dataset = read_dataset(data)
    config = _every_keyframe_stored(config)
    slam = NeoSLAM(config)
    detector = slam.loop_detector = _ObservedDetector(config.keyframes, config.matching)
    for frame in dataset.frames():
        slam.step(frame)
    return slam, dataset.ground_truth.poses, detector.query_times, detector.relocalised


class _ObservedDetector(LoopClosureDetector):
    """The pipeline's loop detector, unchanged, that also times each query and notes the keyframes it relocalised."""

    def __init__(self, keyframes: KeyframeConfig, matching: MatchingConfig) -> None:
        super().__init__(keyframes, matching)
        self.query_times: list[float] = []
        self.relocalised: set[int] = set()

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        start = time.perf_counter()
        accepted = super().query(keyframe, odometer_m)
        self.query_times.append(time.perf_counter() - start)
        return accepted

    def relocalise(self, keyframe: Keyframe, odometer_m: float):
        found = super().relocalise(keyframe, odometer_m)
        if found is not None:
            self.relocalised.add(keyframe.id)
        return found


def _judge(slam: NeoSLAM, truth: np.ndarray, horizontal: bool) -> dict:
    frames = np.array([k.frame_index for k in slam.loop_detector.index.keyframes])
    positions = truth[:, :2] if horizontal else truth
    # The detector's closures: the experience map's closure gate is a separate, later guard.
    return evaluate_closures(slam.detected_closures, positions, LoopCriteria(), frames).as_dict()


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: the drive through the pipeline, its closures judged and its misses sorted (JSON); its keyframes
    go to out/keyframes.pkl (kept with the cell), for the query-speed part."""
    result = _accuracy_of(config, data)
    out.mkdir()
    with (out / "keyframes.pkl").open("wb") as handle:
        pickle.dump(result.pop("_keyframes"), handle)
    del result["_odometer"]
    result["_misses"] = dict(result["_misses"])
    result["timing"] = {"query_ms_median": result.pop("query_ms_median")}  # the machine's: kept out of sweep.csv
    return result


def _closure_evidence(slam: NeoSLAM, truth: np.ndarray) -> list[dict]:
    """Per detected closure: true or not, its contradicted objects and its fit's heading drift (deg per 100 m)."""
    index, matching = slam.loop_detector.index, slam.config.matching
    correct = judge_closures(slam.detected_closures, truth[:, :2], LoopCriteria())
    evidence = []
    for closure, right in zip(slam.detected_closures, correct, strict=True):
        query, stored = index.keyframes[closure.query_keyframe], index.keyframes[closure.match_keyframe]
        transform = stored.pose @ closure.relative_pose @ invert_pose(query.pose)  # query world -> stored world
        travelled = index.odometer(query.id) - index.odometer(stored.id)
        turn = float(np.degrees(rotation_angle(transform[:3, :3])))
        evidence.append(
            {
                "true": bool(right),
                "contradictions": contradictions(query, stored, transform, matching),
                "yaw_deg_per_100m": 100.0 * turn / max(travelled, 1.0),
                "yaw_deg": turn,
            }
        )
    return evidence


def _misses(slam: NeoSLAM, config: NeoSLAMConfig, poses: np.ndarray):
    """The revisit keyframes the detector missed, by why (a replay of the detector over the drive's keyframes)."""
    keyframes = list(slam.loop_detector.index.keyframes)
    odometers = [slam.loop_detector.index.odometer(k.id) for k in keyframes]
    return replay(keyframes, odometers, _every_keyframe_stored(config), poses).misses


def _accuracy_of(config: NeoSLAMConfig, data: Path) -> dict:
    slam, poses, query_times, relocalised = _drive(config, data)
    truth = poses[:, :3, 3]
    flat, full = _judge(slam, truth, horizontal=True), _judge(slam, truth, horizontal=False)
    keyframes = slam.loop_detector.index.keyframes
    return {
        "neighbourhood_m": config.keyframes.neighbourhood_radius,
        "keyframes": len(keyframes),
        "max_objects": max((len(k.labels) for k in keyframes), default=0),
        "revisit_keyframes": flat["revisit_frames"],
        "accepted": flat["accepted"],
        "false_positive": flat["false_positive"],
        "precision": flat["precision"],
        "recall": flat["recall"],
        "f1": flat["f1"],
        "recall_at_full_precision": flat["recall_at_full_precision"],
        "precision_3d": full["precision"],
        "query_ms_median": 1e3 * statistics.median(query_times) if query_times else 0.0,
        "_evidence": _closure_evidence(slam, truth),
        "_misses": _misses(slam, config, poses),
        "_keyframes": list(slam.loop_detector.index.keyframes),
        "_odometer": slam.keyframes.odometer_m,
    }


def _paper_note(paper: list[dict], config: NeoSLAMConfig) -> str:
    """What limits the paper's keyframes, from the keyframes the runs made."""
    largest = max((r["max_objects"] for r in paper), default=0)
    return (
        f"The paper's keyframes hold at most {largest} objects; our default keyframes need "
        f"{config.keyframes.min_objects} and a verified match {config.matching.min_inliers}."
    )


def summary(runs: list[dict]) -> list[dict]:
    """Per sequence over its seeds: false closures, pooled precision, and the spread of recall."""
    rows = []
    for sequence in dict.fromkeys(r["sequence"] for r in runs):
        mine = [r for r in runs if r["sequence"] == sequence]
        accepted = sum(r["accepted"] for r in mine)
        false = sum(r["false_positive"] for r in mine)
        recall = [r["recall"] for r in mine if r["recall"] is not None]
        rows.append(
            {
                "sequence": sequence,
                "seeds": len(mine),
                "accepted": accepted,
                "false_positive": false,
                "precision": (accepted - false) / accepted if accepted else None,
                "recall_min": min(recall, default=None),
                "recall_median": statistics.median(recall) if recall else None,
                "recall_max": max(recall, default=None),
            }
        )
    return rows


def _share(rows: list[dict], test) -> float:
    return sum(map(test, rows)) / len(rows) if rows else float("nan")


def checks_seen(unchecked: list[dict], limit: int) -> dict:
    """What the contradiction and heading-drift checks see in the closures accepted without them."""
    evidence = [e for r in unchecked for e in r["_evidence"]]
    true = [e for e in evidence if e["true"]]
    false = [e for e in evidence if not e["true"]]
    return {
        "false_closures": len(false),
        "false_closure_drives": sum(r["false_positive"] > 0 for r in unchecked),
        "true_closures": len(true),
        "true_without_contradiction": _share(true, lambda e: e["contradictions"] == 0),
        "true_within_limit": _share(true, lambda e: e["contradictions"] <= limit),
        "false_contradictions": sorted({e["contradictions"] for e in false}),
        "true_max_yaw_deg_per_100m": max((e["yaw_deg_per_100m"] for e in true), default=float("nan")),
        "false_yaw_deg": sorted({round(e["yaw_deg"]) for e in false}),
    }


QUICK = "KITTI 05, 08 and the town route, seed 1; smaller maps and fewer queries for the speed"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, nargs="+", help=f"simulation seeds (default {SEEDS}; 11 and up held out)")
    parser.add_argument("--profile", default="vo", help="odometry noise profile of the simulated drives (default vo)")
    parser.add_argument(
        "--detector", default="real", help="detection profile of the simulator: real (default, calibrated) or ideal"
    )
    parser.add_argument("--sequences", nargs="+", help=f"drives (default {' '.join(SEQUENCES)} town)")
    parser.add_argument("--config", type=Path, help="a NeoSLAM config file (YAML) instead of the defaults")
    sweep_options(parser)


def misses_table(runs: list[dict]) -> list[dict]:
    """Missed revisit keyframes by class, per sequence over its seeds."""
    rows = []
    for sequence in dict.fromkeys(r["sequence"] for r in runs):
        mine = [r for r in runs if r["sequence"] == sequence]
        rows.append({"sequence": sequence, **{c: sum(r["_misses"][c] for r in mine) for c in MISS_CLASSES}})
    return rows


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    args = bench.args
    sequences = args.sequences or (["05", "08", "town"] if args.quick else [*SEQUENCES, "town"])
    base = load_config(args.config, environ={})
    seeds = args.seeds or (SEEDS[:1] if args.quick else SEEDS)
    changes = config_file(args)
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"route": n} if n == "town" else {"kitti": n} for n in sequences],
        noise=[args.profile],
        detectors=[args.detector],
        seeds=seeds,
        keep_results=True,  # each cell's keyframes.pkl
        metrics=["keyframes", "accepted", "false_positive", "precision", "recall"],  # what `measure` returns
        data_root=data_root(),
        **changes,
    )
    variants: dict[str, list[dict]] = {name: [] for name in VARIANTS}
    with run_spec(spec, args, measure=measure) as sweep:
        for record in sweep.failed:
            cell = record.cell
            print(f"- failed: {cell.source} seed {cell.seed} {cell.override}: {record.error}")
        for record in sweep.records:
            if record.status == "ok":
                metrics = dict(record.metrics)
                metrics["query_ms_median"] = metrics.pop("timing")["query_ms_median"]
                drive = {"sequence": record.cell.source, "seed": record.cell.seed, "_folder": record.folder}
                variants[record.cell.override].append(drive | metrics)
        runs, paper, unchecked = (variants[name] for name in VARIANTS)
        if not (runs and paper and unchecked):
            sys.exit("loops: a variant has no drive that ran (the errors above; tracebacks in the cells' error.txt)")
        drives = []
        for run in runs:
            with (run["_folder"] / "results" / "keyframes.pkl").open("rb") as handle:
                drives.append(pickle.load(handle))
        sweep_summary = sweep.summary
    sizes = QUICK_MAP_SIZES if args.quick else MAP_SIZES
    speed = query_speed(drives, sizes, QUERIES // 4 if args.quick else QUERIES)
    columns = ["sequence", "seed", "keyframes", "revisit_keyframes", "accepted", "false_positive", "precision",
               "recall", "f1", "recall_at_full_precision", "precision_3d", "query_ms_median"]  # fmt: skip
    public = [{k: v for k, v in r.items() if not k.startswith("_")} for r in runs]
    paper_public = [{k: v for k, v in r.items() if not k.startswith("_")} for r in paper]
    print(f"## (a) Loop closures on simulated drives (detector {args.detector}, profile {args.profile}), "
          "judged within 5 m horizontally, "
          "100 frames apart\n")  # fmt: skip
    print(f"Our keyframes: objects within {runs[0]['neighbourhood_m']:.1f} m of the current object.\n")
    bench.table("drives", public, columns)
    print(f"Per sequence over seeds {', '.join(map(str, seeds))}:\n")
    summary_columns = ["sequence", "seeds", "accepted", "false_positive", "precision", "recall_min",
                       "recall_median", "recall_max"]  # fmt: skip
    bench.table("summary", summary(public), summary_columns)
    print(f"The paper's keyframes: objects within {paper[0]['neighbourhood_m']:.1f} m (e_max), no minimum count.\n")
    bench.table("paper_keyframes", paper_public, [*columns[:3], "max_objects", *columns[3:]])
    print(_paper_note(paper, base))
    unchecked_public = [{k: v for k, v in r.items() if not k.startswith("_")} for r in unchecked]
    limit = base.matching.max_contradictions
    seen = checks_seen(unchecked, limit)
    print("\nWithout the contradiction and heading-drift checks:\n")
    bench.table("without_last_checks", summary(unchecked_public), summary_columns)
    print(
        f"There, {seen['false_closures']} false closures on {seen['false_closure_drives']} drives, with "
        f"{seen['false_contradictions']} contradicted objects and turned by {seen['false_yaw_deg']}°; of "
        f"{seen['true_closures']} true closures, {seen['true_without_contradiction']:.1%} have no contradicted object "
        f"and {seen['true_within_limit']:.1%} at most {limit}; the true fits turn at most "
        f"{seen['true_max_yaw_deg_per_100m']:.2f}° per 100 m travelled."
    )
    misses = misses_table(runs)
    print("\nMissed revisit keyframes, by why (see benchmarks._loop_misses):\n")
    bench.table("misses", misses, ["sequence", *MISS_CLASSES])
    print("\n## (b) Query time (retrieval + matching + verification) against map size\n")
    speed_columns = ["map", "eigenvector", "scope", "map_size", "queries", "eligible_median", "revisit_ms_median",
                     "new_place_ms_median", "query_ms_median", "query_ms_p95", "index_mb", "keyframes_mb",
                     "places_mb"]  # fmt: skip
    bench.table("speed", speed, speed_columns)

    def at_largest(layout: str, scope: str) -> dict:
        return next(
            row for row in speed
            if (row["map"], row["eigenvector"], row["scope"], row["map_size"]) == (layout, "default", scope, max(sizes))
        )  # fmt: skip

    largest, whole = at_largest("distinct", "drift-bounded"), at_largest("distinct", "whole map")
    repeated = at_largest("repeated", "drift-bounded")
    print(
        f"At {largest['map_size']} keyframes of distinct places: median {largest['query_ms_median']:.2f} ms, new "
        f"places {largest['new_place_ms_median']:.2f} ms, revisits {largest['revisit_ms_median']:.2f} ms; searching "
        f"the whole map: median {whole['query_ms_median']:.2f} ms; with every place stored about ten times over: "
        f"median {repeated['query_ms_median']:.2f} ms, revisits {repeated['revisit_ms_median']:.2f} ms; retrieval "
        f"index {whole['index_mb']:.1f} MB, stored keyframes {whole['keyframes_mb']:.0f} MB, cached places "
        f"{whole['places_mb']:.0f} MB."
    )
    print("\n" + sweep_summary.replace("# Sweep", "Sweep", 1))
    bench.finish(
        {
            "query_ms_median": largest["query_ms_median"],
            "new_place_ms_median": largest["new_place_ms_median"],
            "revisit_ms_median": largest["revisit_ms_median"],
            "repeated_query_ms_median": repeated["query_ms_median"],
            "map_sizes": sizes,
            "speed": speed,
            "accuracy": public,
            "accuracy_summary": summary(public),
            "accuracy_paper_keyframes": paper_public,
            "accuracy_without_last_checks": summary(unchecked_public),
            "checks_seen": seen,
            "misses": misses,
        },
    )


if __name__ == "__main__":
    main()
