"""Detection recall and false positives against hand labels, by distance band (benchmarks only: labels are truth).

Labels file (JSON; `tests/data/labels/README.md` describes the ones shipped)::

    {"min_box_height_px": 12, "frames": {"0": [{"label": "car", "box": [x1, y1, x2, y2], "occluded": 0,
     "truncated": false, "distance_m": 12.5, "doubtful": false}, ...], ...}}

Counting, as in KITTI's object benchmark: a label counts when it is a vehicle (car or truck) at least
`min_box_height_px` high and not doubtful. Doubtful and too-small labels, and labels of other classes, are neither
missed nor found: a detection on them is no false positive. Detections are matched to labels greedily by IoU
(highest first, at least `min_iou`), class-agnostically among vehicles (a van called a truck is found). A detection
that matches no label at all is a false positive.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.errors import InputError
from neoslam.text import read_text

__all__ = [
    "LabelledObject",
    "FrameLabels",
    "read_labels",
    "box_iou",
    "FrameMatch",
    "match_frame",
    "DetectionStats",
    "detection_stats",
    "DISTANCE_BANDS",
    "VEHICLES",
]

VEHICLES = frozenset({"car", "truck"})
DISTANCE_BANDS: tuple[tuple[str, float, float], ...] = (
    ("< 20 m", 0.0, 20.0),
    ("20-40 m", 20.0, 40.0),
    (">= 40 m", 40.0, math.inf),
)
DEFAULT_MIN_BOX_HEIGHT = 12.0
NEAR_RANGE_M = 40.0  # the recall target's "nearer than 40 m": the stereo range objects are placed in


@dataclass(frozen=True, slots=True)
class LabelledObject:
    label: str
    box: tuple[float, float, float, float]
    distance_m: float
    occluded: int = 0
    truncated: bool = False
    doubtful: bool = False

    @property
    def height(self) -> float:
        return self.box[3] - self.box[1]


@dataclass(frozen=True, slots=True)
class FrameLabels:
    frame: int
    objects: tuple[LabelledObject, ...]


def _labelled_object(path: Path, key: str, item: Any) -> LabelledObject:
    where = f"frame {key}"
    try:
        box = tuple(float(v) for v in item["box"])
        obj = LabelledObject(
            label=str(item["label"]),
            box=box,  # type: ignore[arg-type]
            distance_m=float(item["distance_m"]),
            occluded=int(item.get("occluded", 0)),
            truncated=bool(item.get("truncated", False)),
            doubtful=bool(item.get("doubtful", False)),
        )
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(
            path, f"{where}: a label needs label, box [x1, y1, x2, y2] and distance_m ({error})"
        ) from error
    if len(box) != 4 or not all(math.isfinite(v) for v in box) or box[0] >= box[2] or box[1] >= box[3]:
        raise InputError(path, f"{where}: box {list(box)} is not x1 < x2, y1 < y2 in finite pixels")
    if not (math.isfinite(obj.distance_m) and obj.distance_m > 0):
        raise InputError(path, f"{where}: distance_m {obj.distance_m} is not a positive distance")
    return obj


def read_labels(path: Path) -> tuple[list[FrameLabels], float]:
    """The labelled frames in frame order, and the least box height that counts (px)."""
    try:
        document = json.loads(read_text(Path(path)))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
        raise InputError(path, f"cannot read the labels ({error})") from error
    if not isinstance(document, dict) or not isinstance(document.get("frames"), dict):
        raise InputError(path, 'not a labels file: expected an object with "frames": {"0": [...], ...}')
    frames = []
    for key, items in document["frames"].items():
        if not key.isdigit() or not isinstance(items, list):
            raise InputError(path, f"frame key {key!r} must be a frame number holding a list of labels")
        frames.append(FrameLabels(int(key), tuple(_labelled_object(path, key, item) for item in items)))
    height = float(document.get("min_box_height_px", DEFAULT_MIN_BOX_HEIGHT))
    return sorted(frames, key=lambda f: f.frame), height


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box of a (N, 4) with every box of b (M, 4), x1 y1 x2 y2: (N, M)."""
    a, b = np.asarray(a, float).reshape(-1, 4), np.asarray(b, float).reshape(-1, 4)
    top_left = np.maximum(a[:, None, :2], b[None, :, :2])
    bottom_right = np.minimum(a[:, None, 2:], b[None, :, 2:])
    overlap = np.prod(np.clip(bottom_right - top_left, 0, None), axis=2)
    area_a = np.prod(a[:, 2:] - a[:, :2], axis=1)
    area_b = np.prod(b[:, 2:] - b[:, :2], axis=1)
    return overlap / np.maximum(area_a[:, None] + area_b[None, :] - overlap, np.finfo(float).tiny)


@dataclass(frozen=True, slots=True)
class FrameMatch:
    counted: tuple[LabelledObject, ...]  # the labels that count
    found: tuple[bool, ...]  # of each counted label
    false_positives: int


def _counts(obj: LabelledObject, min_height: float) -> bool:
    return obj.label in VEHICLES and not obj.doubtful and obj.height >= min_height


def match_frame(
    labels: Sequence[LabelledObject],
    boxes: np.ndarray,
    detected_labels: Sequence[str],
    min_iou: float,
    min_height: float = DEFAULT_MIN_BOX_HEIGHT,
) -> FrameMatch:
    """Greedy IoU matching of one frame's detections (boxes (M, 4) with their labels) to its labels."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    label_boxes = np.array([obj.box for obj in labels], dtype=float).reshape(-1, 4)
    iou = box_iou(label_boxes, boxes)
    # Vehicles match vehicles whatever the class; other classes only their own.
    same_kind = np.array(
        [[_same_kind(obj.label, name) for name in detected_labels] for obj in labels], dtype=bool
    ).reshape(iou.shape)
    iou = np.where(same_kind, iou, 0.0)
    label_used, detection_used = np.zeros(len(labels), bool), np.zeros(len(boxes), bool)
    for flat in np.argsort(-iou, axis=None, kind="stable"):
        i, j = np.unravel_index(flat, iou.shape)
        if iou[i, j] < min_iou:
            break
        if not label_used[i] and not detection_used[j]:
            label_used[i] = detection_used[j] = True
    counted = [i for i, obj in enumerate(labels) if _counts(obj, min_height)]
    return FrameMatch(
        counted=tuple(labels[i] for i in counted),
        found=tuple(bool(label_used[i]) for i in counted),
        false_positives=int((~detection_used).sum()),
    )


def _same_kind(labelled: str, detected: str) -> bool:
    return labelled == detected or (labelled in VEHICLES and detected in VEHICLES)


@dataclass(frozen=True, slots=True)
class DetectionStats:
    frames: int
    vehicles: int
    found: int
    recall: float  # of all counted vehicles; NaN without any
    recall_nearer_40m: float
    false_positives_per_frame: float
    by_band: dict[str, tuple[int, int]]  # band -> (found, labelled)

    def as_row(self) -> dict[str, float | int | str]:
        row: dict[str, float | int | str] = {
            "frames": self.frames,
            "vehicles": self.vehicles,
            "recall": self.recall,
            "recall < 40 m": self.recall_nearer_40m,
            "FP / frame": self.false_positives_per_frame,
        }
        row |= {f"found {band}": f"{found}/{total}" for band, (found, total) in self.by_band.items()}
        return row


def _ratio(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def detection_stats(
    matches: Iterable[FrameMatch], bands: Mapping[str, tuple[float, float]] | None = None
) -> DetectionStats:
    """Recall overall, nearer than 40 m and by distance band; false positives per frame."""
    bands = bands or {name: (low, high) for name, low, high in DISTANCE_BANDS}
    matches = list(matches)
    pairs = [(obj, found) for m in matches for obj, found in zip(m.counted, m.found, strict=True)]
    near = [found for obj, found in pairs if obj.distance_m < NEAR_RANGE_M]
    by_band = {
        name: (
            sum(f for o, f in pairs if low <= o.distance_m < high),
            sum(low <= o.distance_m < high for o, _ in pairs),
        )
        for name, (low, high) in bands.items()
    }
    found = sum(f for _, f in pairs)
    return DetectionStats(
        frames=len(matches),
        vehicles=len(pairs),
        found=found,
        recall=_ratio(found, len(pairs)),
        recall_nearer_40m=_ratio(sum(near), len(near)),
        false_positives_per_frame=_ratio(sum(m.false_positives for m in matches), len(matches)),
        by_band=by_band,
    )
