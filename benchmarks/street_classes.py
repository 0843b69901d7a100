"""More kinds of object: the COCO street classes the detector finds on kitti_06_51, how many of them the ORB stereo
step places in 3-D, how far away, and how many are stable objects.

The detector (YOLOX-Nano, the default; with --yolo11 also YOLO11n, whose weights are AGPL-3.0, read from the shared
data and never part of NeoSLAM) runs over the 51 left images with its default windows, contrast equalisation and
NMS, but with every COCO class kept and boxes down to score 0.25, so that the score distribution of each class shows
below the default threshold too. The boxes of the street classes (car, truck, bus, bicycle, motorcycle, person,
traffic light, stop sign, fire hydrant, parking meter, bench, potted plant) at a score threshold (the default 0.45,
and 0.3) then go through the front end's ORB stereo step together, as a front end configured with those classes
would place them (a box hidden by a nearer one, cut by the image border, with too few agreeing keypoints or beyond
60 m is not placed). Placed observations go to the world with the ground-truth poses (a benchmark may use them; the
SLAM path never does) and are grouped as benchmarks._street groups them: one label, within 2.5 m (or 3 depth
std) across frames. A stable object is one placed in at least 3 frames within 2.5 m of its fused position.

Per class: boxes (at 0.25, 0.3 and the threshold) and their score percentiles; placed observations, their share of
the boxes and their depth percentiles; objects and stable objects. Then the stable objects of the classes other
than car, where they stand (along the driven path and to its side; the labels are the detector's, so a look at the
frames tells whether the class is right), and a recommended class list (classes with a stable object) and class mix
(each class's share of the stable objects) for the simulator's WorldConfig.class_mix, beside the `real` profile's.

    python -m benchmarks.street_classes [--quick] [--out FILE] [--yolo11] [--scores 0.45 0.3]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from benchmarks import harness
from benchmarks._street import ASSOCIATION_RADIUS, SEQUENCE, Cluster, RealRun, along_and_lateral, cluster_observations
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.config.calibration import DETECTION_PROFILES
from neoslam.config.perception import DetectorConfig
from neoslam.datasets.kitti import KittiSequence, read_kitti_sequence
from neoslam.perception.detection import Detection
from neoslam.perception.detector import WindowedDetector, make_detector
from neoslam.perception.stereo import ObjectTriangulator
from neoslam.types import Frame

# COCO street classes and the spellings the models' names files use for them.
STREET_CLASSES: dict[str, tuple[str, ...]] = {
    "car": ("car",),
    "truck": ("truck",),
    "bus": ("bus",),
    "bicycle": ("bicycle",),
    "motorcycle": ("motorcycle", "motorbike"),
    "person": ("person",),
    "traffic light": ("traffic light",),
    "stop sign": ("stop sign",),
    "fire hydrant": ("fire hydrant",),
    "parking meter": ("parking meter",),
    "bench": ("bench",),
    "potted plant": ("potted plant", "pottedplant"),
}
LOW_SCORE = 0.25  # boxes down to this score are kept for the score distribution
COUNTED_SCORES = (0.25, 0.3)  # box counts at these scores, beside the placement threshold
STABLE_FRAMES = 3  # a stable object is placed in at least this many frames
DETECTORS = {"YOLOX-Nano": "yolox", "YOLO11n": "yolo11"}


@dataclass
class Detections:
    """One detector's boxes of every frame (street classes under their street name, the others as the model names
    them), with every COCO class kept down to LOW_SCORE."""

    name: str
    frames: list[list[Detection]]


def _street_name(model_name: str) -> str | None:
    for name, spellings in STREET_CLASSES.items():
        if model_name in spellings:
            return name
    return None


def detect_all(sequence: KittiSequence, config: DetectorConfig, name: str) -> Detections:
    """Every frame's boxes of every COCO class down to LOW_SCORE (default windows, contrast, NMS)."""
    model = make_detector(config).model
    everything = config.model_copy(update={"classes": list(model.class_names), "score_threshold": LOW_SCORE})
    detector = WindowedDetector(model, everything)
    frames = []
    for index in range(len(sequence)):
        boxes = detector.detect(index, sequence.left_image(index))
        frames.append([Detection(_street_name(d.label) or d.label, d.score, d.box) for d in boxes])
    return Detections(name, frames)


def place(sequence: KittiSequence, detections: Detections, score: float, config: NeoSLAMConfig) -> list[Frame]:
    """The front end's ORB stereo step on the street-class boxes of each frame at or above `score`."""
    triangulator = ObjectTriangulator(sequence.camera, config.perception.stereo)
    frames = []
    for index, boxes in enumerate(detections.frames):
        kept = [d for d in boxes if d.label in STREET_CLASSES and d.score >= score]
        left, right = sequence.stereo_pair(index)
        observations = tuple(triangulator.observe(left, right, kept))
        frames.append(
            Frame(index, float(sequence.timestamps[index]), np.eye(4), np.zeros(3), np.zeros(3), observations)
        )
    return frames


def _percentiles(values: list[float], digits: int) -> str:
    if not values:
        return "-"
    p10, p50, p90 = np.percentile(values, [10, 50, 90])
    return f"{p50:.{digits}f} ({p10:.{digits}f} to {p90:.{digits}f})"


def is_stable(cluster: Cluster) -> bool:
    """Placed in at least STABLE_FRAMES frames within ASSOCIATION_RADIUS of the object's fused position."""
    spread = np.linalg.norm(np.array(cluster.points) - cluster.position, axis=1)
    return int(np.sum(spread <= ASSOCIATION_RADIUS)) >= STABLE_FRAMES


def _groups(detections: Detections) -> dict[str, tuple[str, ...]]:
    """Each street class, all of them together, and the other COCO classes the detector reported."""
    groups = {name: (name,) for name in STREET_CLASSES}
    groups["all street classes"] = tuple(STREET_CLASSES)
    others = sorted({d.label for frame in detections.frames for d in frame} - set(STREET_CLASSES))
    groups[f"other COCO classes ({', '.join(others) or 'none'})"] = tuple(others)
    return groups


def score_rows(detections: Detections, score: float) -> list[dict]:
    """Per class: boxes at each counted score and at the threshold, per frame, and the score percentiles."""
    count = len(detections.frames)
    rows = []
    for group, labels in _groups(detections).items():
        scores = [d.score for frame in detections.frames for d in frame if d.label in labels]
        row: dict = {"class": group}
        row |= {f"boxes >= {s:g}": sum(v >= s for v in scores) for s in sorted({*COUNTED_SCORES, score})}
        row |= {
            f"per frame >= {score:g}": f"{sum(v >= score for v in scores) / count:.2f}",
            f"frames with one >= {score:g}": sum(
                any(d.label in labels and d.score >= score for d in frame) for frame in detections.frames
            ),
            f"score median (p10 to p90), >= {LOW_SCORE:g}": _percentiles(scores, 2),
        }
        rows.append(row)
    return rows


def placement_rows(detections: Detections, frames: list[Frame], clusters: list[Cluster], score: float) -> list[dict]:
    """Per class with a box at the threshold: boxes, placed observations, their depths, objects, stable objects."""
    placed = [o for frame in frames for o in frame.observations]
    rows = []
    for group, labels in _groups(detections).items():
        boxes = sum(d.label in labels and d.score >= score for frame in detections.frames for d in frame)
        if (not boxes and group in STREET_CLASSES) or not labels or not set(labels) <= set(STREET_CLASSES):
            continue  # only street-class boxes go through the stereo step
        observations = [o for o in placed if o.label in labels]
        objects = [c for c in clusters if c.label in labels]
        stable = [c for c in objects if is_stable(c)]
        rows.append(
            {
                "class": group,
                f"boxes >= {score:g}": boxes,
                "placed": len(observations),
                "placed share": f"{len(observations) / boxes:.2f}" if boxes else "-",
                "depth m median (p10 to p90)": _percentiles([float(o.center_camera[2]) for o in observations], 1),
                "objects": len(objects),
                f"stable (>= {STABLE_FRAMES} views within {ASSOCIATION_RADIUS:g} m)": len(stable),
                "views of stable": sum(len(c.frames) for c in stable),
            }
        )
    return rows


def stable_objects(clusters: list[Cluster], run: RealRun) -> list[dict]:
    """The stable objects of the classes other than car: where they stand and from how far they were placed."""
    stable = [c for c in clusters if is_stable(c) and c.label != "car"]
    if not stable:
        return []
    along, lateral = along_and_lateral(run.truth, np.array([c.position for c in stable]))
    return [
        {
            "class": c.label,
            "frames": f"{len(c.frames)} ({min(c.frames)}-{max(c.frames)})",
            "along the path m": f"{a:.1f}",
            "to the side m (left +)": f"{s:+.1f}",
            "depth m": f"{min(c.depths):.1f}-{max(c.depths):.1f}",
            "spread m": f"{np.max(np.linalg.norm(np.array(c.points) - c.position, axis=1)):.2f}",
        }
        for c, a, s in zip(stable, along, lateral, strict=True)
    ]


def class_mix(clusters: list[Cluster]) -> dict[str, float]:
    """Each class's share of the stable objects."""
    stable = [c.label for c in clusters if is_stable(c)]
    return {label: round(stable.count(label) / len(stable), 3) for label in STREET_CLASSES if label in stable}


QUICK = "the default score threshold only"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--yolo11", action="store_true", help="also YOLO11n (AGPL-3.0 weights from the shared data)")
    parser.add_argument(
        "--scores", nargs="+", type=float, default=None, help="placement score thresholds (default: 0.45 and 0.3)"
    )


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    args = bench.args
    config = NeoSLAMConfig()
    default_score = config.perception.detector.score_threshold
    scores = args.scores or ([default_score] if args.quick else [default_score, 0.3])
    if min(scores) < LOW_SCORE:
        raise SystemExit(f"--scores: the boxes are collected down to {LOW_SCORE}; give thresholds at or above it")
    sequence = read_kitti_sequence(data_root() / "kitti_06_51", SEQUENCE)
    if sequence.ground_truth is None:
        raise SystemExit("kitti_06_51: no poses/06.txt: grouping the observations into objects needs the ground truth")
    detectors = {name: source for name, source in DETECTORS.items() if source == "yolox" or args.yolo11}
    results = []
    placements = []
    for name, source in detectors.items():
        detector_config = config.perception.detector.model_copy(update={"source": source})
        detections = detect_all(sequence, detector_config, name)
        scored = score_rows(detections, default_score)
        print(f"\n{name}, {len(sequence)} frames of kitti_06_51: boxes of every class down to score {LOW_SCORE:g}")
        bench.table(f"scores {source}", scored, list(scored[0]))
        for score in scores:
            frames = place(sequence, detections, score, config)
            run = RealRun(frames, [], sequence.ground_truth, sequence.camera)
            clusters = cluster_observations(run)
            rows = placement_rows(detections, frames, clusters, score)
            stable = stable_objects(clusters, run)
            mix = class_mix(clusters)
            print(
                f"\n{name}: street-class boxes at score >= {score:g} through the ORB stereo step (classes with a box)"
            )
            bench.table(f"classes {source} {score:g}", rows, list(rows[0]))
            if stable:
                print(f"\nstable objects other than cars ({name}, score >= {score:g}):")
                bench.table(f"stable {source} {score:g}", stable, list(stable[0]))
            stable_count = sum(is_stable(c) for c in clusters)
            bound = min(1.0, 3.0 / stable_count) if stable_count else 1.0
            print(
                f"\nclasses with a stable object: {list(mix)}; class mix of the {stable_count} stable objects: {mix} "
                f"(a class with no stable object has a share below {bound:.2f} at 95 %: 3 / n)"
            )
            placements.append(
                {
                    "detector": name,
                    "score": score,
                    "rows": rows,
                    "stable": stable,
                    "mix": mix,
                    "stable_objects": stable_count,
                }
            )
        results.append({"detector": name, "boxes": scored, "placements": placements[-len(scores) :]})
    profile = DETECTION_PROFILES["real"].world.class_mix
    shares = {label: round(share / sum(profile.values()), 3) for label, share in profile.items()}
    chosen = placements[0]  # the default detector at the default threshold
    print(
        f"\nrecommended ({chosen['detector']}, score >= {chosen['score']:g}): classes {list(chosen['mix'])}, "
        f"WorldConfig.class_mix {chosen['mix']} (shares of the {chosen['stable_objects']} stable objects); "
        f"the `real` profile's class_mix (the street's hand-labelled objects): {shares}"
    )
    bench.finish({"frames": len(sequence), "low_score": LOW_SCORE, "results": results, "profile_mix": shares})


if __name__ == "__main__":
    main()
