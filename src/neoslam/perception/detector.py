"""Object detection with YOLOX-Nano (COCO) through onnxruntime (paper 3.1: "objects are detected with Yolo").

The model's input and output formats are those of `shared/data/models/README.md`: a letterboxed BGR image,
0-255, not normalised, placed at the top left of a square padded with 114; one output row per grid cell of
strides 8, 16 and 32, columns (dx, dy, log w, log h, objectness, class scores).

Each step is its own function so that it can be tested on synthetic arrays: `letterbox` makes the network input,
`make_grid` the cell offsets, `decode` turns raw rows into boxes, `nms` suppresses duplicates class by class, and
`tile_origins` places the optional tiles that find small distant objects.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
import onnxruntime as ort

from neoslam.errors import ConfigError, InputError
from neoslam.perception.config import DetectorConfig

__all__ = [
    "COCO_CLASSES",
    "Detection",
    "ObjectDetector",
    "YoloxDetector",
    "letterbox",
    "make_grid",
    "decode",
    "nms",
    "tile_origins",
    "centred_tile_origins",
    "load_class_names",
]

STRIDES = (8, 16, 32)  # YOLOX heads, finest first: the order of the output rows
PAD_VALUE = 114  # YOLOX's letterbox fill
BOX_COLUMNS = 4  # dx, dy, log w, log h
OBJECTNESS_COLUMN = 4
FIRST_CLASS_COLUMN = 5
TILE_EDGE_MARGIN_PX = 2.0  # a tile box this close to a cut inside the image is a truncated object: dropped
LABELS_FILE_NAME = "coco_classes.txt"  # looked for beside the model when no labels_file is configured
MODEL_HELP = (
    "get yolox_nano.onnx (and coco_classes.txt) from the GitHub repository Kazuhito00/YOLOX-ONNX-TFLite-Sample, "
    "folder model/ (see shared/data/models/README.md), and set perception.detector.model to it; "
    "or run another detector and pass its output with perception.detector.source: file"
)

# COCO's 80 classes in the model's output order, spelled as in the model's coco_classes.txt.
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
    """Anything that gives the detections of a frame: `YoloxDetector`, `DetectionsFile`."""

    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]: ...


def letterbox(image_bgr: np.ndarray, size: int) -> tuple[np.ndarray, float]:
    """Network input (1, 3, size, size) float32, BGR 0-255, and the scale r: image px x r = input px.

    The image is scaled by r = min(size/h, size/w), put at the top left and padded with 114, as YOLOX was trained.
    """
    height, width = image_bgr.shape[:2]
    scale = min(size / height, size / width)
    resized = cv2.resize(image_bgr, (int(width * scale), int(height * scale)), interpolation=cv2.INTER_LINEAR)
    padded = np.full((size, size, 3), PAD_VALUE, dtype=np.uint8)
    padded[: resized.shape[0], : resized.shape[1]] = resized
    blob = np.ascontiguousarray(padded.transpose(2, 0, 1)[np.newaxis], dtype=np.float32)
    return blob, scale


def make_grid(size: int, strides: tuple[int, ...] = STRIDES) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (N, 2) as (gx, gy) and the stride (N, 1) of each output row, in the model's row order."""
    cells, cell_strides = [], []
    for stride in strides:
        side = size // stride
        gy, gx = np.mgrid[0:side, 0:side]  # row-major: x varies fastest
        cells.append(np.stack([gx.ravel(), gy.ravel()], axis=1))
        cell_strides.append(np.full((side * side, 1), stride))
    return np.concatenate(cells).astype(np.float32), np.concatenate(cell_strides).astype(np.float32)


def decode(rows: np.ndarray, grid: np.ndarray, strides: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw output rows (N, 5 + classes) -> boxes (N, 4) x1, y1, x2, y2 in input px, scores (N,), class ids (N,).

    Each row keeps its best class only (score = objectness x class score), so that one object gives one label
    rather than, say, a car and a truck at the same place.
    """
    centres = (rows[:, :2] + grid) * strides
    sizes = np.exp(rows[:, 2:BOX_COLUMNS]) * strides
    boxes = np.concatenate([centres - sizes / 2, centres + sizes / 2], axis=1)
    class_scores = rows[:, FIRST_CLASS_COLUMN:]
    class_ids = np.argmax(class_scores, axis=1)
    scores = rows[:, OBJECTNESS_COLUMN] * class_scores[np.arange(len(rows)), class_ids]
    return boxes, scores, class_ids


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


def tile_origins(length: int, side: int, overlap: float) -> list[int]:
    """Start of each tile of `side` px along an image side of `length` px, neighbours sharing `overlap` x side.

    The tiles are spread evenly from one end to the other; none when one tile would cover the whole side.
    """
    if length <= side:
        return []
    step = side * (1.0 - overlap)
    count = math.ceil((length - side) / step) + 1
    return [round(o) for o in np.linspace(0, length - side, count)]


def centred_tile_origins(length: int, side: int, span: float, overlap: float) -> list[int]:
    """Start of each tile of `side` px over the centred band of `span` x `length` px (at least one tile wide).

    Far objects gather about the vanishing point, near the image centre, so the band there gains most per tile.
    """
    band = min(max(round(span * length), side), length)
    first = (length - band) // 2
    return [first + origin for origin in tile_origins(band, side, overlap)] or [first]


def load_class_names(model_path: Path, labels_file: Path | None) -> tuple[str, ...]:
    """The configured labels file, else coco_classes.txt beside the model, else COCO's 80 names."""
    path = labels_file if labels_file is not None else model_path.parent / LABELS_FILE_NAME
    if labels_file is None and not path.is_file():
        return COCO_CLASSES
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(path, f"cannot read the class names ({error})") from error
    return tuple(line.strip() for line in text.splitlines() if line.strip())


def _to_bgr(image: np.ndarray) -> np.ndarray:
    """A grey (h, w) or (h, w, 1) uint8 image replicated to 3 channels; a BGR (h, w, 3) one as it is."""
    if image.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {image.dtype}")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image.reshape(image.shape[:2]), cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    raise ValueError(f"images must be grey (h, w) or BGR (h, w, 3), got shape {image.shape}")


class YoloxDetector:
    """YOLOX (ONNX) on the whole frame, and optionally on square tiles across it.

    All boxes go through class-wise NMS (`nms_iou`), then across classes at `duplicate_iou`, so that one object
    seen as both car and truck (by the frame and by a tile, say) keeps its best label only.
    """

    def __init__(self, config: DetectorConfig) -> None:
        self.config = config
        self.session = self._open_session(config)
        self.class_names = load_class_names(config.model, config.labels_file)
        self._input_name = self._check_model(config)
        unknown = [name for name in config.classes if name not in self.class_names]
        if unknown:
            raise ConfigError(
                f"perception.detector.classes: {unknown} are not classes of the model (it has e.g. "
                f"{list(self.class_names[:8])}...)"
            )
        self._kept_ids = np.array([self.class_names.index(name) for name in config.classes])
        self._grid, self._strides = make_grid(config.input_size)

    @staticmethod
    def _open_session(config: DetectorConfig) -> ort.InferenceSession:
        if not config.model.is_file():
            raise InputError(config.model, f"YOLOX model not found: {MODEL_HELP}")
        options = ort.SessionOptions()
        options.intra_op_num_threads = config.threads
        options.inter_op_num_threads = 1  # one image at a time: nothing to run in parallel across operators
        options.log_severity_level = 3  # errors only; warnings would clutter the CLI's output
        # Spinning threads keep both cores busy after each inference and slow the OpenCV steps that follow (measured:
        # stereo odometry 46 ms per frame with spinning, 28 ms without).
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        try:
            return ort.InferenceSession(str(config.model), options, providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime's load errors derive from Exception only (InvalidProtobuf, ...)
            raise InputError(config.model, f"cannot load the ONNX model ({error}); {MODEL_HELP}") from error

    def _check_model(self, config: DetectorConfig) -> str:
        """The input name, after checking the model's shapes against the config, grid and class names."""
        model_input = self.session.get_inputs()[0]
        height, width = model_input.shape[2:]
        if isinstance(height, int) and isinstance(width, int) and (height, width) != (config.input_size,) * 2:
            raise ConfigError(
                f"perception.detector.input_size is {config.input_size} but {config.model} takes {height}x{width}"
            )
        rows, columns = self.session.get_outputs()[0].shape[1:]
        expected_rows = sum((config.input_size // s) ** 2 for s in STRIDES)
        if isinstance(rows, int) and rows != expected_rows:
            raise InputError(config.model, f"gives {rows} rows, expected {expected_rows} (strides {STRIDES})")
        if isinstance(columns, int) and columns != FIRST_CLASS_COLUMN + len(self.class_names):
            raise InputError(
                config.labels_file or config.model,
                f"{len(self.class_names)} class names but the model gives {columns - FIRST_CLASS_COLUMN} classes",
            )
        return model_input.name

    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]:
        """Detections of the kept classes in one image (grey or BGR), best score first.

        `frame_index` is not used by the network; it is part of the `ObjectDetector` interface.
        """
        bgr = _to_bgr(image)
        height, width = bgr.shape[:2]
        boxes, scores, class_ids = self._detect_window(bgr)
        if self.config.tiling:
            parts = [(boxes, scores, class_ids)] + self._detect_tiles(bgr)
            boxes, scores, class_ids = (np.concatenate(p) for p in zip(*parts, strict=True))
        boxes[:, 0::2] = np.clip(boxes[:, 0::2], 0, width)
        boxes[:, 1::2] = np.clip(boxes[:, 1::2], 0, height)
        tall = boxes[:, 3] - boxes[:, 1] >= self.config.min_box_height
        boxes, scores, class_ids = boxes[tall], scores[tall], class_ids[tall]
        kept = nms(boxes, scores, class_ids, self.config.nms_iou)
        one_class = np.zeros(len(kept), dtype=class_ids.dtype)  # now across classes, for one label per object
        kept = kept[nms(boxes[kept], scores[kept], one_class, self.config.duplicate_iou)]
        detections = [Detection(self.class_names[class_ids[i]], scores[i], boxes[i]) for i in kept]
        return sorted(detections, key=lambda d: (-d.score, d.box[0], d.box[1], d.label))

    def _detect_window(self, bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes in the window's px, scores and class ids of the kept classes above the score threshold."""
        blob, scale = letterbox(bgr, self.config.input_size)
        rows = self.session.run(None, {self._input_name: blob})[0][0]
        boxes, scores, class_ids = decode(rows, self._grid, self._strides)
        keep = (scores >= self.config.score_threshold) & np.isin(class_ids, self._kept_ids)
        return boxes[keep].astype(np.float64) / scale, scores[keep].astype(np.float64), class_ids[keep]

    def _detect_tiles(self, bgr: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Detections of square tiles (side = image height, capped at the width) across the centred band of
        `tile_span` x width, in image px.

        Boxes that touch a cut inside the image are dropped: they are truncated objects, which the whole frame
        or the overlapping neighbour tile sees whole.
        """
        height, width = bgr.shape[:2]
        side = min(height, width)
        x_origins = centred_tile_origins(width, side, self.config.tile_span, self.config.tile_overlap)
        y_origins = tile_origins(height, side, self.config.tile_overlap) or [0]
        if len(x_origins) * len(y_origins) == 1:
            return []  # a square image: its only tile is the whole frame, already run
        parts = []
        for y0 in y_origins:
            for x0 in x_origins:
                boxes, scores, class_ids = self._detect_window(bgr[y0 : y0 + side, x0 : x0 + side])
                boxes += (x0, y0, x0, y0)
                cut = _touches_inner_cut(boxes, (x0, y0), side, (width, height))
                parts.append((boxes[~cut], scores[~cut], class_ids[~cut]))
        return parts


def _touches_inner_cut(
    boxes: np.ndarray, origin: tuple[int, int], side: int, image_size: tuple[int, int]
) -> np.ndarray:
    """Which boxes (image px) of the tile at `origin` touch one of its edges that lies inside the image."""
    cut = np.zeros(len(boxes), dtype=bool)
    for axis, (start, length) in enumerate(zip(origin, image_size, strict=True)):
        if start > 0:
            cut |= boxes[:, axis] <= start + TILE_EDGE_MARGIN_PX
        if start + side < length:
            cut |= boxes[:, axis + 2] >= start + side - TILE_EDGE_MARGIN_PX
    return cut
