"""The whole NeoSLAM pipeline on simulated KITTI drives: odometry against the paper's relaxation and the pose graph.

For each sequence, odometry noise profile and seed: `neoslam simulate` on the real KITTI ground truth, then
`neoslam run` with each back end, plus the pose graph without the paper's grid-cell check of loop candidates (to
show what that check costs under heavy drift). Loop closures are judged within 5 m horizontally, 100 frames apart.
The runs are one sweep, `benchmarks/specs/kitti_sim.yaml` (`neoslam sweep`; the three back ends share each drive's
simulation): on a local pool, one worker per core, or on a Ray cluster (`--ray ADDRESS`); `--out DIR` keeps the
sweep folder, and running again resumes it. Timing columns are per run.

    python benchmarks/kitti_sim.py [--quick] [--json FILE] [--sequences 05 08] [--profiles vo] [--seeds 1 2 3]
                                   [--detectors real ideal] [--out DIR] [--workers N] [--ray ADDRESS]

`--detectors`: the simulator's detection profiles (default: real, the street and detector calibrated to the real
front end on KITTI 06; ideal, the richer street of the first benchmarks).
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import data_root, markdown_table, parse_args, write_json  # noqa: E402
from _sweep import SPECS, run_spec, sweep_options, with_changes  # noqa: E402
from neoslam.sim.profiles import DETECTION_PROFILES  # noqa: E402
from neoslam.sweep import load_spec  # noqa: E402

SEQUENCES = ["00", "02", "05", "06", "07", "08"]
PROFILES = ["vo", "heavy"]
SEEDS = [1, 2, 3]
SPEC = SPECS / "kitti_sim.yaml"  # overrides relaxation, pose_graph, pose_graph_no_cell_check


def _arguments(parser) -> None:
    parser.add_argument("--sequences", nargs="+", default=SEQUENCES)
    parser.add_argument("--profiles", nargs="+", default=PROFILES)
    parser.add_argument("--seeds", nargs="+", type=int, default=SEEDS)
    parser.add_argument("--detectors", nargs="+", default=["real"], choices=sorted(DETECTION_PROFILES))
    sweep_options(parser)


def _drives(records) -> tuple[list[dict], list[str]]:
    """The sweep's cells gathered per drive (sequence, detector, profile, seed): a row of the three back ends;
    a drive with a failed cell is left out and its errors returned."""
    drives: dict[tuple, dict] = {}
    errors = []
    for record in records:
        cell = record.cell
        drives.setdefault((cell.source, cell.detector, cell.noise, cell.seed), {})[cell.override] = record.metrics
        if record.status != "ok":
            errors.append(
                f"{cell.source} {cell.detector} {cell.noise} seed {cell.seed} {cell.override}: {record.error}"
            )
    rows = [row(*key, metrics) for key, metrics in drives.items() if all(m is not None for m in metrics.values())]
    return rows, errors


def row(sequence: str, detector: str, profile: str, seed: int, metrics: dict[str, dict]) -> dict:
    """One drive's figures from the metrics of its three runs."""
    graph = metrics["pose_graph"]
    return {
        "sequence": sequence,
        "detector": detector,
        "profile": profile,
        "seed": seed,
        "frames": graph["frames"],
        "ate_odometry_m": graph["ate_rmse_m"]["odometry"],
        "ate_relaxation_m": metrics["relaxation"]["ate_rmse_m"]["corrected"],
        "ate_pose_graph_m": graph["ate_rmse_m"]["corrected"],
        "ate_pose_graph_no_cell_check_m": metrics["pose_graph_no_cell_check"]["ate_rmse_m"]["corrected"],
        "rpe_100m_pose_graph_m": graph["trajectory"]["corrected"]["rpe_translation_rmse_m"],
        "kitti_t_percent_odometry": graph["trajectory"]["odometry"]["kitti_translation_percent"],
        "kitti_t_percent_pose_graph": graph["trajectory"]["corrected"]["kitti_translation_percent"],
        "loops_accepted": graph["loops"]["accepted"],
        "loops_false": graph["loops"]["false_positive"],
        "loop_precision": graph["loops"]["precision"],
        "loop_recall": graph["loops"]["recall"],
        "rejected_by_cells": graph["experience_map"]["closures_rejected_by_grid_cells"],
        "loops_false_no_cell_check": metrics["pose_graph_no_cell_check"]["loops"]["false_positive"],
        "fps": graph["timing"]["fps"],
        "fps_relaxation": metrics["relaxation"]["timing"]["fps"],
        "wall_s": graph["timing"]["wall_s"],
        "ms_per_frame_median": graph["timing"]["ms_per_frame_median"],
        "ms_per_frame_p95": graph["timing"]["ms_per_frame_p95"],
    }


def _medians(rows: list[dict], keys: list[str]) -> list[dict]:
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["sequence"], row["detector"], row["profile"]), []).append(row)
    summary = []
    for (sequence, detector, profile), group in groups.items():
        present = {k: [r[k] for r in group if r[k] is not None] for k in keys}
        values = {k: statistics.median(v) if v else None for k, v in present.items()}
        summary.append({"sequence": sequence, "detector": detector, "profile": profile, "seeds": len(group)} | values)
    return summary


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], _arguments)
    sequences, seeds = (["05"], args.seeds[:1]) if args.quick else (args.sequences, args.seeds)
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"kitti": sequences}],
        noise=args.profiles,
        detectors=args.detectors,
        seeds=seeds,
        data_root=data_root(),
    )
    with run_spec(spec, args) as sweep:
        rows, errors = _drives(sweep.records)
        summary = sweep.summary
    order = {"sequence": sequences, "detector": args.detectors, "profile": args.profiles}
    rows.sort(key=lambda r: (*(order[k].index(r[k]) for k in order), r["seed"]))
    if errors:
        print("Failed runs (left out):\n\n" + "\n".join(f"- {e}" for e in errors) + "\n")
    columns = ["sequence", "detector", "profile", "seed", "frames", "ate_odometry_m", "ate_relaxation_m",
               "ate_pose_graph_m", "ate_pose_graph_no_cell_check_m", "loops_accepted", "loops_false", "loop_precision",
               "loop_recall", "rejected_by_cells", "loops_false_no_cell_check", "fps", "ms_per_frame_median",
               "ms_per_frame_p95"]  # fmt: skip
    print(markdown_table(rows, columns))
    keys = ["ate_odometry_m", "ate_relaxation_m", "ate_pose_graph_m", "ate_pose_graph_no_cell_check_m",
            "rpe_100m_pose_graph_m", "kitti_t_percent_odometry", "kitti_t_percent_pose_graph", "loop_precision",
            "loop_recall", "fps", "wall_s", "ms_per_frame_median", "ms_per_frame_p95"]  # fmt: skip
    medians = _medians(rows, keys)
    print("\nMedian over seeds:\n")
    print(markdown_table(medians, ["sequence", "detector", "profile", "seeds", *keys]))
    print("\n" + summary.replace("# Sweep", "Sweep", 1))
    write_json(args.json, {"rows": rows, "medians": medians})


if __name__ == "__main__":
    main()
