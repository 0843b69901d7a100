"""Part (c) of the real_streets study: the detector on real KITTI frames, its recall against hand labels.

(c) Detection. Each detector configuration runs over the hand-labelled frames (`tests/data/labels/`: frames 0, 5,
    ..., 50 of kitti_06_51 and the KITTI object pair). Recall of the labelled vehicles (cars and trucks at least
    12 px high, doubtful ones left out; IoU 0.4, class-agnostic among vehicles) by distance band, nearer than 40 m
    and over all; false positives a frame (boxes on no labelled object); median detection ms a frame. YOLO11n
    rows appear only when its model is in the shared data (its weights are AGPL-3.0: an option, never the default).
    The score threshold of the default configuration is swept too.

    python -m benchmarks.real_streets --parts detection

The detector's speed, its windows' recall against their cost, and the whole front end's speed are
`benchmarks.frontend_speed`'s.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from benchmarks import harness
from benchmarks.harness import REPO_ROOT, data_root
from neoslam.config import NeoSLAMConfig
from neoslam.config.perception import DetectionPass, DetectorConfig
from neoslam.evaluation.detection import detection_stats, match_frame, read_labels
from neoslam.perception.detector import make_detector

LABELS = REPO_ROOT / "tests" / "data" / "labels"
MIN_IOU = 0.4
SEQUENCE = "06"
WHOLE = DetectionPass()
HALF = DetectionPass(scale=0.5)
BAND = DetectionPass(rows=(0.32, 0.78), scale=1.5)  # the road band, where parked and distant cars stand
SMALL = DetectionPass(scale=416 / 1226)  # the whole frame shrunk to the 416 px YOLOX-Nano was exported for
DETECTORS: dict[str, dict] = {
    "YOLOX-Nano, frame at 416 px, score 0.35 (as exported)": {
        "passes": [SMALL],
        "score_threshold": 0.35,
        "contrast_clip": 0,
    },
    "YOLOX-Nano, frame x1, no CLAHE": {"passes": [WHOLE], "contrast_clip": 0},
    "YOLOX-Nano, frame x1": {"passes": [WHOLE]},
    "YOLOX-Nano, frame x1.25": {"passes": [DetectionPass(scale=1.25)]},
    "YOLOX-Nano, frame x1 + road band x1.5": {"passes": [WHOLE, BAND]},
    "YOLOX-Nano, frame x0.5 + road band x1.5": {"passes": [HALF, BAND]},
    "YOLOX-Nano, frame x0.5 + road band x1.25, no CLAHE": {"contrast_clip": 0},
    "YOLOX-Nano, frame x0.5 + road band x1.25 (default)": {},
    "YOLO11n, frame x1": {"source": "yolo11", "passes": [WHOLE]},
    "YOLO11n, frame x1 + road band x1.5": {"source": "yolo11", "passes": [WHOLE, BAND]},
    "YOLO11n, frame x1 + road band x1.5, score 0.35": {
        "source": "yolo11",
        "passes": [WHOLE, BAND],
        "score_threshold": 0.35,
    },
    "YOLO11n, frame x0.5 + road band x1.5": {"source": "yolo11", "passes": [HALF, BAND]},
    "YOLO11n, frame x0.5 + road band x1.25": {"source": "yolo11"},
}
THRESHOLDS = [0.3, 0.35, 0.4, 0.5]  # the default, 0.45, has its row above
NMS_IOUS = [0.3, 0.6]  # the default, 0.45, likewise


def _labelled_images() -> list[tuple[np.ndarray, list]]:
    """(image, labels) of every labelled frame: kitti_06_51's and the object pair's."""
    images = []
    frames, _ = read_labels(LABELS / "kitti_06_51.json")
    folder = data_root() / "kitti_06_51" / "sequences" / SEQUENCE / "image_0"
    images += [(cv2.imread(str(folder / f"{f.frame:06d}.png"), cv2.IMREAD_GRAYSCALE), f.objects) for f in frames]
    (pair,), _ = read_labels(LABELS / "kitti_object_pair.json")
    images.append((cv2.imread(str(data_root() / "kitti_object_pair" / "left.png"), cv2.IMREAD_COLOR), pair.objects))
    return images


def _detection_row(name: str, config: DetectorConfig, images: list) -> dict:
    detector = make_detector(config)
    detector.detect(0, images[0][0])  # warm-up
    matches, times = [], []
    for image, labels in images:
        start = time.perf_counter()
        detections = detector.detect(0, image)
        times.append(time.perf_counter() - start)
        boxes = np.array([d.box for d in detections]).reshape(-1, 4)
        matches.append(match_frame(labels, boxes, [d.label for d in detections], MIN_IOU))
    return {"detector": name, **detection_stats(matches).as_row(), "ms / frame": float(np.median(times) * 1e3)}


def run_detection(bench: harness.Run, args: argparse.Namespace) -> dict:
    """(c): every detector configuration over the hand-labelled frames."""
    base = NeoSLAMConfig()
    images = _labelled_images()
    have_yolo11 = DetectorConfig(source="yolo11").model_path().is_file()
    detector_rows = [
        _detection_row(name, base.perception.detector.model_copy(update=changes), images)
        for name, changes in DETECTORS.items()
        if have_yolo11 or changes.get("source") != "yolo11"
    ]
    detector_rows += [
        _detection_row(
            f"default at score {t}", base.perception.detector.model_copy(update={"score_threshold": t}), images
        )
        for t in THRESHOLDS
    ]
    detector_rows += [
        _detection_row(
            f"default at NMS IoU {iou}", base.perception.detector.model_copy(update={"nms_iou": iou}), images
        )
        for iou in NMS_IOUS
    ]
    columns = ["detector", "frames", "vehicles", "recall < 40 m", "recall", "FP / frame"]
    columns += [c for c in detector_rows[0] if c.startswith("found ")] + ["ms / frame"]
    bench.table("detection", detector_rows, columns)
    return {"detection": detector_rows}
