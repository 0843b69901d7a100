"""YOLOX detector: letterbox, grid, decode, NMS and tiles on synthetic arrays; detection on real KITTI images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam.errors import ConfigError, InputError
from neoslam.perception.config import DetectorConfig
from neoslam.perception.detector import (
    COCO_CLASSES,
    PAD_VALUE,
    Detection,
    YoloxDetector,
    centred_tile_origins,
    decode,
    letterbox,
    load_class_names,
    make_grid,
    nms,
    tile_origins,
)

CAR = COCO_CLASSES.index("car")


def _cars(detections: list[Detection]) -> int:
    return sum(d.label == "car" for d in detections)


# --- letterbox ---------------------------------------------------------------------------------------------------


def test_letterbox_scales_to_the_top_left_and_pads_with_114() -> None:
    image = np.full((100, 200, 3), (10, 20, 30), dtype=np.uint8)
    blob, scale = letterbox(image, 64)
    assert blob.shape == (1, 3, 64, 64) and blob.dtype == np.float32
    assert scale == pytest.approx(64 / 200)
    # 100 x 0.32 = 32 rows of image, then padding; channels stay in BGR order, 0-255, not normalised.
    assert np.all(blob[0, :, :32, :] == np.array([10, 20, 30], dtype=np.float32)[:, None, None])
    assert np.all(blob[0, :, 32:, :] == PAD_VALUE)


def test_letterbox_of_a_tall_image_pads_on_the_right() -> None:
    blob, scale = letterbox(np.zeros((128, 32, 3), dtype=np.uint8), 64)
    assert scale == pytest.approx(0.5)
    assert np.all(blob[0, :, :, :16] == 0) and np.all(blob[0, :, :, 16:] == PAD_VALUE)


# --- grid and decode ---------------------------------------------------------------------------------------------


def test_make_grid_has_the_model_row_order() -> None:
    grid, strides = make_grid(416)
    assert grid.shape == (3549, 2) and strides.shape == (3549, 1)
    assert strides[0, 0] == 8 and strides[52 * 52, 0] == 16 and strides[-1, 0] == 32
    np.testing.assert_array_equal(grid[1], [1, 0])  # row-major: x first
    np.testing.assert_array_equal(grid[52], [0, 1])
    np.testing.assert_array_equal(grid[-1], [12, 12])


def test_decode_of_a_hand_made_row() -> None:
    grid, strides = make_grid(416)
    rows = np.zeros((len(grid), 85), dtype=np.float32)
    row = 52 * 52 + 26 * 3 + 5  # stride 16, cell gx = 5, gy = 3
    rows[row, :4] = [0.5, 0.25, np.log(2.0), np.log(4.0)]
    rows[row, 4] = 0.8
    rows[row, 5 + CAR] = 0.9
    rows[row, 5 + 7] = 0.5  # truck: lower, so the row is a car
    boxes, scores, class_ids = decode(rows, grid, strides)
    # centre ((0.5 + 5) * 16, (0.25 + 3) * 16) = (88, 52); size (2 * 16, 4 * 16) = (32, 64)
    np.testing.assert_allclose(boxes[row], [72, 20, 104, 84], atol=1e-4)
    assert scores[row] == pytest.approx(0.72)
    assert class_ids[row] == CAR
    assert scores[0] == 0


# --- nms and tiles -----------------------------------------------------------------------------------------------


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


def test_tile_origins_span_the_side_with_the_overlap() -> None:
    origins = tile_origins(1242, 375, 0.2)
    assert origins[0] == 0 and origins[-1] == 1242 - 375
    assert all(b - a <= 375 * 0.8 for a, b in zip(origins, origins[1:], strict=False))
    assert tile_origins(375, 375, 0.2) == []


# --- Detection and class names -----------------------------------------------------------------------------------


def test_detection_is_frozen_with_a_read_only_box() -> None:
    detection = Detection("car", 0.5, [1, 2, 3, 4])
    assert detection.box.dtype == np.float64 and not detection.box.flags.writeable
    assert detection == Detection("car", 0.5, np.array([1.0, 2.0, 3.0, 4.0]))
    assert detection != Detection("car", 0.5, [1, 2, 3, 5])
    with pytest.raises(AttributeError):
        detection.label = "truck"  # type: ignore[misc]


def test_class_names_fall_back_to_coco(tmp_path: Path) -> None:
    assert load_class_names(tmp_path / "model.onnx", None) == COCO_CLASSES
    (tmp_path / "coco_classes.txt").write_text("a\nb\n\n")
    assert load_class_names(tmp_path / "model.onnx", None) == ("a", "b")
    (tmp_path / "mine.txt").write_text("x\n")
    assert load_class_names(tmp_path / "model.onnx", tmp_path / "mine.txt") == ("x",)
    with pytest.raises(InputError, match="missing.txt"):
        load_class_names(tmp_path / "model.onnx", tmp_path / "missing.txt")


def test_shared_class_names_match_the_built_in_ones(yolox_model: Path) -> None:
    assert load_class_names(yolox_model, None) == COCO_CLASSES


# --- model loading -----------------------------------------------------------------------------------------------


def test_missing_model_is_an_input_error_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "yolox_nano.onnx"
    with pytest.raises(InputError, match="YOLOX-ONNX-TFLite-Sample") as raised:
        YoloxDetector(DetectorConfig(model=missing))
    assert raised.value.path == missing and str(missing) in str(raised.value)


def test_unreadable_model_is_an_input_error(tmp_path: Path) -> None:
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(b"not a model")
    with pytest.raises(InputError, match="cannot load") as raised:
        YoloxDetector(DetectorConfig(model=broken))
    assert raised.value.path == broken


def test_unknown_class_is_a_config_error(yolox_model: Path) -> None:
    with pytest.raises(ConfigError, match="motorcycle"):
        YoloxDetector(DetectorConfig(model=yolox_model, classes=["car", "motorcycle"]))


def test_wrong_input_size_is_a_config_error(yolox_model: Path) -> None:
    with pytest.raises(ConfigError, match="input_size"):
        YoloxDetector(DetectorConfig(model=yolox_model, input_size=640))


def test_labels_that_do_not_match_the_model_are_an_input_error(yolox_model: Path, tmp_path: Path) -> None:
    labels = tmp_path / "labels.txt"
    labels.write_text("car\ntruck\n")
    with pytest.raises(InputError, match="2 class names"):
        YoloxDetector(DetectorConfig(model=yolox_model, labels_file=labels, classes=["car"]))


# --- real images -------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def object_pair_left(shared_data: Path) -> np.ndarray:
    return cv2.imread(str(shared_data / "kitti_object_pair" / "left.png"), cv2.IMREAD_COLOR)


@pytest.fixture(scope="module")
def kitti_mini_frame(shared_data: Path) -> np.ndarray:
    path = shared_data / "kitti_mini" / "sequences" / "06" / "image_0" / "000000.png"
    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)


def test_parked_cars_of_the_object_pair(yolox_detector: YoloxDetector, object_pair_left: np.ndarray) -> None:
    detections = yolox_detector.detect(0, object_pair_left)
    assert _cars(detections) >= 5
    height, width = object_pair_left.shape[:2]
    for d in detections:
        assert d.label in {"car", "truck", "bicycle", "person"}
        assert 0.35 <= d.score <= 1
        x1, y1, x2, y2 = d.box
        assert 0 <= x1 < x2 <= width and 0 <= y1 < y2 <= height and y2 - y1 >= 10
    assert [d.score for d in detections] == sorted((d.score for d in detections), reverse=True)


def test_grey_kitti_frame_has_a_car(yolox_detector: YoloxDetector, kitti_mini_frame: np.ndarray) -> None:
    assert kitti_mini_frame.ndim == 2
    assert _cars(yolox_detector.detect(0, kitti_mini_frame)) >= 1


def test_grey_image_is_replicated_to_bgr(yolox_detector: YoloxDetector, kitti_mini_frame: np.ndarray) -> None:
    bgr = cv2.cvtColor(kitti_mini_frame, cv2.COLOR_GRAY2BGR)
    assert yolox_detector.detect(0, kitti_mini_frame) == yolox_detector.detect(0, bgr)


def test_detections_are_deterministic(yolox_tiling_detector: YoloxDetector, object_pair_left: np.ndarray) -> None:
    assert yolox_tiling_detector.detect(0, object_pair_left) == yolox_tiling_detector.detect(0, object_pair_left)


@pytest.mark.parametrize("image_name", ["object_pair_left", "kitti_mini_frame"])
def test_tiling_finds_at_least_as_many_cars(
    yolox_detector: YoloxDetector, yolox_tiling_detector: YoloxDetector, image_name: str, request
) -> None:
    image = request.getfixturevalue(image_name)
    assert _cars(yolox_tiling_detector.detect(0, image)) >= _cars(yolox_detector.detect(0, image))


def test_central_tiles_cover_the_middle_of_the_frame() -> None:
    assert centred_tile_origins(1226, 370, 1.0, 0.2) == tile_origins(1226, 370, 0.2)
    first, second = centred_tile_origins(1226, 370, 0.5, 0.2)
    assert (first, second + 370) == (306, 306 + 613)  # the band of 613 px, centred
    assert centred_tile_origins(1226, 370, 0.1, 0.2) == [428]  # never narrower than one tile
    assert centred_tile_origins(370, 370, 0.5, 0.2) == [0]


def test_only_configured_classes_are_kept(yolox_model: Path, object_pair_left: np.ndarray) -> None:
    detector = YoloxDetector(DetectorConfig(model=yolox_model, classes=["person"]))
    assert all(d.label == "person" for d in detector.detect(0, object_pair_left))


def test_malformed_images_are_refused(yolox_detector: YoloxDetector) -> None:
    with pytest.raises(ValueError, match="uint8"):
        yolox_detector.detect(0, np.zeros((10, 10), dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        yolox_detector.detect(0, np.zeros((10, 10, 4), dtype=np.uint8))


def test_boxes_touching_a_cut_inside_the_image_are_found() -> None:
    from neoslam.perception.detector import _touches_inner_cut

    boxes = np.array([[300, 10, 350, 50], [301, 10, 350, 50], [500, 10, 674, 50], [500, 10, 600, 374]], dtype=float)
    # tile x 300..675 of a 1242x375 image: its left and right edges are cuts; top and bottom are the image's own.
    np.testing.assert_array_equal(_touches_inner_cut(boxes, (300, 0), 375, (1242, 375)), [True, True, True, False])
