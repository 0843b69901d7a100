"""Moving objects kept out of keyframes and the map: simulated KITTI drives with a share of moving objects, NeoSLAM
with the motion detector off and on.

Each drive (KITTI ground truth, `vo` odometry, the `real` detection profile, one seed) is simulated with
`world.moving_fraction` 0, 0.2 and 0.4 (the simulator's own traffic model), then run with `moving_objects.enabled`
false and true. Per run: loop precision and recall (true within 5 m horizontally and 100 frames apart, recall over
the keyframes' frames), ATE of the corrected trajectory (SE(3)-aligned), objects in the map and moving objects
reported, and from the simulator's truth (truth/detections.csv: row -> object; truth/objects.csv: its velocity,
moving when its speed is > 0):
- `moving_kept_out`: among the detections of moving objects in frames that made a keyframe, the share not in that
  keyframe (flagged moving, or fused into a window object the keyframe does not hold);
- `moving_not_known`: the share not in that keyframe as an object known to be static (out of it, or in it as a
  provisional object, which is no contradiction to a match when missing: `moving_objects.unjudged: wait`);
- `static_flagged`: the share of all detections of static objects that the detector kept out as moving;
- `heading_noise`, `distance_noise`: the odometry noise its tracks allowed for at the end of the drive (rad and m
  per square root of a second: the stated floor, or the online estimate where larger).
Ground truth is read here for judging only; NeoSLAM sees the frames.

The `oracle` rows are the reference a detector aims at: the same drive with the moving objects' detections removed
by the simulator's truth before NeoSLAM sees them (the detector off), i.e. the street's parked objects only (a
drive with moving_fraction 0.2 has a fifth fewer parked objects than the static street).

    python benchmarks/moving.py [--quick] [--json FILE] [--sequences 05 00] [--fractions 0 0.2 0.4] [--seeds 1]
                                [--config FILE.yaml] [--modes off on oracle]

`--quick`: KITTI 05's first 1200 frames, fractions 0 and 0.2.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from benchmarks.harness import data_root, markdown_table
from neoslam.config import NeoSLAMConfig, load_config
from neoslam.datasets.simulated import SimulatedDataset, read_dataset, write_dataset
from neoslam.evaluation.report import loop_metrics
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.io.tables import numeric_column, read_table
from neoslam.io.trajectory_files import read_trajectory
from neoslam.jobs import simulation_config
from neoslam.pipeline import NeoSLAM
from neoslam.sim.simulator import simulate

SEQUENCES = ["05", "00"]
FRACTIONS = [0.0, 0.2, 0.4]
QUICK_FRAMES = 1200
MODES = ("off", "on", "oracle")
OBJECT_COLUMNS = ("id", "label", "x", "y", "z", "length", "width", "height", "yaw", "vx", "vy", "vz")


def _arguments(parser) -> None:
    parser.add_argument("--sequences", nargs="+", default=None, help="KITTI sequences (default 05 00)")
    parser.add_argument("--fractions", nargs="+", type=float, default=None, help="moving fractions (0 0.2 0.4)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--profile", default="vo", help="odometry noise profile (default vo)")
    parser.add_argument("--detector", default="real", help="detection profile (default real)")
    parser.add_argument("--config", type=Path, help="a config file under both runs (the detector's settings)")
    parser.add_argument(
        "--modes", nargs="+", choices=MODES, default=list(MODES), help="detector off, on, and the oracle (see above)"
    )


def _config(job: dict) -> NeoSLAMConfig:
    base = load_config(Path(job["config"]) if job["config"] else None, environ={})
    config = simulation_config(base, job["profile"], job["seed"], job["detector"])
    world = config.simulator.world.model_copy(update={"moving_fraction": job["fraction"]})
    return config.model_copy(update={"simulator": config.simulator.model_copy(update={"world": world})})


def simulate_drive(job: dict) -> dict:
    """Simulate the drive into job["folder"]."""
    config = _config(job)
    poses = data_root() / "kitti" / "poses" / f"{job['sequence']}.txt"
    truth = read_trajectory(poses, "kitti", None, frame_period=config.simulator.frame_period)
    if job["frames"]:
        truth = truth.subset(np.arange(min(job["frames"], len(truth))))
    recording = simulate(truth, config.simulator, job["sequence"], job["sequence"])
    write_dataset(Path(job["folder"]), recording)
    return job


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


def run_drive(job: dict) -> dict:
    """NeoSLAM over the drive with the detector on or off; each observation followed to the keyframe window
    object it joined (if any), and each keyframe checked for the moving objects' detections of its frame."""
    dataset = read_dataset(Path(job["folder"]))
    config = _config(job)
    moving_objects = config.moving_objects.model_copy(update={"enabled": job["mode"] == "on"})
    config = config.model_copy(update={"moving_objects": moving_objects})
    moving, real = _moving_rows(dataset)
    slam = NeoSLAM(config)
    joined: dict[int, object] = {}  # id(observation) -> window object, this frame
    made: list = []
    window_add, keyframes_add = slam.keyframes.window.add, slam.keyframes.add

    def record_window(pose, observations, odometer_m):
        objects = window_add(pose, observations, odometer_m)
        joined.update({id(o): w for o, w in zip(observations, objects, strict=True)})
        return objects

    def record_keyframe(*args, **kwargs):
        keyframe = keyframes_add(*args, **kwargs)
        made.append(keyframe)
        return keyframe

    slam.keyframes.window.add, slam.keyframes.add = record_window, record_keyframe
    passed = np.zeros(len(moving), dtype=bool)
    moving_at_keyframes = kept_out = kept_provisional = 0
    for frame, rows in zip(dataset.frames(), dataset.detection_rows(), strict=True):
        if job["mode"] == "oracle":  # truth removes the moving objects' detections: the same street, parked only
            frame = replace(frame, observations=tuple(o for o, r in zip(frame.observations, rows, strict=True)
                                                      if not moving[r]))  # fmt: skip
            rows = rows[~moving[rows]]
        joined.clear()
        made.clear()
        slam.step(frame)
        passed[rows] = [id(o) in joined for o in frame.observations]
        keyframe = made[-1] if made else None
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
        "sequence": job["sequence"],
        "seed": job["seed"],
        "moving_fraction": job["fraction"],
        "detector": job["mode"],
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


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], _arguments)
    sequences = args.sequences or (["05"] if args.quick else SEQUENCES)
    fractions = args.fractions or ([0.0, 0.2] if args.quick else FRACTIONS)
    frames = QUICK_FRAMES if args.quick else None
    context = get_context("spawn")
    with tempfile.TemporaryDirectory() as tmp:
        drives = [
            {"sequence": s, "seed": seed, "fraction": f, "profile": args.profile, "detector": args.detector,
             "config": str(args.config) if args.config else None, "frames": frames,
             "folder": str(Path(tmp) / f"{s}_{seed}_{f}")}
            for s in sequences for seed in args.seeds for f in fractions
        ]  # fmt: skip
        with context.Pool(2, maxtasksperchild=1) as pool:
            drives = pool.map(simulate_drive, drives, chunksize=1)
        runs = [d | {"mode": mode} for d in drives for mode in args.modes]
        with context.Pool(2, maxtasksperchild=1) as pool:
            rows = pool.map(run_drive, runs, chunksize=1)
    cut = f", first {frames} frames" if frames else ""
    print(
        f"## Moving objects: simulated KITTI {', '.join(sequences)} ({args.profile} odometry, {args.detector} "
        f"detection profile, seeds {', '.join(map(str, args.seeds))}{cut})\n"
    )
    columns = ["sequence", "seed", "moving_fraction", "detector", "loop_precision", "loop_recall", "closures",
               "ate_corrected_m", "objects", "moving_reported", "moving_at_keyframes", "moving_kept_out",
               "moving_not_known", "static_flagged", "heading_noise", "distance_noise"]  # fmt: skip
    print(markdown_table(rows, columns))
    write_json(args.json, {"profile": args.profile, "detector": args.detector, "frames": frames, "rows": rows})


if __name__ == "__main__":
    main()
