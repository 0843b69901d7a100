"""Fixtures of the perception tests: the YOLOX-Nano model and detectors built from it."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.perception.config import DetectorConfig


@pytest.fixture(scope="session")
def yolox_model(shared_data: Path) -> Path:
    """Path of the shared YOLOX-Nano ONNX model."""
    return shared_data / "models" / "yolox_nano_coco" / "yolox_nano.onnx"


@pytest.fixture(scope="session")
def yolox_detector(yolox_model: Path):
    """A YoloxDetector on the whole frame only (default config otherwise)."""
    from neoslam.perception.detector import YoloxDetector

    return YoloxDetector(DetectorConfig(model=yolox_model, tiling=False))


@pytest.fixture(scope="session")
def yolox_tiling_detector(yolox_model: Path):
    """A YoloxDetector that also runs square tiles across the frame."""
    from neoslam.perception.detector import YoloxDetector

    return YoloxDetector(DetectorConfig(model=yolox_model, tiling=True))
