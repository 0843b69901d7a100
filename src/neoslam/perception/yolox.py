"""YOLOX (COCO, ONNX), the default detector's model (Apache-2.0 weights).

Formats (`shared/data/models/README.md`): input BGR 0-255, not normalised, letterboxed at the top left with 114;
one output row per grid cell of strides 8, 16 and 32 (finest first, row-major), columns (dx, dy, log w, log h,
objectness, class scores).
"""

from __future__ import annotations

import numpy as np

from neoslam.perception.grid_model import GridModel

__all__ = ["YoloxModel", "decode"]

BOX_COLUMNS = 4  # dx, dy, log w, log h
OBJECTNESS_COLUMN = 4
FIRST_CLASS_COLUMN = 5
MAX_LOG_SIZE = 20.0  # exp of a wild size logit would overflow
MODEL_HELP = (
    "the default is models/yolox_nano_coco/yolox_nano.onnx under $NEOSLAM_DATA (unset: ../shared/data, from the "
    "folder you run in): set NEOSLAM_DATA to the data folder, or perception.detector.model to the file; "
    "yolox_nano.onnx comes from the GitHub repository Kazuhito00/YOLOX-ONNX-TFLite-Sample, folder model/; "
    "or run another detector and pass its output with --detections FILE"
)


def decode(rows: np.ndarray, grid: np.ndarray, strides: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw output rows (N, 5 + classes) -> boxes (N, 4) x1, y1, x2, y2 in input px, scores (N,), class ids (N,).

    Each row keeps its best class only (score = objectness x class score), so that one object gives one label
    rather than, say, a car and a truck at the same place.
    """
    centres = (rows[:, :2] + grid) * strides
    sizes = np.exp(np.minimum(rows[:, 2:BOX_COLUMNS], MAX_LOG_SIZE)) * strides
    boxes = np.concatenate([centres - sizes / 2, centres + sizes / 2], axis=1)
    class_scores = rows[:, FIRST_CLASS_COLUMN:]
    class_ids = np.argmax(class_scores, axis=1)
    scores = rows[:, OBJECTNESS_COLUMN] * class_scores[np.arange(len(rows)), class_ids]
    return boxes, scores, class_ids


class YoloxModel(GridModel):
    """YOLOX: BGR 0-255 in, one row per cell out."""

    help_text = MODEL_HELP

    def _blob(self, padded_bgr: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(padded_bgr.transpose(2, 0, 1)[np.newaxis], dtype=np.float32)

    def _cells(self, output: np.ndarray) -> np.ndarray:
        return output

    def _classes_given(self, output_shape: list) -> int | None:
        columns = output_shape[-1]
        return columns - FIRST_CLASS_COLUMN if isinstance(columns, int) else None

    def _decode(self, cells: np.ndarray, grid: np.ndarray, strides: np.ndarray):
        return decode(cells, grid, strides)
