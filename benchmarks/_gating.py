"""Part `gating` of the kitti_sim study: which loop closures the experience map accepts: the paper's grid-cell check
against the drift gate, which widens it with the metres travelled since the robot last knew where it was, and no gate
at all.

For each KITTI sequence, odometry noise profile and seed: the real ground truth simulated once (`real` detection
profile), then NeoSLAM run with each gate (a sweep, `benchmarks/specs/gating.yaml`, with `measure` below as each
cell's measurement) (`experience_map.closure_gate`; `drift` at each rate of
--rates, cells per 100 m), each with the cells recalled on every closure the detector accepts (`hebbian.recall_on:
detected`, NeuroSLAM's local-view calibration) and only on those the gate accepted (`accepted`, the paper's order
and the default; "+ paper recall").
Besides the KITTI drives, a trap that only a gate can stop: the built-in town route, whose one street repeats
another's layout 370 m away, with the loop detector's retrieval radius opened to 1 km so that the two are compared
(`town-trap`; the default radius keeps them apart). Per run: ATE RMSE (SE(3)-aligned) of the odometry and of the
corrected trajectory, the closures the map accepted and how many are false (judged against the ground truth:
within 5 m horizontally, 100 frames apart), loop recall, and the closures the gate rejected. Then the targets per
gate: with `heavy` odometry no false closure on any KITTI drive, corrected ATE at most a quarter of the odometry's on
05 and 06; with `vo` no drive worse than the paper's check with recall on detected; and the false closures of the
trap. Ground truth is read for judging only.

    python -m benchmarks.kitti_sim --parts gating [--sequences 00 02 05 06 08] [--profiles vo heavy] [--seeds 1]
                                   [--gates grid-cells drift none] [--rates 2] [--recall-on detected accepted]
                                   [--no-trap]

`--quick`: KITTI 05 and the trap only.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from benchmarks import harness
from benchmarks._sweep import SPECS, run_spec, with_changes
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.report import loop_metrics
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.pipeline import run
from neoslam.sweep import load_spec

SEQUENCES = ["00", "02", "05", "06", "08"]
PROFILES = ["vo", "heavy"]
GATES = ["grid-cells", "drift", "none"]
RECALLS = ["detected", "accepted"]
QUARTER_ON = ("05", "06")  # the ATE target: corrected at most a quarter of the odometry's here
SPEC = SPECS / "gating.yaml"  # the default variants; the options below replace them
TRAP = "town-trap"
TRAP_SEARCH_RADIUS_M = 1000.0  # matching.search_radius: the town's two look-alike streets are 370 m apart
PAPER_CHECK = "grid-cells"  # the paper's check, cells recalled on every detected closure: the reference for vo


QUICK = "KITTI 05 and the trap only"


def arguments(group: argparse._ArgumentGroup) -> None:
    group.add_argument("--gates", nargs="+", default=GATES, choices=GATES, help="gating: the closure gates")
    group.add_argument(
        "--rates", nargs="+", type=float, default=[2.0], help="gating: drift gate cells per 100 m (the config's 2)"
    )
    group.add_argument("--recall-on", nargs="+", default=RECALLS, choices=RECALLS, help="gating: hebbian.recall_on")
    group.add_argument("--no-trap", action="store_true", help="gating: leave out the town trap")


def _variants(gates: list[str], rates: list[float], recalls: list[str]) -> list[tuple[str, dict]]:
    """(name, config sections to change) of each run of a drive: each gate (drift once per rate) with each recall
    (none once: with no gate, every detected closure is accepted and recalled either way)."""
    gate_settings = []
    for gate in gates:
        if gate != "drift":
            gate_settings.append((gate, {"closure_gate": gate}))
            continue
        for rate in rates:
            name = f"drift {rate:g}" if len(rates) > 1 else "drift"
            gate_settings.append((name, {"closure_gate": gate, "gc_drift_cells_per_100m": rate}))
    variants = []
    for recall in recalls:
        suffix = "" if recall == "detected" else " + paper recall"
        for name, settings in gate_settings:
            if settings["closure_gate"] != "none" or recall == recalls[0]:
                variants.append((name + suffix, {"experience_map": settings, "hebbian": {"recall_on": recall}}))
    return variants


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: NeoSLAM over one simulated drive with one gate, in this process; the figures of one row."""
    dataset = read_dataset(data)
    frames = list(dataset.frames())
    truth = dataset.ground_truth
    assert truth is not None
    start = time.perf_counter()
    result = run(iter(frames), config, total=len(frames), progress=False)
    run_s = time.perf_counter() - start
    loops = loop_metrics(result.session_closures(), truth, config.evaluation, result.keyframe_frames)
    odometry = absolute_trajectory_error(result.odometry, truth, "se3").rmse
    corrected = absolute_trajectory_error(result.estimate, truth, "se3").rmse
    return {
        "ate_odometry_m": odometry,
        "ate_corrected_m": corrected,
        "corrected_share": corrected / odometry,
        "closures_accepted": loops["accepted"],
        "closures_false": loops["false_positive"],
        "closures_rejected": len(result.experience_map.rejected_closures),
        "loop_recall": loops["recall"],
        "run_s": run_s,
    }


def _sweep(bench_args: argparse.Namespace, spec, sources: list[dict], variants, profiles, seeds, label=None):
    """The rows of the spec's cells on these sources and variants (a failed cell left out, its error returned)."""
    spec = with_changes(
        spec,
        sources=sources,
        noise=profiles,
        seeds=seeds,
        overrides=dict(variants),
        metrics=["ate_corrected_m", "closures_false", "loop_recall"],
        data_root=data_root(),
    )
    rows, errors = [], []
    with run_spec(spec, bench_args, measure=measure) as sweep:
        for record in sweep.records:
            cell = record.cell
            source = label or cell.source
            if record.status != "ok":
                errors.append(f"{source} {cell.noise} seed {cell.seed} {cell.override}: {record.error}")
                continue
            rows.append({"sequence": source, "profile": cell.noise, "seed": cell.seed, "gate": cell.override}
                        | record.metrics)  # fmt: skip
    return rows, errors


def _drive(row: dict) -> tuple[str, str, int]:
    return row["sequence"], row["profile"], row["seed"]


def targets(rows: list[dict], gates: list[str]) -> list[dict]:
    """Per gate, the targets on the KITTI drives: heavy ones without a false closure; heavy 05 and 06 corrected to
    at most a quarter of the odometry's ATE; vo ones no worse than the paper's check (the worst drive's corrected
    ATE over the paper check's); and the trap's false closures."""
    paper = {_drive(r): r["ate_corrected_m"] for r in rows if r["gate"] == PAPER_CHECK}
    summary = []
    for gate in gates:
        kitti = [r for r in rows if r["gate"] == gate and r["sequence"] != TRAP]
        heavy = [r for r in kitti if r["profile"] == "heavy"]
        quarter = [r for r in heavy if r["sequence"] in QUARTER_ON]
        vo = [r for r in kitti if r["profile"] == "vo"]
        against_paper = [r["ate_corrected_m"] / paper[_drive(r)] for r in vo if _drive(r) in paper]
        trap = [r for r in rows if r["gate"] == gate and r["sequence"] == TRAP]
        summary.append(
            {
                "gate": gate,
                "heavy_drives": len(heavy),
                "heavy_false_closures": sum(r["closures_false"] for r in heavy),
                "heavy_05_06_at_most_quarter": f"{sum(r['corrected_share'] <= 0.25 for r in quarter)}/{len(quarter)}",
                "heavy_worst_share_05_06": max((r["corrected_share"] for r in quarter), default=None),
                "vo_false_closures": sum(r["closures_false"] for r in vo),
                "vo_worst_ate_vs_paper_check": max(against_paper, default=None),
                "trap_false_closures": sum(r["closures_false"] for r in trap) if trap else None,
                "trap_worst_ate_m": max((r["ate_corrected_m"] for r in trap), default=None),
            }
        )
    return summary


def run_part(bench: harness.Run, args: argparse.Namespace) -> dict:
    profiles, seeds = args.profiles or PROFILES, args.seeds or [1]
    sources = (["05"] if args.quick else args.sequences or SEQUENCES) + ([] if args.no_trap else [TRAP])
    variants = _variants(args.gates, args.rates, args.recall_on)
    spec = load_spec(SPEC)
    kitti = [s for s in sources if s != TRAP]
    rows, errors = _sweep(args, spec, [{"kitti": kitti}], variants, profiles, seeds) if kitti else ([], [])
    if TRAP in sources:  # the trap: the town route with the search radius opened, under every variant
        opened = [
            (name, sections | {"matching": {"search_radius": TRAP_SEARCH_RADIUS_M}}) for name, sections in variants
        ]
        trap_rows, trap_errors = _sweep(args, spec, [{"route": "town"}], opened, profiles, seeds, label=TRAP)
        rows, errors = rows + trap_rows, errors + trap_errors
    if errors:
        print("Failed runs (left out):\n\n" + "\n".join(f"- {e}" for e in errors) + "\n")
    names = [name for name, _ in variants]
    rows.sort(key=lambda r: (profiles.index(r["profile"]), sources.index(r["sequence"]), r["seed"],
                             names.index(r["gate"])))  # fmt: skip
    columns = ["sequence", "profile", "seed", "gate", "ate_odometry_m", "ate_corrected_m", "corrected_share",
               "closures_accepted", "closures_false", "closures_rejected", "loop_recall", "run_s"]  # fmt: skip
    bench.table("gating", rows, columns)
    summary = targets(rows, names)
    bench.table(
        "gating_targets",
        summary,
        list(summary[0]),
        title="Targets of the closure gate (KITTI drives, and the town trap apart):",
    )
    return {"rows": rows, "targets": summary, "failed": errors}
