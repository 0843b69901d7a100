"""YOLO11 (Ultralytics, COCO, ONNX): an optional detector the user selects (`perception.detector.source: yolo11`).

Its weights are AGPL-3.0, so NeoSLAM never ships them and never uses them by default. Formats
(`shared/data/models/yolo11n_coco/README.md`): input RGB scaled to 0-1, letterboxed, sides multiples of 32; output
[1, 4 + classes, N] with N the grid cells of strides 8, 16 and 32 (finest first, row-major); rows 0-3 the distances
(left, top, right, bottom) from the cell centre in cells, the rest class probabilities (no objectness).
"""

from __future__ import annotations

import cv2
import numpy as np

from neoslam.errors import InputError
from neoslam.perception.config import DetectorConfig
from neoslam.perception.detection import letterbox, load_class_names, network_size
from neoslam.perception.onnx_session import open_session
from neoslam.perception.yolox import STRIDES, make_grid

__all__ = ["Yolo11Model", "decode"]

BOX_ROWS = 4  # distances left, top, right, bottom
CELL_CENTRE = 0.5  # anchor points sit in the middle of their cells
LABELS_FILE_NAME = "coco_classes.txt"
# The weights are stored as int8 with dequantisation nodes: dequantise them once at load time (about 20 % faster).
SESSION_ENTRIES = {"session.disable_quant_qdq": "1"}
MODEL_HELP = (
    "YOLO11n is an option you select; its weights (AGPL-3.0) are not part of NeoSLAM: see "
    "shared/data/models/yolo11n_coco/README.md, and set perception.detector.model to yolo11n_coco.onnx"
)


def decode(output: np.ndarray, grid: np.ndarray, strides: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw output (4 + classes, N) -> boxes (N, 4) x1, y1, x2, y2 in input px, scores (N,), class ids (N,)."""
    distances = output[:BOX_ROWS].T
    anchors = grid + CELL_CENTRE
    boxes = np.concatenate([anchors - distances[:, :2], anchors + distances[:, 2:]], axis=1) * strides
    class_scores = output[BOX_ROWS:]
    class_ids = np.argmax(class_scores, axis=0)
    return boxes, class_scores[class_ids, np.arange(output.shape[1])], class_ids


class Yolo11Model:
    """A YOLO11 network that turns one image window into boxes (window px), scores and class ids."""

    def __init__(self, config: DetectorConfig) -> None:
        model = self.model_path = config.model_path()
        self.session = open_session(model, config.threads, MODEL_HELP, SESSION_ENTRIES)
        self.class_names = load_class_names(model, config.labels_file, LABELS_FILE_NAME)
        self._input_name = self.session.get_inputs()[0].name
        rows = self.session.get_outputs()[0].shape[1]
        if isinstance(rows, int) and rows != BOX_ROWS + len(self.class_names):
            raise InputError(
                config.labels_file or model,
                f"{len(self.class_names)} class names but the model gives {rows - BOX_ROWS} classes",
            )
        self._grids: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def infer(self, window_bgr: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every cell's box in window px, score and class id, the window enlarged by `scale` for the network."""
        size = network_size(window_bgr.shape[1], window_bgr.shape[0], scale)
        padded, r = letterbox(window_bgr, size, scale)
        rgb = cv2.cvtColor(padded, cv2.COLOR_BGR2RGB)
        blob = np.ascontiguousarray(rgb.transpose(2, 0, 1)[np.newaxis], dtype=np.float32) / np.float32(255.0)
        output = self.session.run(None, {self._input_name: blob})[0][0]
        if size not in self._grids:
            self._grids[size] = make_grid(*size, STRIDES)
        grid, strides = self._grids[size]
        if output.shape[1] != len(grid):
            raise InputError(self.model_path, f"gives {output.shape[1]} cells for a {size} input, expected {len(grid)}")
        boxes, scores, class_ids = decode(output, grid, strides)
        return boxes.astype(np.float64) / r, scores.astype(np.float64), class_ids
