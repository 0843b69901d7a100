"""ORB stereo triangulation of objects: synthetic stereo pairs with known depth, and the real KITTI object pair
checked against OpenCV's SGBM disparity inside the same boxes."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam.config import CameraConfig
from neoslam.config.perception import DetectorConfig, StereoObjectConfig
from neoslam.perception.detection import Detection
from neoslam.perception.detector import make_detector
from neoslam.perception.stereo import ObjectTriangulator, match_stereo_keypoints, triangulate

CAMERA = CameraConfig(fx=700.0, fy=700.0, cx=320.0, cy=120.0, width=640, height=240, baseline=0.5)
OBJECT_BOX = np.array([300.0, 80.0, 420.0, 180.0])
OBJECT_DISPARITY = 35.0  # 10 m
BACKGROUND_DISPARITY = 5.0  # 70 m
MIN_UNHIDDEN_SHARE = 0.25  # a box less visible than this holds too little of its car for SGBM's median


def _texture(shape: tuple[int, int], seed: int) -> np.ndarray:
    noise = np.random.default_rng(seed).uniform(0, 255, shape).astype(np.float32)
    return cv2.GaussianBlur(noise, (0, 0), 1.5)


def _shifted(image: np.ndarray, shift: float) -> np.ndarray:
    """The image moved left by a (sub-pixel) shift, as the right camera sees a fronto-parallel plane."""
    warp = np.array([[1.0, 0.0, -shift], [0.0, 1.0, 0.0]])
    return cv2.warpAffine(image, warp, (image.shape[1], image.shape[0]), flags=cv2.INTER_CUBIC)


def synthetic_pair(object_disparity: float = OBJECT_DISPARITY) -> tuple[np.ndarray, np.ndarray]:
    """A textured box-shaped plane at one depth in front of a textured background at another."""
    shape = (CAMERA.height, CAMERA.width)
    background, foreground = _texture(shape, 1), _texture(shape, 2)
    mask = np.zeros(shape, np.float32)
    x1, y1, x2, y2 = OBJECT_BOX.astype(int)
    mask[y1:y2, x1:x2] = 1.0
    left = mask * foreground + (1 - mask) * background
    right_mask = _shifted(mask, object_disparity) > 0.5
    right = np.where(right_mask, _shifted(foreground, object_disparity), _shifted(background, BACKGROUND_DISPARITY))
    return np.clip(left, 0, 255).astype(np.uint8), np.clip(right, 0, 255).astype(np.uint8)


def _car(box: np.ndarray) -> Detection:
    return Detection("car", 0.9, box.astype(np.float64))


def test_triangulate_inverts_the_projection() -> None:
    points = np.array([[1.0, -0.5, 10.0], [-2.0, 0.3, 25.0]])
    pixels = np.column_stack(
        [CAMERA.fx * points[:, 0] / points[:, 2] + CAMERA.cx, CAMERA.fy * points[:, 1] / points[:, 2] + CAMERA.cy]
    )
    disparity = CAMERA.fx * CAMERA.baseline / points[:, 2]
    np.testing.assert_allclose(triangulate(pixels, disparity, CAMERA), points, rtol=1e-12)


@pytest.mark.parametrize("disparity", [35.0, 20.4, 12.7])
def test_keypoint_disparities_are_sub_pixel(disparity: float) -> None:
    left, right = synthetic_pair(disparity)
    matches = match_stereo_keypoints(left, right, OBJECT_BOX, StereoObjectConfig())
    on_object = np.all((matches.left >= OBJECT_BOX[:2] + 3) & (matches.left <= OBJECT_BOX[2:] - 3), axis=1)
    assert on_object.sum() >= 20
    errors = np.abs(matches.disparity[on_object] - disparity)
    assert np.median(errors) < 0.15


def test_object_centre_depth_and_boxes() -> None:
    left, right = synthetic_pair()
    (observation,) = ObjectTriangulator(CAMERA, StereoObjectConfig()).observe(left, right, [_car(OBJECT_BOX)])
    depth = CAMERA.fx * CAMERA.baseline / OBJECT_DISPARITY
    assert observation.center_camera[2] == pytest.approx(depth, rel=0.01)
    # The centre sits near the box's middle ray (keypoints spread over the whole plane).
    middle = (OBJECT_BOX[:2] + OBJECT_BOX[2:]) / 2
    expected_xy = (middle - [CAMERA.cx, CAMERA.cy]) * depth / CAMERA.fx
    np.testing.assert_allclose(observation.center_camera[:2], expected_xy, atol=0.15)
    np.testing.assert_allclose(observation.box_right, OBJECT_BOX - [OBJECT_DISPARITY, 0, OBJECT_DISPARITY, 0], atol=0.5)
    assert observation.patch.shape == (16, 16) and observation.patch.dtype == np.uint8
    assert 0 < observation.depth_sigma < 0.05
    assert observation.label == "car" and observation.score == 0.9


def test_objects_out_of_range_untextured_or_cut_off_are_not_placed() -> None:
    left, right = synthetic_pair()
    near_only = StereoObjectConfig(max_depth=5.0)
    assert ObjectTriangulator(CAMERA, near_only).observe(left, right, [_car(OBJECT_BOX)]) == []
    flat = np.full_like(left, 128)
    assert ObjectTriangulator(CAMERA, StereoObjectConfig()).observe(flat, flat, [_car(OBJECT_BOX)]) == []
    at_border = np.array([0.0, 80.0, 120.0, 180.0])
    assert ObjectTriangulator(CAMERA, StereoObjectConfig()).observe(left, right, [_car(at_border)]) == []
    assert ObjectTriangulator(CAMERA, StereoObjectConfig()).observe(left, right, []) == []


def test_background_keypoints_in_the_box_do_not_move_the_centre() -> None:
    left, right = synthetic_pair()
    wider = OBJECT_BOX + np.array([-25.0, -20.0, 25.0, 20.0])  # a loose box: background all around the object
    (observation,) = ObjectTriangulator(CAMERA, StereoObjectConfig()).observe(left, right, [_car(wider)])
    assert observation.center_camera[2] == pytest.approx(CAMERA.fx * CAMERA.baseline / OBJECT_DISPARITY, rel=0.02)


def test_deterministic() -> None:
    left, right = synthetic_pair()
    triangulator = ObjectTriangulator(CAMERA, StereoObjectConfig())
    first, second = (triangulator.observe(left, right, [_car(OBJECT_BOX)]) for _ in range(2))
    np.testing.assert_array_equal(first[0].center_camera, second[0].center_camera)


def _object_pair_camera(folder: Path) -> CameraConfig:
    """P2 and P3 of the KITTI object calibration: the colour cameras of this pair."""
    rows = {
        line.split(":")[0]: np.array(line.split(":")[1].split(), float)
        for line in (folder / "calib.txt").read_text().splitlines()
        if ":" in line
    }
    p2, p3 = rows["P2"].reshape(3, 4), rows["P3"].reshape(3, 4)
    fx = p2[0, 0]
    return CameraConfig(
        fx=fx, fy=p2[1, 1], cx=p2[0, 2], cy=p2[1, 2], width=1242, height=375, baseline=(p2[0, 3] - p3[0, 3]) / fx
    )


# A near car seen obliquely spans a metre or more of depth; its "depth" is within about this of either estimate.
NEAR_CAR_EXTENT_M = 0.6
# Far away the two agree to what SGBM's sub-pixel disparity resolves on a box a few dozen px wide.
FAR_DISPARITY_PX = 0.5
DISPARITY_BIN_PX = 0.5  # of the histogram whose peak is a box's dominant surface


def _dominant(disparities: np.ndarray) -> float:
    """The disparity of the surface that fills most of a box: the median of the values in and beside the
    histogram's fullest bin (the box's edges hold road and background seen past the car, which a plain median
    of the box mixes in)."""
    bins = np.floor(disparities / DISPARITY_BIN_PX)
    values, counts = np.unique(bins, return_counts=True)
    peak = values[np.argmax(counts)]
    return float(np.median(disparities[np.abs(bins - peak) <= 1]))


def _sgbm_depths(
    left: np.ndarray, right: np.ndarray, camera: CameraConfig, boxes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Depth of the dominant SGBM disparity in each box, leaving out the part of the box that a nearer box (by its own
    SGBM median) covers, since there the disparity is the nearer car's; and the share of the box left."""
    sgbm = cv2.StereoSGBM_create(
        0, 128, 5, P1=8 * 25, P2=32 * 25, uniquenessRatio=10, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY
    )
    disparity = sgbm.compute(left, right).astype(np.float32) / 16
    valid = disparity > 0
    masks = []
    for x1, y1, x2, y2 in np.round(boxes).astype(int):
        mask = np.zeros(disparity.shape, bool)
        mask[y1:y2, x1:x2] = True
        masks.append(mask)
    whole = np.array([np.median(disparity[m & valid]) for m in masks])
    depths, shares = [], []
    for k, mask in enumerate(masks):
        visible = mask.copy()
        for j in np.flatnonzero(whole > whole[k]):
            visible &= ~masks[j]
        shares.append(visible.sum() / mask.sum())
        depths.append(camera.fx * camera.baseline / _dominant(disparity[visible & valid]))
    return np.array(depths), np.array(shares)


def test_real_cars_agree_with_sgbm(shared_data: Path, yolox_model: Path) -> None:
    """The KITTI object pair: YOLOX finds its parked cars; every car placed whose box is at least a quarter
    unhidden by nearer cars agrees with the dense SGBM disparity there: within 5 %, or a near car's depth extent,
    or far away what SGBM resolves (0.5 px). The range limit is lifted so that the distant cars (50 m, 100 m) are
    checked too; the car cut off by the image border is not placed, nor the car mostly hidden by a nearer one."""
    folder = shared_data / "kitti_object_pair"
    left_bgr, right_bgr = (cv2.imread(str(folder / name)) for name in ("left.png", "right.png"))
    left, right = (cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) for image in (left_bgr, right_bgr))
    camera = _object_pair_camera(folder)
    cars = [d for d in make_detector(DetectorConfig(model=yolox_model)).detect(0, left_bgr) if d.label == "car"]
    assert len(cars) >= 5
    observations = ObjectTriangulator(camera, StereoObjectConfig(max_depth=120.0)).observe(left, right, cars)
    boxes = np.array([c.box for c in cars])
    depths, shares = _sgbm_depths(left, right, camera, boxes)
    reference = {tuple(box): (depth, share) for box, depth, share in zip(boxes, depths, shares, strict=True)}
    checked = [(o.center_camera[2], reference[tuple(o.box_left)]) for o in observations]
    checked = [(depth, sgbm) for depth, (sgbm, share) in checked if share >= MIN_UNHIDDEN_SHARE]
    assert len(checked) >= 5
    for depth, sgbm in checked:
        disparity_gap = abs(camera.fx * camera.baseline * (1 / depth - 1 / sgbm))
        assert depth == pytest.approx(sgbm, rel=0.05, abs=NEAR_CAR_EXTENT_M) or disparity_gap <= FAR_DISPARITY_PX


def test_unhidden_shares_count_boxes_reaching_lower_as_nearer() -> None:
    from neoslam.perception.stereo import unhidden_shares

    far = [100, 100, 140, 130]
    near_right_half = [120, 90, 200, 160]  # reaches lower: nearer, hides the right half of `far`
    behind = [0, 95, 110, 120]  # ends higher: farther, hides nothing of `far`
    shares = unhidden_shares(np.array([far, near_right_half, behind], dtype=float))
    assert shares[0] == pytest.approx(0.5, abs=0.05)
    assert shares[1] == 1.0
    assert shares[2] == pytest.approx(1.0 - 10 / 110, abs=0.05)  # `far` reaches lower and covers its last 10 px
