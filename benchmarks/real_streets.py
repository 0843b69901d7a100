"""The whole system on real KITTI images: keyframes along a real street, a revisit that closes loops, and the
detector against hand labels.

(a) `kitti_06_51`, the 51 real stereo frames of KITTI 06 (60 m of a residential street) through the real front end
    (default detector, ORB stereo, stereo odometry) and the pipeline: detections and placed objects a frame,
    distinct mapped objects, keyframes and objects per keyframe, front-end frames a second, ATE.
(b) A revisit of the same street's images: the frames forward, back to the start, and forward again through a
    photometric change (gain 0.8, offset +15, noise sigma 3, blur sigma 0.7 px, shift (1.3, -0.8) px). Closures
    from the third pass to the first, closures judged against the ground truth (true within 5 m), and the error of
    each closure's relative pose; the keyframes each pass made (stored, or recognised as stored ones) and how many
    of the third pass's have a first-pass keyframe within 5 m to close to. This is the same street's images played
    again, not an independent second drive.

(a) and (b) with the default detector and, with --yolo11 (its weights are AGPL-3.0, read from the shared data, never
part of NeoSLAM), with YOLO11n.

(c) Detection recall against hand labels on real frames: benchmarks._perception. The front end's speed is
`benchmarks.frontend_speed`'s.
(d) What each part of the third pass's photometric change costs the default front end on the 51 frames: detections
    and placed objects, with the contrast equalisation and without (benchmarks._photometric).

    python -m benchmarks.real_streets [--quick] [--parts street revisit detection photometric] [--yolo11]
                                      [--out FILE]

`--quick`: the same run (it is as small as it is).
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks import _perception, _photometric, harness
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.replay import PhotometricChange, forward_back_forward
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error
from neoslam.geometry import invert_pose
from neoslam.perception.frontend import open_front_end
from neoslam.pipeline import run

THIRD_PASS = PhotometricChange(gain=0.8, offset=15.0, noise_sigma=3.0, blur_sigma=0.7, shift_x=1.3, shift_y=-0.8)
TRUE_CLOSURE_M = 5.0


def _street_row(name: str, config: NeoSLAMConfig) -> dict:
    sequence = read_kitti_sequence(data_root() / "kitti_06_51", "06")
    dataset = open_front_end(sequence, config.perception)
    frames = list(dataset.frames())
    result = run(iter(frames), config, total=len(frames), progress=False)
    perception = dataset.front_end.times.summary()
    keyframes = result.keyframes
    return {
        "detector": name,
        "frames": len(frames),
        "placed / frame": float(np.mean([len(f.observations) for f in frames])),
        "mapped objects": len(result.objects),
        "keyframes": len(keyframes),
        "objects / keyframe": float(np.mean([len(k.labels) for k in keyframes])) if keyframes else 0.0,
        "front end fps": perception["wall_fps"],
        "ATE corrected m": float(absolute_trajectory_error(result.estimate, sequence.ground_truth).rmse),
    }


def _revisit_row(name: str, config: NeoSLAMConfig) -> dict:
    sequence = read_kitti_sequence(data_root() / "kitti_06_51", "06")
    replay = forward_back_forward(sequence, THIRD_PASS)
    frames = list(open_front_end(replay, config.perception).frames())
    result = run(iter(frames), config, total=len(frames), progress=False)
    truth = replay.ground_truth.poses
    first_end, third_start = len(sequence), 2 * len(sequence) - 1
    gaps = [np.linalg.norm(truth[c.query_frame, :3, 3] - truth[c.match_frame, :3, 3]) for c in result.loop_closures]
    third_to_first = [c for c in result.loop_closures if c.query_frame >= third_start and c.match_frame < first_end]
    pose_errors = [
        np.linalg.norm(c.relative_pose[:2, 3] - (invert_pose(truth[c.match_frame]) @ truth[c.query_frame])[:2, 3])
        for c in third_to_first
    ]
    made = np.asarray(result.keyframe_frames, dtype=int)  # stored, or recognised as stored ones
    first, third = made[made < first_end], made[made >= third_start]
    # a third-pass keyframe can close to the first pass only where the first pass made a keyframe near it
    reach = [min(np.linalg.norm(truth[f, :3, 3] - truth[g, :3, 3]) for g in first) for f in third] if len(first) else []
    closable = int(sum(r <= TRUE_CLOSURE_M for r in reach))
    return {
        "detector": name,
        "frames": len(frames),
        "keyframes made (pass 1 / 3)": f"{len(first)} / {len(third)}",
        "pass-3 keyframes with a pass-1 keyframe within 5 m": closable,
        "closures": len(result.loop_closures),
        "false closures": int(sum(g > TRUE_CLOSURE_M for g in gaps)),
        "pass 3 -> pass 1": len(third_to_first),
        "pass-3 keyframes closed": f"{len({c.query_frame for c in third_to_first})}/{len(third)}",
        "relative pose error m (max)": float(max(pose_errors)) if pose_errors else float("nan"),
    }


QUICK = "the same run as the default (it is as small as it is)"
PARTS = ["street", "revisit", "detection", "photometric"]


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=PARTS, help="which parts to run (default all)")
    parser.add_argument("--yolo11", action="store_true", help="(a) and (b) also with YOLO11n (AGPL-3.0 weights)")


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    args = bench.args
    base = NeoSLAMConfig()
    configs = {"YOLOX-Nano (default)": base}
    if args.yolo11:
        detector = base.perception.detector.model_copy(update={"source": "yolo11"})
        perception = base.perception.model_copy(update={"detector": detector})
        configs["YOLO11n"] = base.model_copy(update={"perception": perception})
    figures = {}
    if "street" in args.parts:
        street = [_street_row(name, config) for name, config in configs.items()]
        bench.table(
            "street", street, list(street[0]), title="## (a) kitti_06_51 through the front end and the pipeline"
        )
        figures["street"] = street
    if "revisit" in args.parts:
        revisit = [_revisit_row(name, config) for name, config in configs.items()]
        bench.table("revisit", revisit, list(revisit[0]), title="## (b) The revisit: forward, back, forward again")
        figures["revisit"] = revisit
    if "detection" in args.parts:
        print("## (c) Detection against hand labels\n")
        figures |= _perception.run_detection(bench, args)
    if "photometric" in args.parts:
        rows = _photometric.photometric_rows(base, THIRD_PASS)
        title = "## (d) The 51 frames through each part of the third pass's change: detections and placed objects"
        bench.table("photometric", rows, list(rows[0]), title=title)
    bench.finish(figures)


if __name__ == "__main__":
    main()
