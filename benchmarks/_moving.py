"""Part `moving` of the kitti_sim study: moving objects kept out of keyframes and the map; simulated KITTI drives
with a share of moving objects, NeoSLAM with the motion detector off and on.

Each drive (KITTI ground truth, `vo` odometry, the `real` detection profile, one seed) is simulated with
`world.moving_fraction` 0, 0.2 and 0.4 (the simulator's own traffic model), then run with `moving_objects.enabled`
false and true: a sweep, `benchmarks/specs/moving.yaml`, with `measure` below as each cell's measurement. Per run:
loop precision and recall (true within 5 m horizontally and 100 frames apart, recall over the keyframes' frames), ATE
of the corrected trajectory (SE(3)-aligned), objects in the map and moving objects reported, and from the simulator's
truth (truth/detections.csv: row -> object; truth/objects.csv: its velocity, moving when its speed is > 0):
- `moving_kept_out`: among the detections of moving objects in frames that made a keyframe, the share not in that
  keyframe (flagged moving, or fused into a window object the keyframe does not hold);
- `moving_not_known`: the share not in that keyframe as an object known to be static (out of it, or in it as a
  provisional object, which is no contradiction to a match when missing: `moving_objects.unjudged: wait`);
- `static_flagged`: the share of all detections of static objects that the detector kept out as moving;
- `heading_noise`, `distance_noise`: the odometry noise its tracks allowed for at the end of the drive (rad and m
  per square root of a second: the stated floor, or the online estimate where larger).
Ground truth is read here for judging only; NeoSLAM sees the frames.

The `oracle` rows are the reference a detector aims at: the same drive with the moving objects' detections removed
by the simulator's truth before NeoSLAM sees them, the detector on (its provisional objects help a static street
too), i.e. the street's parked objects only (a drive with moving_fraction 0.2 has a fifth fewer parked objects than
the static street). The gap between `on` and `oracle` is what judging moving objects better can gain.

    python -m benchmarks.kitti_sim --parts moving [--sequences 05 00] [--fractions 0 0.2 0.4] [--seeds 1]
                                   [--profiles vo] [--detectors real] [--config FILE.yaml] [--modes off on oracle]

`--quick`: KITTI 05's first 1200 frames, fractions 0 and 0.2.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._sweep import SPECS, config_file, run_spec, with_changes
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import SimulatedDataset, read_dataset
from neoslam.evaluation.report import loop_metrics
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.io.tables import numeric_column, read_table
from neoslam.loop.keyframes import KeyframeStep
from neoslam.pipeline import NeoSLAM
from neoslam.sweep import load_spec

SPEC = SPECS / "moving.yaml"  # its overrides are replaced by the options' fractions and modes
SEQUENCES = ["05", "00"]
FRACTIONS = [0.0, 0.2, 0.4]
QUICK_FRAMES = 1200
MODES = ("off", "on", "oracle")
OBJECT_COLUMNS = ("id", "label", "x", "y", "z", "length", "width", "height", "yaw", "vx", "vy", "vz")


QUICK = f"KITTI 05's first {QUICK_FRAMES} frames, fractions 0 and 0.2"


def arguments(group: argparse._ArgumentGroup) -> None:
    group.add_argument("--fractions", nargs="+", type=float, default=None, help="moving: moving fractions (0 0.2 0.4)")
    group.add_argument(
        "--modes", nargs="+", choices=MODES, default=list(MODES), help="moving: detector off, on, and the oracle"
    )


def _moving_rows(dataset: SimulatedDataset) -> np.ndarray:
    """Per detections.csv row, whether it is a detection of a moving object (truth, for judging only)."""
    truth = dataset.folder / "truth"
    rows = read_table(truth / "objects.csv", OBJECT_COLUMNS)
    speed = np.linalg.norm(
        np.column_stack([numeric_column(truth / "objects.csv", rows, OBJECT_COLUMNS, c) for c in ("vx", "vy")]), axis=1
    )
    detections = read_table(truth / "detections.csv", ("detection", "object_id"))
    objects = numeric_column(truth / "detections.csv", detections, ("detection", "object_id"), "object_id").astype(int)
    moving = np.zeros(len(objects), dtype=bool)
    real = objects >= 0
    moving[real] = speed[objects[real]] > 0
    return moving, real


def _share(part: int, whole: int) -> float:
    return part / whole if whole else float("nan")


def measure(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: the drive with the motion detector as the config has it (`moving_objects.enabled`)."""
    return _measure(data, config, oracle=False)


def measure_oracle(data: Path, config: NeoSLAMConfig, out: Path, inputs=None) -> dict:
    """A sweep cell: the drive without the moving objects' detections (the detector as the config has it)."""
    return _measure(data, config, oracle=True)


def _measure(data: Path, config: NeoSLAMConfig, oracle: bool) -> dict:
    """NeoSLAM over the drive; each observation followed to the keyframe window object it joined (if any), and
    each keyframe checked for the moving objects' detections of its frame."""
    dataset = read_dataset(data)
    moving, real = _moving_rows(dataset)
    slam = NeoSLAM(config)
    steps: list[KeyframeStep] = []  # what the keyframe builder did with this frame
    slam.keyframes.observers.append(steps.append)
    passed = np.zeros(len(moving), dtype=bool)
    moving_at_keyframes = kept_out = kept_provisional = 0
    for frame, rows in zip(dataset.frames(), dataset.detection_rows(), strict=True):
        if oracle:  # truth removes the moving objects' detections: the same street, parked only
            frame = replace(frame, observations=tuple(o for o, r in zip(frame.observations, rows, strict=True)
                                                      if not moving[r]))  # fmt: skip
            rows = rows[~moving[rows]]
        steps.clear()
        slam.step(frame)
        joined = {id(o): w for step in steps for o, w in zip(step.observations, step.joined, strict=True)}
        passed[rows] = [id(o) in joined for o in frame.observations]
        keyframe = steps[-1].keyframe if steps else None
        if keyframe is None:
            continue
        for observation, row in zip(frame.observations, rows, strict=True):
            if not moving[row]:
                continue
            window_object = joined.get(id(observation))
            position = np.full(3, np.nan) if window_object is None else window_object.position
            held = np.flatnonzero(np.all(keyframe.centers == position, axis=1))
            moving_at_keyframes += 1
            kept_out += len(held) == 0
            kept_provisional += len(held) > 0 and bool(keyframe.provisional[held[0]])
    result = slam.result(np.zeros(len(dataset)))
    heading_noise, distance_noise = result.odometry_noise
    truth = dataset.ground_truth
    loops = loop_metrics(result.session_closures(), truth, config.evaluation, result.keyframe_frames)
    static = real & ~moving
    return {
        "loop_precision": loops["precision"],
        "loop_recall": loops["recall"],
        "closures": loops["accepted"],
        "ate_corrected_m": absolute_trajectory_error(result.estimate, truth, "se3").rmse,
        "objects": len(result.objects),
        "moving_reported": len(result.moving_objects),
        "keyframes": len(result.keyframe_frames),
        "moving_detections": int(moving.sum()),
        "moving_at_keyframes": moving_at_keyframes,
        "moving_kept_out": _share(kept_out, moving_at_keyframes),
        "moving_not_known": _share(kept_out + kept_provisional, moving_at_keyframes),
        "static_flagged": float(np.mean(~passed[static])) if static.any() else float("nan"),
        "heading_noise": heading_noise,
        "distance_noise": distance_noise,
    }


def _overrides(fractions: list[float], modes: list[str]) -> dict[str, tuple[float, str, dict]]:
    """Override name -> (moving fraction, mode, config sections), in the order of the rows."""
    overrides = {}
    for fraction in fractions:
        for mode in modes:
            sections = {"simulator": {"world": {"moving_fraction": fraction}}}
            overrides[f"{fraction:g} {mode}"] = (
                fraction,
                mode,
                sections | {"moving_objects": {"enabled": mode != "off"}},
            )
    return overrides


def run_part(bench: harness.Run, args: argparse.Namespace) -> dict:
    sequences = args.sequences or (["05"] if args.quick else SEQUENCES)
    fractions = args.fractions or ([0.0, 0.2] if args.quick else FRACTIONS)
    seeds = args.seeds or [1]
    profile = args.profiles[0] if args.profiles else "vo"
    detector = args.detectors[0] if args.detectors else "real"
    frames = QUICK_FRAMES if args.quick else None
    overrides = _overrides(fractions, args.modes)
    spec = with_changes(
        load_spec(SPEC),
        sources=[{"kitti": s, **({"frames": frames} if frames else {})} for s in sequences],
        noise=[profile],
        detectors=[detector],
        seeds=seeds,
        data_root=data_root(),
        metrics=["loop_recall", "ate_corrected_m", "moving_kept_out"],
        **config_file(args),
    )
    figures: dict[tuple, dict] = {}
    for oracle in (False, True):  # the oracle is a measurement of its own: a sweep of its own
        chosen = {name: o[2] for name, o in overrides.items() if (o[1] == "oracle") == oracle}
        if not chosen:
            continue
        with run_spec(with_changes(spec, overrides=chosen), args, measure_oracle if oracle else measure) as sweep:
            for record in sweep.records:
                cell = record.cell
                if record.status != "ok":
                    print(f"- failed: {cell.source} seed {cell.seed} {cell.override}: {record.error}")
                    continue
                figures[(cell.source, cell.seed, cell.override)] = record.metrics
    rows = [
        {"sequence": s, "seed": seed, "moving_fraction": fraction, "detector": mode} | figures[(s, seed, name)]
        for s in sequences
        for seed in seeds
        for name, (fraction, mode, _) in overrides.items()
        if (s, seed, name) in figures
    ]
    cut = f", first {frames} frames" if frames else ""
    print(
        f"## Moving objects: simulated KITTI {', '.join(sequences)} ({profile} odometry, {detector} "
        f"detection profile, seeds {', '.join(map(str, seeds))}{cut})\n"
    )
    columns = ["sequence", "seed", "moving_fraction", "detector", "loop_precision", "loop_recall", "closures",
               "ate_corrected_m", "objects", "moving_reported", "moving_at_keyframes", "moving_kept_out",
               "moving_not_known", "static_flagged", "heading_noise", "distance_noise"]  # fmt: skip
    bench.table("moving", rows, columns)
    return {"profile": profile, "detector": detector, "frames": frames, "rows": rows}
