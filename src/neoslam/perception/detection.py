"""What every object detector shares: the detection record, the detector protocol, the windows a network looks at,
the letterbox that makes a window the network's input, and non-maximum suppression.

A model (`yolox.py`, `yolo11.py`) only turns a window into boxes; `detector.py` runs the configured windows
through it and merges what they find. Each step is its own function so that it can be tested on synthetic arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from neoslam.text import read_text

__all__ = [
    "COCO_CLASSES",
    "PAD_VALUE",
    "Detection",
    "ObjectDetector",
    "Window",
    "letterbox",
    "network_size",
    "nms",
    "touches_inner_cut",
    "to_bgr",
    "plain_image",
    "equalise_contrast",
    "load_class_names",
]

PAD_VALUE = 114  # the YOLO family's letterbox fill
STRIDE_MULTIPLE = 32  # the coarsest head's stride: network input sides are multiples of it

# COCO's 80 classes in the models' output order, spelled as in YOLOX's coco_classes.txt.
COCO_CLASSES: tuple[str, ...] = (
    "person", "bicycle", "car", "motorbike", "aeroplane", "bus", "train", "truck", "boat", "traffic light",
    "fire hydrant", "stop sign", "parking meter", "bench", "bird", "cat", "dog", "horse", "sheep", "cow",
    "elephant", "bear", "zebra", "giraffe", "backpack", "umbrella", "handbag", "tie", "suitcase", "frisbee",
    "skis", "snowboard", "sports ball", "kite", "baseball bat", "baseball glove", "skateboard", "surfboard",
    "tennis racket", "bottle", "wine glass", "cup", "fork", "knife", "spoon", "bowl", "banana", "apple",
    "sandwich", "orange", "broccoli", "carrot", "hot dog", "pizza", "donut", "cake", "chair", "sofa",
    "pottedplant", "bed", "diningtable", "toilet", "tvmonitor", "laptop", "mouse", "remote", "keyboard",
    "cell phone", "microwave", "oven", "toaster", "sink", "refrigerator", "book", "clock", "vase", "scissors",
    "teddy bear", "hair drier", "toothbrush",
)  # fmt: skip


@dataclass(frozen=True, slots=True, eq=False)
class Detection:
    """One detected object: its class name, score in [0, 1] and box (x1, y1, x2, y2) in left-image pixels."""

    label: str
    score: float
    box: np.ndarray = field(repr=True)  # (4,) x1, y1, x2, y2 in left-image px

    def __post_init__(self) -> None:
        # A frozen dataclass holding a writable array would only be half frozen: keep a read-only float copy.
        box = np.array(self.box, dtype=np.float64).reshape(4)
        box.flags.writeable = False
        object.__setattr__(self, "box", box)
        object.__setattr__(self, "score", float(self.score))

    def __eq__(self, other: object) -> bool:
        # The generated __eq__ would compare arrays with ==, whose truth value is ambiguous.
        if not isinstance(other, Detection):
            return NotImplemented
        return self.label == other.label and self.score == other.score and np.array_equal(self.box, other.box)

    __hash__ = None  # type: ignore[assignment]  # equal by value, yet holds an array: not hashable


class ObjectDetector(Protocol):
    """Anything that gives the detections of a frame: a model's detector, `DetectionsFile`."""

    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]: ...


@dataclass(frozen=True, slots=True)
class Window:
    """A rectangle of the image (x0, y0, x1, y1 in px) that the network sees enlarged by `scale`."""

    x0: int
    y0: int
    x1: int
    y1: int
    scale: float

    @classmethod
    def of(
        cls, image_size: tuple[int, int], rows: tuple[float, float], columns: tuple[float, float], scale: float
    ) -> Window:
        """The window over the given shares of the image's rows and columns (0 = top or left, 1 = bottom or right)."""
        width, height = image_size
        return cls(
            round(columns[0] * width),
            round(rows[0] * height),
            round(columns[1] * width),
            round(rows[1] * height),
            scale,
        )

    def crop(self, image: np.ndarray) -> np.ndarray:
        return image[self.y0 : self.y1, self.x0 : self.x1]

    def inner_edges(self, image_size: tuple[int, int]) -> tuple[bool, bool, bool, bool]:
        """Whether the left, top, right and bottom edges lie inside the image (they cut objects), not on its border."""
        width, height = image_size
        return self.x0 > 0, self.y0 > 0, self.x1 < width, self.y1 < height


def network_size(width: int, height: int, scale: float) -> tuple[int, int]:
    """The network input (width, height) that holds a width x height crop enlarged by `scale`: each side rounded up
    to a multiple of the coarsest stride."""
    return tuple(
        max(STRIDE_MULTIPLE, math.ceil(round(side * scale, 6) / STRIDE_MULTIPLE) * STRIDE_MULTIPLE)
        for side in (width, height)
    )


def letterbox(image: np.ndarray, input_size: tuple[int, int], scale: float | None = None) -> tuple[np.ndarray, float]:
    """The image resized by r (default: as large as fits `input_size` = (width, height)), put at the top left of an
    input of that size padded with 114, as (h, w, 3) uint8; and r (image px x r = input px)."""
    width, height = input_size
    rows, columns = image.shape[:2]
    r = min(width / columns, height / rows) if scale is None else scale
    size = (min(width, round(columns * r)), min(height, round(rows * r)))
    resized = cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)
    padded = np.full((height, width, 3), PAD_VALUE, dtype=np.uint8)
    padded[: resized.shape[0], : resized.shape[1]] = resized
    return padded, r


def nms(boxes: np.ndarray, scores: np.ndarray, class_ids: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Indices of the boxes kept by class-wise non-maximum suppression, best score first (ties: input order)."""
    order = np.argsort(-scores, kind="stable")
    areas = np.prod(np.clip(boxes[:, 2:] - boxes[:, :2], 0, None), axis=1)
    kept: list[int] = []
    while order.size:
        best, rest = order[0], order[1:]
        kept.append(int(best))
        top_left = np.maximum(boxes[best, :2], boxes[rest, :2])
        bottom_right = np.minimum(boxes[best, 2:], boxes[rest, 2:])
        overlap = np.prod(np.clip(bottom_right - top_left, 0, None), axis=1)
        iou = overlap / np.maximum(areas[best] + areas[rest] - overlap, np.finfo(float).tiny)
        order = rest[(iou <= iou_threshold) | (class_ids[rest] != class_ids[best])]
    return np.array(kept, dtype=np.intp)


def touches_inner_cut(boxes: np.ndarray, window: Window, image_size: tuple[int, int], margin: float) -> np.ndarray:
    """Which boxes (image px) come within `margin` px of an edge of the window that lies inside the image: objects
    the window cuts, which another window sees whole."""
    left, top, right, bottom = window.inner_edges(image_size)
    cut = np.zeros(len(boxes), dtype=bool)
    if left:
        cut |= boxes[:, 0] <= window.x0 + margin
    if top:
        cut |= boxes[:, 1] <= window.y0 + margin
    if right:
        cut |= boxes[:, 2] >= window.x1 - margin
    if bottom:
        cut |= boxes[:, 3] >= window.y1 - margin
    return cut


def equalise_contrast(image: np.ndarray, clip: float, tiles: int) -> np.ndarray:
    """Contrast-limited adaptive histogram equalisation (CLAHE) of a grey image, or of a BGR image's lightness; the
    image as it is for clip 0.

    KITTI's grey frames are dark where parked cars stand in the shade of trees and hedges; equalised locally, the
    cars there stand out (measured on the labelled frames: `benchmarks.frontend_speed --parts windows`). A grey image
    is equalised as it is, before it is replicated to the network's three channels: a quarter of the cost of going
    through LAB, and on the labelled frames as good or better."""
    if clip <= 0:
        return image
    clahe = cv2.createCLAHE(clipLimit=clip, tileGridSize=(tiles, tiles))
    if image.ndim == 2:
        return clahe.apply(image)
    lab = cv2.cvtColor(image, cv2.COLOR_BGR2LAB)
    lab[..., 0] = clahe.apply(np.ascontiguousarray(lab[..., 0]))
    return cv2.cvtColor(lab, cv2.COLOR_LAB2BGR)


def plain_image(image: np.ndarray) -> np.ndarray:
    """A uint8 grey (h, w) or BGR (h, w, 3) image as it is, a (h, w, 1) one as (h, w); ValueError for others."""
    if image.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {image.dtype}")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3):
        return image
    if image.ndim == 3 and image.shape[2] == 1:
        return image.reshape(image.shape[:2])
    raise ValueError(f"images must be grey (h, w) or BGR (h, w, 3), got shape {image.shape}")


def to_bgr(image: np.ndarray) -> np.ndarray:
    """A grey (h, w) or (h, w, 1) uint8 image replicated to 3 channels; a BGR (h, w, 3) one as it is."""
    image = plain_image(image)
    return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image


def load_class_names(model_path: Path, labels_file: Path | None, file_name: str) -> tuple[str, ...]:
    """The configured labels file, else `file_name` beside the model, else COCO's 80 names."""
    path = labels_file if labels_file is not None else model_path.parent / file_name
    if labels_file is None and not path.is_file():
        return COCO_CLASSES
    text = read_text(path, "class names file not found")
    return tuple(line.strip() for line in text.splitlines() if line.strip())
