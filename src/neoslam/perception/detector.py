"""Object detection (paper 3.1: "objects are detected with Yolo"): a network run over configured windows of the
frame, whose boxes are merged into one list.

KITTI's cars are small: a parked car 40 m away is about 25 px high in a 1226x370 frame, and a network that sees the
frame shrunk to 416 px misses most of them. So the detector runs the network over windows (`perception.detector.
passes`): the whole frame at its own resolution, and optionally the horizontal band that holds the road enlarged.
Boxes of all windows go through class-wise NMS, then across classes, so that one object keeps one label.

One model per module (`yolox.py`, `yolo11.py`), each turning a window into boxes; `make_detector` picks the one the
config names. A new model adds a module and a line here, not a change to the pipeline.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from neoslam.config.perception import DetectorConfig
from neoslam.errors import ConfigError
from neoslam.perception.detection import (
    Detection,
    Window,
    equalise_contrast,
    nms,
    plain_image,
    to_bgr,
    touches_inner_cut,
)

__all__ = ["DetectionModel", "WindowedDetector", "make_detector", "windows_of"]


class DetectionModel(Protocol):
    """A network that turns an image window into boxes (window px), scores and class ids of every cell."""

    class_names: tuple[str, ...]

    def infer(self, window_bgr: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


def windows_of(config: DetectorConfig, image_size: tuple[int, int]) -> list[Window]:
    """The windows the configured passes make of an image of (width, height) px."""
    windows = [Window.of(image_size, tuple(p.rows), tuple(p.columns), p.scale) for p in config.passes]
    for index, window in enumerate(windows):
        if window.x1 <= window.x0 or window.y1 <= window.y0:
            raise ConfigError(
                f"perception.detector.passes[{index}]: covers no pixel of a {image_size[0]}x{image_size[1]} image"
            )
    return windows


class WindowedDetector:
    """A detection model run over the configured windows; its detections merged, best score first."""

    def __init__(self, model: DetectionModel, config: DetectorConfig) -> None:
        self.model = model
        self.config = config
        self.class_names = model.class_names
        unknown = [name for name in config.classes if name not in self.class_names]
        if unknown:
            raise ConfigError(
                f"perception.detector.classes: {unknown} are not classes of the model (it has e.g. "
                f"{list(self.class_names[:8])}...)"
            )
        self._kept_ids = np.array([self.class_names.index(name) for name in config.classes])

    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]:
        """Detections of the kept classes in one image (grey or BGR), best score first.

        `frame_index` is not used by the network; it is part of the `ObjectDetector` interface.
        """
        bgr = to_bgr(equalise_contrast(plain_image(image), self.config.contrast_clip, self.config.contrast_tiles))
        size = (bgr.shape[1], bgr.shape[0])
        parts = [self._detect_window(bgr, window, size) for window in windows_of(self.config, size)]
        boxes, scores, class_ids = (np.concatenate(p) for p in zip(*parts, strict=True))
        boxes[:, 0::2] = np.clip(boxes[:, 0::2], 0, size[0])
        boxes[:, 1::2] = np.clip(boxes[:, 1::2], 0, size[1])
        tall = boxes[:, 3] - boxes[:, 1] >= self.config.min_box_height
        boxes, scores, class_ids = boxes[tall], scores[tall], class_ids[tall]
        kept = nms(boxes, scores, class_ids, self.config.nms_iou)
        one_class = np.zeros(len(kept), dtype=class_ids.dtype)  # now across classes, for one label per object
        kept = kept[nms(boxes[kept], scores[kept], one_class, self.config.duplicate_iou)]
        detections = [Detection(self.class_names[class_ids[i]], scores[i], boxes[i]) for i in kept]
        return sorted(detections, key=lambda d: (-d.score, d.box[0], d.box[1], d.label))

    def _detect_window(
        self, bgr: np.ndarray, window: Window, image_size: tuple[int, int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes (image px), scores and class ids of the kept classes above the threshold in one window; boxes the
        window cuts inside the image are left to the windows that see them whole."""
        boxes, scores, class_ids = self.model.infer(window.crop(bgr), window.scale)
        keep = (scores >= self.config.score_threshold) & np.isin(class_ids, self._kept_ids)
        boxes = boxes[keep] + (window.x0, window.y0, window.x0, window.y0)
        whole = ~touches_inner_cut(boxes, window, image_size, self.config.cut_margin)
        return boxes[whole], scores[keep][whole], class_ids[keep][whole]


def make_detector(config: DetectorConfig) -> WindowedDetector:
    """The detector of the configured model (`perception.detector.source`: yolox or yolo11)."""
    if config.source == "yolox":
        from neoslam.perception.yolox import YoloxModel

        return WindowedDetector(YoloxModel(config), config)
    if config.source == "yolo11":
        from neoslam.perception.yolo11 import Yolo11Model

        return WindowedDetector(Yolo11Model(config), config)
    raise ConfigError(
        f"perception.detector.source {config.source!r} has no model: give the detections with --detections"
    )
