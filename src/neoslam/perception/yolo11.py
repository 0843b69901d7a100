"""YOLO11 (Ultralytics, COCO, ONNX): an optional detector the user selects (`perception.detector.source: yolo11`).

Its weights are AGPL-3.0, so NeoSLAM never ships them and never uses them by default. Formats
(`shared/data/models/yolo11n_coco/README.md`): input RGB scaled to 0-1, letterboxed, sides multiples of 32; output
[1, 4 + classes, N] with N the grid cells of strides 8, 16 and 32 (finest first, row-major); rows 0-3 the distances
(left, top, right, bottom) from the cell centre in cells, the rest class probabilities (no objectness).
"""

from __future__ import annotations

import cv2
import numpy as np

from neoslam.perception.grid_model import GridModel

__all__ = ["Yolo11Model", "decode"]

BOX_ROWS = 4  # distances left, top, right, bottom
CELL_CENTRE = 0.5  # anchor points sit in the middle of their cells
GREY_MAX = 255.0
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


class Yolo11Model(GridModel):
    """YOLO11: RGB 0-1 in, one column per cell out."""

    help_text = MODEL_HELP
    # The weights are stored as int8 with dequantisation nodes: dequantise them once at load time (about 20 % faster).
    session_entries = {"session.disable_quant_qdq": "1"}

    def _blob(self, padded_bgr: np.ndarray) -> np.ndarray:
        rgb = cv2.cvtColor(padded_bgr, cv2.COLOR_BGR2RGB)
        return np.ascontiguousarray(rgb.transpose(2, 0, 1)[np.newaxis], dtype=np.float32) / np.float32(GREY_MAX)

    def _cells(self, output: np.ndarray) -> np.ndarray:
        return output.T  # one row per cell, as the grid

    def _classes_given(self, output_shape: list) -> int | None:
        rows = output_shape[1]
        return rows - BOX_ROWS if isinstance(rows, int) else None

    def _decode(self, cells: np.ndarray, grid: np.ndarray, strides: np.ndarray):
        return decode(cells.T, grid, strides)
