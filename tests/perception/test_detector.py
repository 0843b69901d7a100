"""The detectors: YOLOX and YOLO11 decoding on hand-made rows, model loading with a free input size, and detection
on real KITTI images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import onnx
import pytest

from neoslam.config.perception import DetectionPass, DetectorConfig
from neoslam.errors import ConfigError, InputError
from neoslam.evaluation.detection import box_iou
from neoslam.perception.detection import COCO_CLASSES, Detection
from neoslam.perception.detector import make_detector
from neoslam.perception.grid_model import make_grid
from neoslam.perception.onnx_session import free_input_size
from neoslam.perception.yolo11 import decode as decode_yolo11
from neoslam.perception.yolox import decode as decode_yolox

CAR = COCO_CLASSES.index("car")
TRUCK = COCO_CLASSES.index("truck")


def _cars(detections: list[Detection]) -> int:
    return sum(d.label == "car" for d in detections)


# --- grids and decoding ------------------------------------------------------------------------------------------


def test_make_grid_of_a_rectangle_has_the_model_row_order() -> None:
    grid, strides = make_grid(64, 32)
    assert len(grid) == 8 * 4 + 4 * 2 + 2 * 1 and strides.shape == (len(grid), 1)
    assert strides[0, 0] == 8 and strides[32, 0] == 16 and strides[-1, 0] == 32
    np.testing.assert_array_equal(grid[1], [1, 0])  # row-major: x first
    np.testing.assert_array_equal(grid[8], [0, 1])
    np.testing.assert_array_equal(grid[-1], [1, 0])
    square, _ = make_grid(416, 416)
    assert len(square) == 3549  # YOLOX-Nano's exported output


def test_yolox_decode_of_a_hand_made_row() -> None:
    grid, strides = make_grid(416, 416)
    rows = np.zeros((len(grid), 85), dtype=np.float32)
    row = 52 * 52 + 26 * 3 + 5  # stride 16, cell gx = 5, gy = 3
    rows[row, :4] = [0.5, 0.25, np.log(2.0), np.log(4.0)]
    rows[row, 4] = 0.8
    rows[row, 5 + CAR] = 0.9
    rows[row, 5 + TRUCK] = 0.5  # lower, so the row is a car
    boxes, scores, class_ids = decode_yolox(rows, grid, strides)
    # centre ((0.5 + 5) * 16, (0.25 + 3) * 16) = (88, 52); size (2 * 16, 4 * 16) = (32, 64)
    np.testing.assert_allclose(boxes[row], [72, 20, 104, 84], atol=1e-4)
    assert scores[row] == pytest.approx(0.72) and class_ids[row] == CAR and scores[0] == 0


def test_yolo11_decode_of_a_hand_made_cell() -> None:
    grid, strides = make_grid(64, 32)
    output = np.zeros((84, len(grid)), dtype=np.float32)
    cell = 32 + 4 * 1 + 2  # stride 16, gx = 2, gy = 1: anchor (2.5, 1.5) cells = (40, 24) px
    output[:4, cell] = [1.0, 0.5, 2.0, 1.0]  # left, top, right, bottom, in cells
    output[4 + TRUCK, cell] = 0.7
    output[4 + CAR, cell] = 0.6
    boxes, scores, class_ids = decode_yolo11(output, grid, strides)
    np.testing.assert_allclose(boxes[cell], [24, 16, 72, 40], atol=1e-4)
    assert scores[cell] == pytest.approx(0.7) and class_ids[cell] == TRUCK


# --- model loading -----------------------------------------------------------------------------------------------


def test_free_input_size_keeps_the_weights(yolox_model: Path) -> None:
    model = onnx.load(str(yolox_model))
    weights = {init.name: init.raw_data for init in model.graph.initializer}
    freed = free_input_size(model)
    dims = freed.graph.input[0].type.tensor_type.shape.dim
    assert [d.dim_value for d in dims[:2]] == [1, 3] and [d.dim_param for d in dims[2:]] == ["height", "width"]
    assert {init.name: init.raw_data for init in freed.graph.initializer} == weights


def test_missing_model_is_an_input_error_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "yolox_nano.onnx"
    with pytest.raises(InputError, match="YOLOX-ONNX-TFLite-Sample") as raised:
        make_detector(DetectorConfig(model=missing))
    assert raised.value.path == missing and str(missing) in str(raised.value)


def test_yolo11_missing_model_says_it_is_an_option(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="AGPL-3.0"):
        make_detector(DetectorConfig(source="yolo11", model=tmp_path / "yolo11n.onnx"))


def test_unreadable_model_is_an_input_error(tmp_path: Path) -> None:
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(b"not a model")
    with pytest.raises(InputError, match="ONNX") as raised:
        make_detector(DetectorConfig(model=broken))
    assert raised.value.path == broken


def test_unknown_class_is_a_config_error(yolox_model: Path) -> None:
    with pytest.raises(ConfigError, match="motorcycle"):
        make_detector(DetectorConfig(model=yolox_model, classes=["car", "motorcycle"]))


def test_a_file_source_has_no_model() -> None:
    with pytest.raises(ConfigError, match="--detections"):
        make_detector(DetectorConfig(source="file"))


def test_labels_that_do_not_match_the_model_are_an_input_error(yolox_model: Path, tmp_path: Path) -> None:
    labels = tmp_path / "labels.txt"
    labels.write_text("car\ntruck\n")
    with pytest.raises(InputError, match="2 class names"):
        make_detector(DetectorConfig(model=yolox_model, labels_file=labels, classes=["car"]))


# --- real images -------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def object_pair_left(shared_data: Path) -> np.ndarray:
    return cv2.imread(str(shared_data / "kitti_object_pair" / "left.png"), cv2.IMREAD_COLOR)


@pytest.fixture(scope="module")
def street_frame(shared_data: Path) -> np.ndarray:
    """Frame 40 of kitti_06_51: a row of parked cars on the left, cars and a truck down the road."""
    path = shared_data / "kitti_06_51" / "sequences" / "06" / "image_0" / "000040.png"
    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)


def test_parked_cars_of_the_object_pair(yolox_detector, object_pair_left: np.ndarray) -> None:
    detections = yolox_detector.detect(0, object_pair_left)
    assert _cars(detections) >= 7
    height, width = object_pair_left.shape[:2]
    for d in detections:
        assert d.label in {"car", "truck", "bicycle", "person"}
        assert 0.35 <= d.score <= 1
        x1, y1, x2, y2 = d.box
        assert 0 <= x1 < x2 <= width and 0 <= y1 < y2 <= height and y2 - y1 >= 10
    assert [d.score for d in detections] == sorted((d.score for d in detections), reverse=True)


def test_the_whole_frame_at_its_own_size_finds_more_than_at_416(
    yolox_detector, yolox_small_detector, street_frame: np.ndarray
) -> None:
    # At 416 px wide YOLOX-Nano finds none of frame 40's cars; at the frame's own resolution it finds the nearer ones.
    assert _cars(yolox_detector.detect(40, street_frame)) >= _cars(yolox_small_detector.detect(40, street_frame)) + 2


def test_grey_image_is_replicated_to_bgr(yolox_model: Path, street_frame: np.ndarray) -> None:
    plain = make_detector(DetectorConfig(model=yolox_model, contrast_clip=0))
    bgr = cv2.cvtColor(street_frame, cv2.COLOR_GRAY2BGR)
    assert plain.detect(0, street_frame) == plain.detect(0, bgr)


def test_a_grey_image_is_equalised_as_it_is(yolox_model: Path, street_frame: np.ndarray) -> None:
    # Equalised in grey, then replicated: the same as giving the network the equalised grey image with contrast off.
    detector = make_detector(DetectorConfig(model=yolox_model))
    plain = make_detector(DetectorConfig(model=yolox_model, contrast_clip=0))
    equalised = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(street_frame)
    assert detector.detect(0, street_frame) == plain.detect(0, equalised)
    assert detector.detect(0, street_frame) != plain.detect(0, street_frame)


def test_detections_are_deterministic(yolox_detector, object_pair_left: np.ndarray) -> None:
    assert yolox_detector.detect(0, object_pair_left) == yolox_detector.detect(0, object_pair_left)


def test_an_enlarged_road_band_finds_distant_cars(yolox_model: Path, street_frame: np.ndarray) -> None:
    whole = make_detector(DetectorConfig(model=yolox_model, passes=[DetectionPass()]))
    band = DetectionPass(rows=(0.32, 0.78), scale=1.5)
    both = make_detector(DetectorConfig(model=yolox_model, passes=[DetectionPass(), band]))
    found, more = whole.detect(40, street_frame), both.detect(40, street_frame)
    assert _cars(more) > _cars(found)
    assert min(d.box[3] - d.box[1] for d in more) < min(d.box[3] - d.box[1] for d in found)  # smaller, farther


def test_only_configured_classes_are_kept(yolox_model: Path, object_pair_left: np.ndarray) -> None:
    detector = make_detector(DetectorConfig(model=yolox_model, classes=["person"]))
    assert all(d.label == "person" for d in detector.detect(0, object_pair_left))


def test_yolo11_finds_the_parked_cars(yolo11_model: Path, object_pair_left: np.ndarray) -> None:
    detector = make_detector(DetectorConfig(source="yolo11", model=yolo11_model))
    detections = detector.detect(0, object_pair_left)
    assert _cars(detections) >= 7
    yolox = make_detector(DetectorConfig(model=yolo11_model.parents[1] / "yolox_nano_coco" / "yolox_nano.onnx"))
    # Where YOLOX-Nano is sure of a car, YOLO11n has a box on it too (the decodings agree).
    sure = np.array([d.box for d in yolox.detect(0, object_pair_left) if d.score > 0.7])
    assert len(sure) >= 3
    assert np.all(box_iou(sure, np.array([d.box for d in detections])).max(axis=1) > 0.7)
