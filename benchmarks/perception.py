"""Speed of the perception front end on real KITTI frames (issue 6), and what it measures there.

Per frame at 1226x370 on this CPU: reading the stereo pair, YOLOX-Nano detection (onnxruntime), ORB stereo
triangulation of the objects and stereo visual odometry; median and 95th percentile of their sum, and frames per
second from the median. Run over the 12 real frames of kitti_mini (sequence 06), several passes (the odometry starts
again each pass; the first pass warms up and is not counted): detection on the whole frame only, with two tiles
over the central half of the width, and with tiles across the whole width. `fps_median` in the JSON is the
default configuration's. Alongside: objects
placed per frame, and the stereo odometry against the ground truth over the 12 frames (distance travelled and
heading change).

    python benchmarks/perception.py [--quick] [--json FILE]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import data_root, markdown_table, parse_args, write_json  # noqa: E402
from neoslam.config import NeoSLAMConfig  # noqa: E402
from neoslam.datasets.kitti import read_kitti_sequence  # noqa: E402
from neoslam.geometry import yaw_of  # noqa: E402
from neoslam.perception.frontend import STAGES, open_front_end  # noqa: E402
from neoslam.types import Trajectory  # noqa: E402

PASSES, QUICK_PASSES = 6, 2  # the first is a warm-up
SEQUENCE = "06"


def _odometry_errors(estimate: np.ndarray, truth: Trajectory) -> tuple[float, float]:
    """Distance travelled (relative error, %) and heading change (error, degrees) over the sequence."""
    travelled = np.linalg.norm(np.diff(estimate[:, :3, 3], axis=0), axis=1).sum()
    distance_error = 100.0 * (travelled / truth.path_length() - 1.0)
    turn = yaw_of(estimate[-1:])[0] - yaw_of(estimate[:1])[0]
    true_turn = yaw_of(truth.poses[-1:])[0] - yaw_of(truth.poses[:1])[0]
    return float(distance_error), float(np.degrees(abs(turn - true_turn)))


def _measure(name: str, config: NeoSLAMConfig, passes: int) -> dict:
    sequence = read_kitti_sequence(data_root() / "kitti_mini", SEQUENCE)
    stage_times: dict[str, list[float]] = {stage: [] for stage in STAGES}
    objects: list[int] = []
    for run in range(passes):
        dataset = open_front_end(sequence, config.perception)
        frames = list(dataset.frames())
        if run == 0:
            continue  # warm-up: model load, first inferences
        for stage in STAGES:
            stage_times[stage] += dataset.front_end.times.stages[stage]
        objects += [len(f.observations) for f in frames]
    poses = np.array([f.odometry_pose for f in frames])
    distance_error, heading_error = _odometry_errors(poses, sequence.ground_truth)
    total = np.sum([stage_times[s] for s in STAGES], axis=0)
    row = {"configuration": name, "frames": len(total)}
    row |= {f"{s}_ms": float(np.median(stage_times[s]) * 1e3) for s in STAGES}
    row |= {
        "total_ms_median": float(np.median(total) * 1e3),
        "total_ms_p95": float(np.percentile(total, 95) * 1e3),
        "fps_median": float(1.0 / np.median(total)),
        "objects_per_frame": float(np.mean(objects)),
        "odometry_distance_error_pct": distance_error,
        "odometry_heading_error_deg": heading_error,
    }
    return row


def main() -> None:
    args = parse_args(__doc__.splitlines()[0])
    passes = QUICK_PASSES if args.quick else PASSES
    base = NeoSLAMConfig()
    model = data_root() / "models" / "yolox_nano_coco" / "yolox_nano.onnx"
    configurations = {}
    for name, tiling, span in (
        ("whole frame", False, 1.0),
        ("+ central tiles", True, 0.5),
        ("+ tiles across", True, 1.0),
    ):
        detector = base.perception.detector.model_copy(update={"model": model, "tiling": tiling, "tile_span": span})
        perception = base.perception.model_copy(update={"detector": detector})
        configurations[name] = base.model_copy(update={"perception": perception})
    rows = [_measure(name, config, passes) for name, config in configurations.items()]
    columns = ["configuration", "frames", *(f"{s}_ms" for s in STAGES), "total_ms_median", "total_ms_p95"]
    columns += ["fps_median", "objects_per_frame", "odometry_distance_error_pct", "odometry_heading_error_deg"]
    print(markdown_table(rows, columns))
    default = base.perception.detector
    headline = next(r for r, c in zip(rows, configurations.values(), strict=True) if _same_detector(c, default))
    write_json(args.json, {"fps_median": headline["fps_median"], "rows": rows})


def _same_detector(config: NeoSLAMConfig, default) -> bool:
    """Whether a measured configuration is the default one (the headline figure)."""
    detector = config.perception.detector
    return detector.tiling == default.tiling and (not default.tiling or detector.tile_span == default.tile_span)


if __name__ == "__main__":
    main()
