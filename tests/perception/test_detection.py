"""What every detector shares: windows, network sizes, letterbox, NMS, cut boxes, class names, the record."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from neoslam.config.perception import DetectionPass, DetectorConfig
from neoslam.errors import InputError
from neoslam.perception.detection import (
    COCO_CLASSES,
    PAD_VALUE,
    Detection,
    Window,
    equalise_contrast,
    letterbox,
    load_class_names,
    network_size,
    nms,
    to_bgr,
    touches_inner_cut,
)
from neoslam.perception.detector import windows_of

# --- windows and network sizes -----------------------------------------------------------------------------------


def test_window_of_shares_of_the_image() -> None:
    window = Window.of((1226, 370), rows=(0.32, 0.78), columns=(0.0, 1.0), scale=1.5)
    assert (window.x0, window.y0, window.x1, window.y1, window.scale) == (0, 118, 1226, 289, 1.5)
    assert window.inner_edges((1226, 370)) == (False, True, False, True)
    assert window.crop(np.zeros((370, 1226))).shape == (171, 1226)


def test_network_size_rounds_up_to_the_stride() -> None:
    assert network_size(1226, 370, 1.0) == (1248, 384)
    assert network_size(1226, 171, 1.5) == (1856, 288)
    assert network_size(1226, 370, 416 / 1226) == (416, 128)
    assert network_size(3, 3, 0.1) == (32, 32)  # never empty


def test_windows_of_the_config() -> None:
    config = DetectorConfig(passes=[DetectionPass(), DetectionPass(rows=(0.5, 1.0), columns=(0.25, 0.75), scale=2)])
    whole, part = windows_of(config, (1200, 400))
    assert (whole.x0, whole.y0, whole.x1, whole.y1) == (0, 0, 1200, 400)
    assert (part.x0, part.y0, part.x1, part.y1, part.scale) == (300, 200, 900, 400, 2)


@pytest.mark.parametrize(
    "settings",
    [{"rows": (0.5, 0.5)}, {"rows": (0.6, 0.4)}, {"columns": (-0.1, 1.0)}, {"columns": (0.0, 1.1)}, {"scale": 0}],
)
def test_empty_or_reversed_passes_are_refused(settings: dict) -> None:
    with pytest.raises(ValidationError):
        DetectionPass(**settings)


def test_a_detector_needs_a_pass() -> None:
    with pytest.raises(ValidationError):
        DetectorConfig(passes=[])


def test_the_default_model_follows_neoslam_data(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("NEOSLAM_DATA", str(tmp_path))
    assert DetectorConfig().model_path() == tmp_path / "models" / "yolox_nano_coco" / "yolox_nano.onnx"
    assert DetectorConfig(source="yolo11").model_path() == tmp_path / "models" / "yolo11n_coco" / "yolo11n_coco.onnx"
    assert DetectorConfig(model=Path("mine.onnx")).model_path() == Path("mine.onnx")


# --- letterbox ---------------------------------------------------------------------------------------------------


def test_letterbox_scales_to_the_top_left_and_pads_with_114() -> None:
    image = np.full((100, 200, 3), (10, 20, 30), dtype=np.uint8)
    padded, scale = letterbox(image, (64, 64))
    assert padded.shape == (64, 64, 3) and padded.dtype == np.uint8
    assert scale == pytest.approx(64 / 200)
    assert np.all(padded[:32] == (10, 20, 30)) and np.all(padded[32:] == PAD_VALUE)


def test_letterbox_at_a_given_scale_into_a_rectangle() -> None:
    padded, scale = letterbox(np.zeros((171, 1226, 3), dtype=np.uint8), (1856, 288), 1.5)
    assert scale == 1.5 and padded.shape == (288, 1856, 3)
    assert np.all(padded[:256, :1839] == 0)  # 171 x 1.5 = 256.5 rows, 1226 x 1.5 = 1839 columns of image
    assert np.all(padded[257:] == PAD_VALUE) and np.all(padded[:, 1840:] == PAD_VALUE)


# --- nms and cut boxes -------------------------------------------------------------------------------------------


def test_nms_is_class_wise() -> None:
    boxes = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [0, 0, 10, 10], [50, 50, 60, 60]], dtype=float)
    scores = np.array([0.9, 0.8, 0.7, 0.6])
    class_ids = np.array([2, 2, 7, 2])
    # box 1 overlaps box 0 (IoU 0.82, same class): suppressed; box 2 is another class: kept.
    np.testing.assert_array_equal(nms(boxes, scores, class_ids, 0.45), [0, 2, 3])


def test_nms_keeps_the_first_of_equal_scores() -> None:
    boxes = np.array([[0, 0, 10, 10], [0, 0, 10, 10]], dtype=float)
    np.testing.assert_array_equal(nms(boxes, np.array([0.5, 0.5]), np.array([0, 0]), 0.45), [0])


def test_nms_of_nothing() -> None:
    assert nms(np.zeros((0, 4)), np.zeros(0), np.zeros(0, dtype=int), 0.45).size == 0


def test_boxes_touching_a_cut_inside_the_image() -> None:
    boxes = np.array([[300, 10, 350, 50], [301, 10, 350, 50], [500, 10, 674, 50], [500, 10, 600, 374]], dtype=float)
    # window x 300..675 of a 1242x375 image: its left and right edges are cuts; top and bottom are the image's own.
    window = Window(300, 0, 675, 375, 1.0)
    np.testing.assert_array_equal(touches_inner_cut(boxes, window, (1242, 375), 2.0), [True, True, True, False])
    band = Window(0, 120, 1242, 290, 1.5)  # a road band: its top and bottom cut, its sides are the image's
    on_band = np.array([[0, 150, 40, 200], [100, 200, 200, 289], [100, 121, 200, 200]], dtype=float)
    np.testing.assert_array_equal(touches_inner_cut(on_band, band, (1242, 375), 2.0), [False, True, True])


# --- Detection, images and class names ---------------------------------------------------------------------------


def test_detection_is_frozen_with_a_read_only_box() -> None:
    detection = Detection("car", 0.5, [1, 2, 3, 4])
    assert detection.box.dtype == np.float64 and not detection.box.flags.writeable
    assert detection == Detection("car", 0.5, np.array([1.0, 2.0, 3.0, 4.0]))
    assert detection != Detection("car", 0.5, [1, 2, 3, 5])
    with pytest.raises(AttributeError):
        detection.label = "truck"  # type: ignore[misc]


def test_grey_images_become_three_channels_and_others_are_refused() -> None:
    assert to_bgr(np.zeros((4, 5), np.uint8)).shape == (4, 5, 3)
    assert to_bgr(np.zeros((4, 5, 1), np.uint8)).shape == (4, 5, 3)
    with pytest.raises(ValueError, match="uint8"):
        to_bgr(np.zeros((10, 10), dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        to_bgr(np.zeros((10, 10, 4), dtype=np.uint8))


def test_contrast_is_equalised_on_grey_itself_and_on_a_colour_image_s_lightness() -> None:
    rng = np.random.default_rng(3)
    grey = (rng.random((64, 96)) * 60 + 40).astype(np.uint8)  # dull: a narrow band of grey levels
    equalised = equalise_contrast(grey, 3.0, 4)
    assert equalised.shape == grey.shape and np.ptp(equalised) > np.ptp(grey)
    assert np.array_equal(equalised, cv2.createCLAHE(clipLimit=3.0, tileGridSize=(4, 4)).apply(grey))
    colour = equalise_contrast(to_bgr(grey), 3.0, 4)
    assert colour.shape == (64, 96, 3) and np.ptp(colour) > np.ptp(grey)
    assert equalise_contrast(grey, 0.0, 4) is grey


def test_class_names_fall_back_to_coco(tmp_path: Path) -> None:
    name = "coco_classes.txt"
    assert load_class_names(tmp_path / "model.onnx", None, name) == COCO_CLASSES
    (tmp_path / name).write_text("a\nb\n\n")
    assert load_class_names(tmp_path / "model.onnx", None, name) == ("a", "b")
    (tmp_path / "mine.txt").write_text("x\n")
    assert load_class_names(tmp_path / "model.onnx", tmp_path / "mine.txt", name) == ("x",)
    with pytest.raises(InputError, match="missing.txt"):
        load_class_names(tmp_path / "model.onnx", tmp_path / "missing.txt", name)


def test_a_window_that_covers_no_pixel_is_a_config_error() -> None:
    from neoslam.errors import ConfigError

    config = DetectorConfig(passes=[DetectionPass(), DetectionPass(rows=(0.5, 0.501))])
    with pytest.raises(ConfigError, match=r"passes\[1\]: covers no pixel of a 100x100 image"):
        windows_of(config, (100, 100))
