"""YOLOX (COCO, ONNX), the default detector's model (Apache-2.0 weights).

Formats (`shared/data/models/README.md`): input BGR 0-255, not normalised, letterboxed at the top left with 114;
one output row per grid cell of strides 8, 16 and 32 (finest first, row-major), columns (dx, dy, log w, log h,
objectness, class scores).
"""

from __future__ import annotations

import numpy as np

from neoslam.errors import InputError
from neoslam.perception.config import DetectorConfig
from neoslam.perception.detection import letterbox, load_class_names, network_size
from neoslam.perception.onnx_session import open_session

__all__ = ["STRIDES", "YoloxModel", "make_grid", "decode"]

STRIDES = (8, 16, 32)  # YOLOX heads, finest first: the order of the output rows
BOX_COLUMNS = 4  # dx, dy, log w, log h
OBJECTNESS_COLUMN = 4
FIRST_CLASS_COLUMN = 5
LABELS_FILE_NAME = "coco_classes.txt"  # looked for beside the model when no labels_file is configured
MODEL_HELP = (
    "get yolox_nano.onnx (and coco_classes.txt) from the GitHub repository Kazuhito00/YOLOX-ONNX-TFLite-Sample, "
    "folder model/ (see shared/data/models/README.md), and set perception.detector.model to it; "
    "or run another detector and pass its output with --detections FILE"
)


def make_grid(width: int, height: int, strides: tuple[int, ...] = STRIDES) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (N, 2) as (gx, gy) and the stride (N, 1) of each output row, in the model's row order, for an
    input of width x height px."""
    cells, cell_strides = [], []
    for stride in strides:
        gy, gx = np.mgrid[0 : height // stride, 0 : width // stride]  # row-major: x varies fastest
        cells.append(np.stack([gx.ravel(), gy.ravel()], axis=1))
        cell_strides.append(np.full((gx.size, 1), stride))
    return np.concatenate(cells).astype(np.float32), np.concatenate(cell_strides).astype(np.float32)


def decode(rows: np.ndarray, grid: np.ndarray, strides: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw output rows (N, 5 + classes) -> boxes (N, 4) x1, y1, x2, y2 in input px, scores (N,), class ids (N,).

    Each row keeps its best class only (score = objectness x class score), so that one object gives one label
    rather than, say, a car and a truck at the same place.
    """
    centres = (rows[:, :2] + grid) * strides
    sizes = np.exp(np.minimum(rows[:, 2:BOX_COLUMNS], 20.0)) * strides  # exp of a wild logit would overflow
    boxes = np.concatenate([centres - sizes / 2, centres + sizes / 2], axis=1)
    class_scores = rows[:, FIRST_CLASS_COLUMN:]
    class_ids = np.argmax(class_scores, axis=1)
    scores = rows[:, OBJECTNESS_COLUMN] * class_scores[np.arange(len(rows)), class_ids]
    return boxes, scores, class_ids


class YoloxModel:
    """A YOLOX network that turns one image window into boxes (window px), scores and class ids."""

    def __init__(self, config: DetectorConfig) -> None:
        model = self.model_path = config.model_path()
        self.session = open_session(model, config.threads, MODEL_HELP)
        self.class_names = load_class_names(model, config.labels_file, LABELS_FILE_NAME)
        self._input_name = self.session.get_inputs()[0].name
        columns = self.session.get_outputs()[0].shape[-1]
        if isinstance(columns, int) and columns != FIRST_CLASS_COLUMN + len(self.class_names):
            raise InputError(
                config.labels_file or model,
                f"{len(self.class_names)} class names but the model gives {columns - FIRST_CLASS_COLUMN} classes",
            )
        self._grids: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def infer(self, window_bgr: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every cell's box in window px, score and class id, the window enlarged by `scale` for the network."""
        size = network_size(window_bgr.shape[1], window_bgr.shape[0], scale)
        padded, r = letterbox(window_bgr, size, scale)
        blob = np.ascontiguousarray(padded.transpose(2, 0, 1)[np.newaxis], dtype=np.float32)
        rows = self.session.run(None, {self._input_name: blob})[0][0]
        if size not in self._grids:
            self._grids[size] = make_grid(*size)
        grid, strides = self._grids[size]
        if len(rows) != len(grid):
            raise InputError(self.model_path, f"gives {len(rows)} rows for a {size} input, expected {len(grid)}")
        boxes, scores, class_ids = decode(rows, grid, strides)
        return boxes.astype(np.float64) / r, scores.astype(np.float64), class_ids
