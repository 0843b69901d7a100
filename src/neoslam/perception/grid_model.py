"""What the YOLO-family models share: an ONNX network over a grid of cells of strides 8, 16 and 32, run on one
image window at a time. A model module (`yolox.py`, `yolo11.py`) says how its input is made and its output read."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neoslam.config.perception import DetectorConfig
from neoslam.errors import InputError
from neoslam.perception.detection import letterbox, load_class_names, network_size
from neoslam.perception.onnx_session import open_session

__all__ = ["STRIDES", "make_grid", "GridModel"]

STRIDES = (8, 16, 32)  # the heads, finest first: the order of the output cells
LABELS_FILE_NAME = "coco_classes.txt"  # looked for beside the model when no labels_file is configured


def make_grid(width: int, height: int, strides: tuple[int, ...] = STRIDES) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (N, 2) as (gx, gy) and the stride (N, 1) of each output cell, in the model's order, for an
    input of width x height px."""
    cells, cell_strides = [], []
    for stride in strides:
        gy, gx = np.mgrid[0 : height // stride, 0 : width // stride]  # row-major: x varies fastest
        cells.append(np.stack([gx.ravel(), gy.ravel()], axis=1))
        cell_strides.append(np.full((gx.size, 1), stride))
    return np.concatenate(cells).astype(np.float32), np.concatenate(cell_strides).astype(np.float32)


class GridModel:
    """A network that turns one image window into boxes (window px), scores and class ids of every cell.

    Subclasses give `help_text` (how to obtain the model), `session_entries` (onnxruntime settings), `_blob` (the
    network input of a letterboxed BGR window), `_cells` (the output as one row per cell), `_classes_given` (the
    number of classes an output shape holds) and `_decode`.
    """

    help_text = ""
    session_entries: dict[str, str] = {}

    def __init__(self, config: DetectorConfig) -> None:
        model = self.model_path = config.model_path()
        self.session = open_session(model, config.threads, self.help_text, self.session_entries, config.device)
        self.class_names = load_class_names(model, config.labels_file, LABELS_FILE_NAME)
        self._input_name = self.session.get_inputs()[0].name
        given = self._classes_given(self.session.get_outputs()[0].shape)
        if given is not None and given != len(self.class_names):
            where: Path = config.labels_file or model
            raise InputError(where, f"{len(self.class_names)} class names but the model gives {given} classes")
        self._grids: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def infer(self, window_bgr: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every cell's box in window px, score and class id, the window enlarged by `scale` for the network."""
        size = network_size(window_bgr.shape[1], window_bgr.shape[0], scale)
        padded, r = letterbox(window_bgr, size, scale)
        cells = self._cells(self.session.run(None, {self._input_name: self._blob(padded)})[0][0])
        if size not in self._grids:
            self._grids[size] = make_grid(*size)
        grid, strides = self._grids[size]
        if len(cells) != len(grid):
            raise InputError(self.model_path, f"gives {len(cells)} cells for a {size} input, expected {len(grid)}")
        boxes, scores, class_ids = self._decode(cells, grid, strides)
        return boxes.astype(np.float64) / r, scores.astype(np.float64), class_ids

    def _blob(self, padded_bgr: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _cells(self, output: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _classes_given(self, output_shape: list) -> int | None:
        raise NotImplementedError

    def _decode(self, cells: np.ndarray, grid: np.ndarray, strides: np.ndarray):
        raise NotImplementedError
