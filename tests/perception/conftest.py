"""Fixtures of the perception tests: the shared models and detectors built from them."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.config.perception import DetectionPass, DetectorConfig

SMALL_PASS = DetectionPass(scale=416 / 1242)  # the whole frame shrunk to YOLOX-Nano's exported 416 px


@pytest.fixture(scope="session")
def yolox_model(shared_data: Path) -> Path:
    """Path of the shared YOLOX-Nano ONNX model."""
    return shared_data / "models" / "yolox_nano_coco" / "yolox_nano.onnx"


@pytest.fixture(scope="session")
def yolo11_model(shared_data: Path) -> Path:
    """Path of the shared YOLO11n ONNX model (AGPL-3.0 weights: read from the shared data, never copied)."""
    return shared_data / "models" / "yolo11n_coco" / "yolo11n_coco.onnx"


@pytest.fixture(scope="session")
def yolox_detector(yolox_model: Path):
    """The default YOLOX detector (the whole frame at its own resolution)."""
    from neoslam.perception.detector import make_detector

    return make_detector(DetectorConfig(model=yolox_model))


@pytest.fixture(scope="session")
def yolox_small_detector(yolox_model: Path):
    """YOLOX on the whole frame shrunk to 416 px wide, as the model was exported."""
    from neoslam.perception.detector import make_detector

    return make_detector(DetectorConfig(model=yolox_model, passes=[SMALL_PASS]))
