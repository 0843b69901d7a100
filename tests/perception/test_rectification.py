"""Stereo rectification: raw pairs synthesised from a known scene through known lenses (radial-tangential and
fisheye) and a known rotation between the cameras come back to rows that line up, each point within a fraction of a
pixel of where the rectified camera sees it; calibrations of a rectified pair pass the images on untouched; a
calibration that cannot be rectified is one clear sentence."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.geometry import invert_pose, make_pose
from neoslam.perception.rectification import RawCamera, StereoRectifier

SIZE = (640, 480)
BASELINE = 0.12
K_LEFT = np.array([[420.0, 0.0, 322.5], [0.0, 418.0, 243.0], [0.0, 0.0, 1.0]])
K_RIGHT = np.array([[415.0, 0.0, 316.0], [0.0, 416.5, 238.5], [0.0, 0.0, 1.0]])
D_LEFT = np.array([-0.28, 0.074, 0.0002, 0.00002])  # EuRoC-like radial-tangential
D_RIGHT = np.array([-0.27, 0.071, -0.0001, -0.00004, 0.01])
FISHEYE_LEFT = np.array([0.02, -0.01, 0.004, -0.001])
FISHEYE_RIGHT = np.array([0.018, -0.008, 0.003, -0.0012])
TURN = Rotation.from_euler("xyz", [0.8, -1.2, 0.5], degrees=True).as_matrix()  # right camera relative to left
BLOB_SIGMA = 1.5  # px
WINDOW = 5  # half side of the window a blob's centroid is measured in, px
MAX_POINT_ERROR = 0.25  # px: "a fraction of a pixel"


def _scene() -> np.ndarray:
    """Points in the left camera's optical frame, spread over the middle of the view at 3-9 m."""
    rng = np.random.default_rng(7)
    grid = np.stack(np.meshgrid(np.linspace(-0.55, 0.55, 7), np.linspace(-0.4, 0.4, 5)), axis=-1).reshape(-1, 2)
    depth = rng.uniform(3.0, 9.0, len(grid))
    return np.column_stack([grid * depth[:, None], depth])


def _right_from_left() -> np.ndarray:
    """T_right_left: the right camera BASELINE to the right of the left one, turned by TURN."""
    right_in_left = make_pose(TURN.T, np.array([BASELINE, 0.004, -0.003]))
    return invert_pose(right_in_left)


def _project(points: np.ndarray, K: np.ndarray, D: np.ndarray, fisheye: bool, pose: np.ndarray) -> np.ndarray:
    rvec, tvec = cv2.Rodrigues(np.ascontiguousarray(pose[:3, :3]))[0], pose[:3, 3].reshape(3, 1).copy()
    if fisheye:
        pixels, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, K, D)
    else:
        pixels, _ = cv2.projectPoints(points, rvec, tvec, K, D)
    return pixels.reshape(-1, 2)


def _render(pixels: np.ndarray) -> np.ndarray:
    """Bright Gaussian blobs centred at sub-pixel positions on black."""
    v, u = np.mgrid[0 : SIZE[1], 0 : SIZE[0]].astype(np.float64)
    image = np.zeros((SIZE[1], SIZE[0]))
    for x, y in pixels:
        lo_x, hi_x, lo_y, hi_y = int(x) - 8, int(x) + 9, int(y) - 8, int(y) + 9
        patch = (slice(max(lo_y, 0), max(hi_y, 0)), slice(max(lo_x, 0), max(hi_x, 0)))
        image[patch] += np.exp(-((u[patch] - x) ** 2 + (v[patch] - y) ** 2) / (2 * BLOB_SIGMA**2))
    return np.clip(image * 250, 0, 255).astype(np.uint8)


def _centroids(image: np.ndarray, expected: np.ndarray) -> np.ndarray:
    found = []
    for x, y in expected:
        cx, cy = round(x), round(y)
        window = image[cy - WINDOW : cy + WINDOW + 1, cx - WINDOW : cx + WINDOW + 1].astype(np.float64)
        v, u = np.mgrid[cy - WINDOW : cy + WINDOW + 1, cx - WINDOW : cx + WINDOW + 1]
        found.append([(window * u).sum() / window.sum(), (window * v).sum() / window.sum()])
    return np.array(found)


def _expected(rectifier: StereoRectifier, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the rectified pair sees the points: the rectified left camera is the raw left turned by
    `left_rotation`; the right one sits `baseline` along its x axis with the same intrinsics."""
    camera = rectifier.camera
    turned = points @ rectifier.left_rotation.T
    y = camera.fy * turned[:, 1] / turned[:, 2] + camera.cy
    left = np.column_stack([camera.fx * turned[:, 0] / turned[:, 2] + camera.cx, y])
    right = np.column_stack([camera.fx * (turned[:, 0] - camera.baseline) / turned[:, 2] + camera.cx, y])
    return left, right


def _raw_pair(model: str) -> tuple[RawCamera, RawCamera, np.ndarray, np.ndarray, np.ndarray]:
    fisheye = model == "equidistant"
    d_left, d_right = (FISHEYE_LEFT, FISHEYE_RIGHT) if fisheye else (D_LEFT, D_RIGHT)
    left, right = RawCamera(K_LEFT, d_left, model, SIZE), RawCamera(K_RIGHT, d_right, model, SIZE)
    points, pose = _scene(), _right_from_left()
    raw_left = _render(_project(points, K_LEFT, d_left, fisheye, np.eye(4)))
    raw_right = _render(_project(points, K_RIGHT, d_right, fisheye, pose))
    return left, right, pose, raw_left, raw_right


@pytest.mark.parametrize("model", ["plumb_bob", "equidistant"])
def test_a_raw_pair_comes_back_to_its_rectified_scene(model: str) -> None:
    left, right, pose, raw_left, raw_right = _raw_pair(model)
    rectifier = StereoRectifier.from_extrinsics(left, right, pose)
    assert not rectifier.identity
    assert rectifier.camera.baseline == pytest.approx(np.linalg.norm(pose[:3, 3]), rel=1e-9)
    assert (rectifier.camera.width, rectifier.camera.height) == SIZE
    rect_left, rect_right = rectifier.rectify(raw_left, raw_right)
    assert rect_left.shape == rect_right.shape == (SIZE[1], SIZE[0]) and rect_left.dtype == np.uint8
    expected_left, expected_right = _expected(rectifier, _scene())
    found_left, found_right = _centroids(rect_left, expected_left), _centroids(rect_right, expected_right)
    assert np.abs(found_left - expected_left).max() < MAX_POINT_ERROR
    assert np.abs(found_right - expected_right).max() < MAX_POINT_ERROR
    assert np.abs(found_left[:, 1] - found_right[:, 1]).max() < MAX_POINT_ERROR  # the rows line up
    # the raw pair's rows do not: what rectification is for
    raw_left_pixels = _centroids(raw_left, _project(_scene(), K_LEFT, left.D, model == "equidistant", np.eye(4)))
    raw_right_pixels = _centroids(raw_right, _project(_scene(), K_RIGHT, right.D, model == "equidistant", pose))
    assert np.median(np.abs(raw_left_pixels[:, 1] - raw_right_pixels[:, 1])) > 2.0
    np.testing.assert_array_equal(rectifier.rectify_left(raw_left), rect_left)


def test_the_projections_of_a_rectification_give_its_maps() -> None:
    """ROS's CameraInfo path (K, D, R, P of each camera, as image_proc uses them) gives the same pair as the
    extrinsics it was computed from."""
    left, right, pose, raw_left, raw_right = _raw_pair("plumb_bob")
    R1, R2, P1, P2, *_ = cv2.stereoRectify(
        K_LEFT,
        D_LEFT,
        K_RIGHT,
        D_RIGHT,
        SIZE,
        pose[:3, :3].copy(),
        pose[:3, 3:].copy(),
        flags=cv2.CALIB_ZERO_DISPARITY,
        alpha=0,
    )
    direct = StereoRectifier.from_extrinsics(left, right, pose)
    ros = StereoRectifier.from_projections(left, right, R1, R2, P1, P2)
    assert ros.camera == direct.camera
    for ours, theirs in zip(ros.rectify(raw_left, raw_right), direct.rectify(raw_left, raw_right), strict=True):
        np.testing.assert_array_equal(ours, theirs)


def test_a_rectified_pair_needs_no_warp() -> None:
    camera = RawCamera(K_LEFT, np.zeros(5), "plumb_bob", SIZE)
    undistorted = RawCamera(K_LEFT, [], "none", SIZE)
    rng = np.random.default_rng(1)
    left, right = (rng.integers(0, 256, (SIZE[1], SIZE[0]), dtype=np.uint8) for _ in range(2))
    shift = make_pose(np.eye(3), np.array([-BASELINE, 0.0, 0.0]))
    for rectifier in (
        StereoRectifier.from_extrinsics(camera, camera, shift),
        StereoRectifier.from_extrinsics(undistorted, undistorted, shift),
        StereoRectifier.from_projections(
            camera, camera, np.eye(3), np.eye(3), np.hstack([K_LEFT, np.zeros((3, 1))]),
            np.hstack([K_LEFT, [[-K_LEFT[0, 0] * BASELINE], [0.0], [0.0]]]),
        ),
    ):  # fmt: skip
        assert rectifier.identity
        assert rectifier.camera.baseline == pytest.approx(BASELINE, rel=1e-15)
        assert (rectifier.camera.fx, rectifier.camera.cx, rectifier.camera.cy) == (420.0, 322.5, 243.0)
        out_left, out_right = rectifier.rectify(left, right)
        assert out_left is left and out_right is right
    exact = StereoRectifier.from_extrinsics(camera, camera, shift)
    assert exact.camera.baseline == BASELINE  # to the last bit: a rectified input runs as KITTI's does


def test_a_calibration_that_cannot_be_rectified_is_refused() -> None:
    camera = RawCamera(K_LEFT, D_LEFT, "plumb_bob", SIZE)
    swapped = make_pose(np.eye(3), np.array([BASELINE, 0.0, 0.0]))  # the right camera on the left
    with pytest.raises(ValueError, match="baseline is not positive"):
        StereoRectifier.from_extrinsics(
            RawCamera(K_LEFT, [], "none", SIZE), RawCamera(K_LEFT, [], "none", SIZE), swapped
        )
    with pytest.raises(ValueError, match="baseline is not positive"):
        StereoRectifier.from_extrinsics(camera, camera, swapped)
    stacked = make_pose(np.eye(3), np.array([0.0, -BASELINE, 0.0]))  # one camera above the other
    with pytest.raises(ValueError, match="above or below"):
        StereoRectifier.from_extrinsics(camera, camera, stacked)
    with pytest.raises(ValueError, match="not finite"):
        StereoRectifier.from_extrinsics(camera, camera, np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="not a rotation"):
        StereoRectifier.from_extrinsics(camera, camera, make_pose(2 * np.eye(3), np.array([-BASELINE, 0, 0])))
    with pytest.raises(ValueError, match="in one place"):
        StereoRectifier.from_extrinsics(camera, camera, make_pose(TURN, np.zeros(3)))
    fisheye = RawCamera(K_LEFT, FISHEYE_LEFT, "equidistant", SIZE)
    with pytest.raises(ValueError, match="both need one model"):
        StereoRectifier.from_extrinsics(camera, fisheye, _right_from_left())
    smaller = RawCamera(K_LEFT, D_LEFT, "plumb_bob", (320, 240))
    with pytest.raises(ValueError, match="differs from the right"):
        StereoRectifier.from_extrinsics(camera, smaller, _right_from_left())
    other = np.hstack([K_RIGHT * [[1.1], [1], [1]], [[-50.0], [0], [0]]])
    with pytest.raises(ValueError, match="not a rectified pair"):
        StereoRectifier.from_projections(
            camera, camera, np.eye(3), np.eye(3), np.hstack([K_LEFT, np.zeros((3, 1))]), other
        )


@pytest.mark.parametrize(
    ("K", "D", "model", "size", "problem"),
    [
        (np.eye(2), [], "none", SIZE, "shape"),
        (K_LEFT * [[-1], [1], [1]], [], "none", SIZE, "non-positive focal length"),
        (np.where(np.eye(3) == 1, np.inf, 0), [], "none", SIZE, "not finite"),
        (K_LEFT, [0.1, 0.2, 0.3], "plumb_bob", SIZE, "takes 0, 4, 5, 8, 12, 14 coefficients, not 3"),
        (K_LEFT, D_LEFT[:3], "equidistant", SIZE, "takes 4 coefficients, not 3"),
        (K_LEFT, [0.1], "none", SIZE, "non-zero"),
        (K_LEFT, [], "kannala", SIZE, "unknown distortion model"),
        (K_LEFT, [], "none", (640, 0), "image size"),
        (K_LEFT, [], "none", (640.5, 480), "image size"),
        (K_LEFT, [], "none", (np.inf, 480), "image size"),
        (K_LEFT, [], "none", "640x480", "image size"),
        (K_LEFT, [np.nan] * 4, "plumb_bob", SIZE, "not finite"),
    ],
)
def test_a_bad_camera_is_one_sentence(K, D, model: str, size, problem: str) -> None:
    with pytest.raises(ValueError, match=problem) as caught:
        RawCamera(K, D, model, size)  # type: ignore[arg-type]
    assert "\n" not in str(caught.value)


def test_images_of_another_size_name_both_sizes() -> None:
    camera = RawCamera(K_LEFT, D_LEFT, "plumb_bob", SIZE)
    rectifier = StereoRectifier.from_extrinsics(camera, camera, make_pose(np.eye(3), np.array([-BASELINE, 0, 0])))
    good, small = np.zeros((480, 640), np.uint8), np.zeros((240, 320), np.uint8)
    with pytest.raises(ValueError, match="right image is 320x240, the calibration's is 640x480"):
        rectifier.rectify(good, small)
    with pytest.raises(ValueError, match="grey uint8"):
        rectifier.rectify(good.astype(np.float32), good)
    with pytest.raises(ValueError, match="grey uint8"):
        rectifier.rectify_left(np.zeros((480, 640, 3), np.uint8))


def test_rectification_is_deterministic() -> None:
    left, right, pose, raw_left, raw_right = _raw_pair("plumb_bob")
    first = StereoRectifier.from_extrinsics(left, right, pose).rectify(raw_left, raw_right)
    second = StereoRectifier.from_extrinsics(left, right, pose).rectify(raw_left, raw_right)
    for a, b in zip(first, second, strict=True):
        assert a.tobytes() == b.tobytes()
