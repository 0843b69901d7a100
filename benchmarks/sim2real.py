"""The real front end against the simulator on the same stretch of street: the 51 real frames of KITTI 06.

Real: the front end (YOLOX-Nano, ORB stereo, stereo odometry) on kitti_06_51, then the NeoSLAM pipeline. Simulated:
`neoslam simulate` of the same ground-truth poses (KITTI 06 frames 0-50, same camera, odometry profile vo) with
each detection profile, several seeds, then the same pipeline. The simulated street is laid along the poses that
follow too, as far as the camera's range, so that the last frames look down a street as the real ones do; only
frames 0-50 are used. Rows: placed detections per frame and by distance band (depth of the placed centre), distinct
objects in the object map (objects.csv), keyframes and objects per keyframe. A row is flagged (!) when the `real`
profile's mean over the seeds is not within 30 % of the real front end.

    python -m benchmarks.sim2real [--quick] [--out FILE] [--seeds 1 2 ...]  (default seeds 1-10)
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._street import DISTANCE_BANDS, band_counts, band_name, run_real_front_end
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.io.trajectory_files import read_trajectory
from neoslam.pipeline import run
from neoslam.sim.simulator import simulate
from neoslam.types import Frame, Trajectory

SEEDS, QUICK_SEEDS = list(range(1, 11)), [1, 2]
PROFILES = ("real", "ideal")
ODOMETRY = "vo"
TOLERANCE = 0.3  # the calibrated profile should be within 30 % of the real front end


QUICK = f"seeds {QUICK_SEEDS}"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", nargs="+", type=int, default=None)


def _measure(frames: list[Frame], config: NeoSLAMConfig) -> dict[str, float]:
    """Per-frame detection counts of a run's frames, then the pipeline's object map and keyframes."""
    depths = [[float(o.center_camera[2]) for o in f.observations] for f in frames]
    figures = {"detections per frame": float(np.mean([len(d) for d in depths]))}
    per_band = np.array([band_counts(d) for d in depths], dtype=float).mean(axis=0)
    for band, value in zip(DISTANCE_BANDS, per_band, strict=True):
        figures[f"placed per frame, {band_name(band)}"] = float(value)
    result = run(iter(frames), config, total=len(frames), progress=False)
    figures["mapped objects"] = float(len(result.objects))
    figures["keyframes"] = float(len(result.keyframes))
    sizes = [len(k.labels) for k in result.keyframes]
    figures["objects per keyframe"] = float(np.mean(sizes)) if sizes else 0.0
    return figures


def _street_poses(frames: int, camera_range: float) -> Trajectory:
    """KITTI 06 ground truth from frame 0 on: the measured frames and those within the detection range beyond."""
    root = data_root()
    full = root / "kitti" / "poses" / "06.txt"
    times = root / "kitti" / "times" / "06.txt"
    if not full.is_file():  # only the 51 frames: the street ends with them
        short = root / "kitti_06_51"
        return read_trajectory(short / "poses" / "06.txt", "kitti", short / "sequences" / "06" / "times.txt")
    truth = read_trajectory(full, "kitti", times if times.is_file() else None)
    ahead = np.linalg.norm(truth.positions - truth.positions[frames - 1], axis=1)
    last = frames + int(np.argmax(ahead[frames:] > camera_range)) if (ahead[frames:] > camera_range).any() else None
    return truth.subset(np.arange(last if last else len(truth)))


def _simulated_frames(profile: str, seed: int, frames: int, folder: Path) -> list[Frame]:
    config = simulation_config(NeoSLAMConfig(), ODOMETRY, seed, profile)
    truth = _street_poses(frames, config.simulator.detection.max_range or config.simulator.camera.max_range)
    recording = simulate(truth, config.simulator, name="kitti06-51", source="kitti/poses/06.txt")
    first = np.arange(frames)
    recording = replace(
        recording,
        truth=truth.subset(first),
        linear_velocity=recording.linear_velocity[first],
        angular_velocity=recording.angular_velocity[first],
        detections=recording.detections[:frames],
    )
    write_dataset(folder, recording)
    return list(read_dataset(folder).frames())


def _ratio(simulated: float, real: float) -> float | None:
    return simulated / real if real > 0 else None


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    args = bench.args
    seeds = args.seeds or (QUICK_SEEDS if args.quick else SEEDS)
    config = NeoSLAMConfig()
    real_run = run_real_front_end(data_root() / "kitti_06_51", config)
    frames = len(real_run.frames)
    real = _measure(real_run.frames, config)
    simulated: dict[str, list[dict[str, float]]] = {profile: [] for profile in PROFILES}
    with tempfile.TemporaryDirectory() as tmp:
        for profile in PROFILES:
            for seed in seeds:
                folder = Path(tmp) / f"{profile}-{seed}"
                simulated[profile].append(_measure(_simulated_frames(profile, seed, frames, folder), config))
    rows = []
    for name, value in real.items():
        means = {p: float(np.mean([s[name] for s in simulated[p]])) for p in PROFILES}
        ratio = _ratio(means["real"], value)
        within = ratio is not None and abs(ratio - 1.0) <= TOLERANCE or (value == 0 and means["real"] == 0)
        rows.append(
            {
                "measure": name,
                "real": round(value, 2),
                "sim real": round(means["real"], 2),
                "ratio": ("-" if ratio is None else f"{ratio:.2f}") + ("" if within else " !"),
                "sim ideal": round(means["ideal"], 2),
                "within": within,
            }
        )
    boxes = float(np.mean(real_run.boxes_per_frame)) if real_run.boxes_per_frame else None
    print(f"KITTI 06 frames 0-{frames - 1}; simulated: seeds {seeds}, odometry {ODOMETRY}; ! = not within 30 %")
    bench.table("counts", rows, ["measure", "real", "sim real", "ratio", "sim ideal"])
    if boxes is not None:
        print(f"\nreal detector boxes per frame (before the stereo step places them): {boxes:.2f}")
    bench.finish(
        {
            "frames": frames,
            "seeds": seeds,
            "rows": rows,
            "real_detector_boxes_per_frame": boxes,
            "seed_runs": simulated,
        },
    )


if __name__ == "__main__":
    main()
