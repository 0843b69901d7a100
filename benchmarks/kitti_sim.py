"""The whole NeoSLAM pipeline on simulated KITTI drives: three steps beyond the paper, each on alone and together,
and a closer look at each step.

Parts (`--parts`, default all four, in this order):

- `steps`: for each sequence, odometry noise profile, detection profile and seed, `neoslam simulate` on the real KITTI
  ground truth (a share --moving of the street's objects move: traffic in both directions, people walking), then
  `neoslam run` with the paper's relaxation, the pose graph without the steps (`baseline`: grid-cell check, cells
  recalled on every detected closure, no motion detection, no landmarks), each step on alone over it (`moving`:
  moving objects kept out of keyframes and the map; `gate`: the drift gate with the cells recalled on accepted
  closures; `landmarks`: objects as landmarks in iSAM2), and the three together (`all`, the defaults but for
  landmarks, which are off by default). Loop closures are judged within 5 m horizontally, 100 frames apart. The runs
  are one sweep, `benchmarks/specs/kitti_sim.yaml` (`neoslam sweep`; a drive's runs share its simulation): on a
  local pool (--workers), or on a Ray cluster (`--ray ADDRESS`); `--sweep-dir DIR` keeps the sweep folder, and
  running again resumes it. Beside ATE, the translation RPE over 100 m of route (the evaluation's `rpe_delta`) per
  step. Timing columns are per run.
- `moving`: the motion detector on streets with 0, 20 and 40 % of their objects moving, off, on and against an oracle
  that removes the moving objects' detections (benchmarks._moving).
- `gating`: the closure gates (the paper's grid-cell check, the drift gate, none) under `vo` and `heavy` odometry,
  and a repeated-layout trap only a gate can stop (benchmarks._gating).
- `landmarks`: objects as landmarks in the pose graph (iSAM2) against the pose graph without them
  (benchmarks._landmarks).

    python -m benchmarks.kitti_sim [--quick] [--parts steps moving gating landmarks] [--sequences 05 08]
                                   [--profiles vo] [--seeds 1 2 3] [--detectors real ideal] [--moving 0.2]
                                   [--config FILE.yaml] [--sweep-dir DIR] [--workers N] [--ray ADDRESS] [--out FILE]

`--sequences`, `--profiles`, `--seeds` and `--detectors` replace each part's own defaults (steps: 00 02 05 06 07 08,
vo and heavy, seed 1, real and ideal; moving: 05 00, vo, seed 1, real; gating: 00 02 05 06 08, vo and heavy, seed 1;
landmarks: 05 08 00 06, vo, seed 1, real and ideal; a part that takes one profile, seed or detector takes the first).
`--moving`: share of moving objects in `steps` (default 0.2: a fifth of the objects; 0 gives static streets).
`--config`: a config file under every run of `steps` and `moving` (the steps' overrides over it), e.g.
`benchmarks/specs/heavy_odometry.yaml`, the motion detector told how noisy `heavy` odometry is.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from benchmarks import _gating, _landmarks, _moving, harness
from benchmarks._sweep import SPECS, config_file, run_spec, sweep_options, with_changes
from benchmarks.harness import data_root
from neoslam.config.calibration import DETECTION_PROFILES
from neoslam.sweep import load_spec

SEQUENCES = ["00", "02", "05", "06", "07", "08"]  # of the part `steps`
PROFILES = ["vo", "heavy"]
DETECTORS = ["real", "ideal"]
SEEDS = [1]
MOVING = 0.2  # the benchmark's setting: a fifth of the street's objects move
SPEC = SPECS / "kitti_sim.yaml"  # overrides relaxation, baseline, moving, gate, landmarks, all
STEPS = ["baseline", "moving", "gate", "landmarks", "all"]


PARTS = {"moving": _moving, "gating": _gating, "landmarks": _landmarks}  # beside `steps`, which is here
QUICK = "steps on KITTI 05 (first seed); " + "; ".join(f"{name}: {part.QUICK}" for name, part in PARTS.items())


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--parts", nargs="+", choices=["steps", *PARTS], default=["steps", *PARTS], help="which parts to run"
    )
    parser.add_argument("--sequences", nargs="+", help="KITTI sequences (default: each part's own)")
    parser.add_argument("--profiles", nargs="+", help="odometry noise profiles (default: each part's own)")
    parser.add_argument("--seeds", nargs="+", type=int, help="simulation seeds (default: each part's own)")
    parser.add_argument(
        "--detectors", nargs="+", choices=sorted(DETECTION_PROFILES), help="detection profiles (default: each part's)"
    )
    parser.add_argument("--config", type=Path, help="a config file under every run of steps and moving (see above)")
    group = parser.add_argument_group("steps")
    group.add_argument("--moving", type=float, default=MOVING, help="steps: share of the street's objects that move")
    sweep_options(group)
    for name, part in PARTS.items():
        part.arguments(parser.add_argument_group(name))


def _on_street(overrides: dict, moving: float) -> dict:
    """Every override simulates the same street, with a share `moving` of its objects moving."""
    street = {"simulator": {"world": {"moving_fraction": moving}}}
    return {name: values | street for name, values in overrides.items()}


def _drives(records) -> tuple[list[dict], list[str]]:
    """The sweep's cells gathered per drive (sequence, detector, profile, seed): a row of its runs; a drive with a
    failed cell is left out and its errors returned."""
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
    """One drive's figures from the metrics of its runs."""
    baseline, every = metrics["baseline"], metrics["all"]
    figures = {
        "sequence": sequence,
        "detector": detector,
        "profile": profile,
        "seed": seed,
        "frames": baseline["frames"],
        "ate_odometry_m": baseline["ate_rmse_m"]["odometry"],
        "ate_relaxation_m": metrics["relaxation"]["ate_rmse_m"]["corrected"],
    }
    for step in STEPS:
        figures[f"ate_{step}_m"] = metrics[step]["ate_rmse_m"]["corrected"]
    figures["rpe_odometry_m"] = _rpe(baseline, "odometry")
    for step in ("relaxation", *STEPS):
        figures[f"rpe_{step}_m"] = _rpe(metrics[step], "corrected")
    for step in ("baseline", "moving", "all"):
        loops = metrics[step]["loops"]
        figures |= {
            f"loops_{step}": loops["accepted"],
            f"false_{step}": loops["false_positive"],
            f"precision_{step}": loops["precision"],
            f"recall_{step}": loops["recall"],
        }
    return figures | {
        "objects_baseline": baseline["objects"],
        "objects_all": every["objects"],
        "fps_baseline": baseline["timing"]["fps"],
        "fps_landmarks": metrics["landmarks"]["timing"]["fps"],
        "fps_all": every["timing"]["fps"],
        "wall_s_baseline": baseline["timing"]["wall_s"],
        "wall_s_all": every["timing"]["wall_s"],
        "ms_per_frame_p95_all": every["timing"]["ms_per_frame_p95"],
        "backend_s_baseline": baseline["timing"].get("backend_s"),
        "backend_s_landmarks": metrics["landmarks"]["timing"].get("backend_s"),
    }


def _rpe(metrics: dict, trajectory: str) -> float | None:
    """Translation RPE RMSE over the evaluation's spacing (100 m): how well a step keeps the map locally right,
    which ATE over a whole drive hides when one stretch is off."""
    return metrics["trajectory"][trajectory]["rpe_translation_rmse_m"]


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


def run_steps(bench: harness.Run, args: argparse.Namespace) -> dict:
    """Part `steps`: the sweep of the spec."""
    all_seeds = args.seeds or SEEDS
    sequences, seeds = (["05"], all_seeds[:1]) if args.quick else (args.sequences or SEQUENCES, all_seeds)
    profiles, detectors = args.profiles or PROFILES, args.detectors or DETECTORS
    spec = load_spec(SPEC)
    spec = with_changes(
        spec,
        sources=[{"kitti": sequences}],
        noise=profiles,
        detectors=detectors,
        seeds=seeds,
        overrides=_on_street(spec.overrides, args.moving),
        data_root=data_root(),
        **config_file(args),
    )
    with run_spec(spec, args) as sweep:
        rows, errors = _drives(sweep.records)
        summary = sweep.summary
    order = {"sequence": sequences, "detector": detectors, "profile": profiles}
    rows.sort(key=lambda r: (*(order[k].index(r[k]) for k in order), r["seed"]))
    if errors:
        print("Failed runs (left out):\n\n" + "\n".join(f"- {e}" for e in errors) + "\n")
    title = f"Streets with {args.moving:.0%} of their objects moving. Corrected ATE RMSE (m, SE(3)-aligned):"
    ate = ["ate_odometry_m", "ate_relaxation_m", *(f"ate_{step}_m" for step in STEPS)]
    bench.table("steps_ate", rows, ["sequence", "detector", "profile", "seed", "frames", *ate], title=title)
    rpe = ["rpe_odometry_m", "rpe_relaxation_m", *(f"rpe_{step}_m" for step in STEPS)]
    title = "Translation RPE RMSE over 100 m of route (m):"
    bench.table("steps_rpe", rows, ["sequence", "detector", "profile", "seed", *rpe], title=title)
    loops = [f"{kind}_{step}" for step in ("baseline", "moving", "all") for kind in ("loops", "false", "recall")]
    title = "Loop closures (accepted, false, recall), map objects and speed:"
    speed = ["objects_baseline", "objects_all", "fps_baseline", "fps_landmarks", "fps_all", "ms_per_frame_p95_all",
             "backend_s_baseline", "backend_s_landmarks"]  # fmt: skip
    bench.table("steps_loops", rows, ["sequence", "detector", "profile", "seed", *loops, *speed], title=title)
    if len(seeds) > 1:
        keys = [*ate, *rpe, *loops, *speed]
        columns = ["sequence", "detector", "profile", "seeds", *keys]
        bench.table("steps_medians", _medians(rows, keys), columns, title="Median over seeds:")
    print(summary.replace("# Sweep", "Sweep", 1))
    return {"moving_fraction": args.moving, "rows": rows, "medians": _medians(rows, [*ate, *rpe])}


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti", "poses"),))
    args = bench.args
    figures = {}
    for name in args.parts:
        print(f"# Part {name}\n", flush=True)
        figures[name] = run_steps(bench, args) if name == "steps" else PARTS[name].run_part(bench, args)
    bench.finish(figures)


if __name__ == "__main__":
    main()
