"""Stereo visual odometry: on the 12 real frames of kitti_mini against KITTI's ground truth, and on synthetic
images with a known motion."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam.config import CameraConfig
from neoslam.config.perception import StereoOdometryConfig
from neoslam.datasets.kitti import KittiSequence, read_kitti_sequence
from neoslam.geometry import camera_poses_to_robot, relative_pose, rotation_angle, yaw_of
from neoslam.perception.odometry import (
    StereoOdometry,
    box_mask,
    detect_corners,
    stereo_points,
)

CAMERA = CameraConfig()  # KITTI 04-12 calibration, 1226x370
CONFIG = StereoOdometryConfig()
DISTANCE_TOLERANCE = 0.02  # the target: 2 % of the distance travelled
HEADING_TOLERANCE_DEG = 1.0  # the target
STEP_TRANSLATION_TOLERANCE_M = 0.1  # per step of ~1.2 m; measured at most ~0.03
STEP_ROTATION_TOLERANCE_DEG = 0.5  # per step; measured ~0.1 (KITTI's own poses are no better)


@pytest.fixture(scope="module")
def kitti_mini_sequence(shared_data: Path) -> KittiSequence:
    return read_kitti_sequence(shared_data / "kitti_mini", "06")


@pytest.fixture(scope="module")
def kitti_mini_pairs(kitti_mini_sequence: KittiSequence) -> list[tuple[np.ndarray, np.ndarray]]:
    return [kitti_mini_sequence.stereo_pair(i) for i in range(len(kitti_mini_sequence))]


def _run(camera: CameraConfig, pairs: list[tuple[np.ndarray, np.ndarray]]) -> tuple[StereoOdometry, np.ndarray]:
    odometry = StereoOdometry(camera, CONFIG)
    poses = []
    for left, right in pairs:
        odometry.step(left, right)
        poses.append(odometry.pose)
    return odometry, np.array(poses)


@pytest.fixture(scope="module")
def kitti_mini_odometry(kitti_mini_sequence, kitti_mini_pairs) -> tuple[StereoOdometry, np.ndarray]:
    """The odometry after the 12 frames and its robot poses T_first_robot."""
    odometry, camera_poses = _run(kitti_mini_sequence.camera, kitti_mini_pairs)
    return odometry, camera_poses_to_robot(camera_poses)


def test_distance_and_heading_match_ground_truth(kitti_mini_sequence, kitti_mini_odometry) -> None:
    _, poses = kitti_mini_odometry
    truth = kitti_mini_sequence.ground_truth.poses
    travelled = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum()
    true_travelled = kitti_mini_sequence.ground_truth.path_length()
    assert travelled == pytest.approx(true_travelled, rel=DISTANCE_TOLERANCE)
    end_distance = np.linalg.norm(poses[-1, :3, 3] - poses[0, :3, 3])
    true_end_distance = np.linalg.norm(truth[-1, :3, 3] - truth[0, :3, 3])
    assert end_distance == pytest.approx(true_end_distance, rel=DISTANCE_TOLERANCE)
    heading = yaw_of(poses[-1]) - yaw_of(poses[0])
    true_heading = yaw_of(truth[-1]) - yaw_of(truth[0])
    assert abs(np.degrees(heading - true_heading)) < HEADING_TOLERANCE_DEG


def test_each_step_is_close_to_ground_truth(kitti_mini_sequence, kitti_mini_odometry) -> None:
    odometry, poses = kitti_mini_odometry
    truth = kitti_mini_sequence.ground_truth.poses
    steps, true_steps = relative_pose(poses[:-1], poses[1:]), relative_pose(truth[:-1], truth[1:])
    translation_errors = np.linalg.norm(steps[:, :3, 3] - true_steps[:, :3, 3], axis=1)
    assert translation_errors.max() < STEP_TRANSLATION_TOLERANCE_M
    rotation_errors = rotation_angle(np.swapaxes(steps[:, :3, :3], 1, 2) @ true_steps[:, :3, :3])
    assert np.degrees(rotation_errors).max() < STEP_ROTATION_TOLERANCE_DEG
    assert odometry.failures == 0
    assert odometry.last_inliers >= CONFIG.min_inliers


def test_the_same_images_give_the_same_motion(kitti_mini_sequence, kitti_mini_pairs) -> None:
    first = _run(kitti_mini_sequence.camera, kitti_mini_pairs[:4])[1]
    second = _run(kitti_mini_sequence.camera, kitti_mini_pairs[:4])[1]
    assert np.array_equal(first, second)


def test_a_frame_seen_twice_is_no_motion(kitti_mini_sequence, kitti_mini_pairs) -> None:
    odometry = StereoOdometry(kitti_mini_sequence.camera, CONFIG)
    np.testing.assert_array_equal(odometry.step(*kitti_mini_pairs[0]), np.eye(4))
    motion = odometry.step(*kitti_mini_pairs[0])
    assert np.linalg.norm(motion[:3, 3]) < 1e-3
    assert np.degrees(rotation_angle(motion[:3, :3])) < 0.01


def _texture(size: int, seed: int) -> np.ndarray:
    noise = np.random.default_rng(seed).uniform(0, 255, (size, size)).astype(np.float32)
    blurred = cv2.GaussianBlur(noise, (0, 0), 2.0)
    return cv2.normalize(blurred, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _render_plane(texture: np.ndarray, metres_per_texel: float, depth: float, camera_x: float) -> np.ndarray:
    """Image of a textured plane facing the camera (centred on the optical axis at x = 0) from a pinhole at
    (camera_x, 0, 0), looking down z; the plane is `depth` ahead."""
    scale = CAMERA.fx / depth * metres_per_texel  # image px per texel
    centre = texture.shape[0] / 2
    offset_x = CAMERA.cx - CAMERA.fx / depth * (centre * metres_per_texel + camera_x)
    offset_y = CAMERA.cy - CAMERA.fy / depth * centre * metres_per_texel
    warp = np.array([[scale, 0.0, offset_x], [0.0, scale, offset_y]])
    return cv2.warpAffine(texture, warp, (CAMERA.width, CAMERA.height), flags=cv2.INTER_LINEAR)


def _stereo_plane(texture: np.ndarray, depth: float, camera_x: float) -> tuple[np.ndarray, np.ndarray]:
    metres_per_texel = 0.02
    left = _render_plane(texture, metres_per_texel, depth, camera_x)
    right = _render_plane(texture, metres_per_texel, depth, camera_x + CAMERA.baseline)
    return left, right


def test_stereo_depth_of_a_synthetic_plane() -> None:
    depth = 10.0
    left, right = _stereo_plane(_texture(1500, seed=1), depth, 0.0)
    corners = detect_corners(left, CONFIG)
    pixels, points = stereo_points(left, right, corners, CAMERA, CONFIG)
    assert len(pixels) > 0.8 * len(corners) > 100
    assert np.median(points[:, 2]) == pytest.approx(depth, rel=0.01)


def test_synthetic_motion_is_recovered() -> None:
    """The camera moves towards a textured plane and sideways: T_previous_current holds that translation."""
    texture = _texture(1500, seed=2)
    odometry = StereoOdometry(CAMERA, CONFIG)
    odometry.step(*_stereo_plane(texture, depth=10.0, camera_x=0.0))
    forward, sideways = 0.8, 0.1
    motion = odometry.step(*_stereo_plane(texture, depth=10.0 - forward, camera_x=sideways))
    np.testing.assert_allclose(motion[:3, 3], [sideways, 0.0, forward], atol=0.01)
    assert np.degrees(rotation_angle(motion[:3, :3])) < 0.05
    assert odometry.failures == 0


def test_masked_boxes_hold_no_corners(kitti_mini_pairs) -> None:
    left = kitti_mini_pairs[0][0]
    box = np.array([[300.0, 100.0, 700.0, 300.0]])
    unmasked = detect_corners(left, CONFIG)
    masked = detect_corners(left, CONFIG, box)

    def inside(corners: np.ndarray) -> np.ndarray:
        x, y = corners[:, 0], corners[:, 1]
        return (x >= 300) & (x <= 700) & (y >= 100) & (y <= 300)

    assert inside(unmasked).sum() > 50
    assert not inside(masked).any()
    assert len(masked) > 100
    assert inside(detect_corners(left, CONFIG.model_copy(update={"mask_objects": False}), box)).sum() > 50


def test_box_mask_is_clipped_to_the_image() -> None:
    assert box_mask((10, 20), None) is None
    assert box_mask((10, 20), np.empty((0, 4))) is None
    mask = box_mask((10, 20), np.array([[-5.0, 2.0, 3.2, 50.0]]))
    assert mask.shape == (10, 20)
    assert (mask[2:, :4] == 0).all() and (mask[:2] == 255).all() and (mask[:, 5:] == 255).all()


def test_blank_images_repeat_the_previous_motion(kitti_mini_sequence, kitti_mini_pairs) -> None:
    odometry = StereoOdometry(kitti_mini_sequence.camera, CONFIG)
    odometry.step(*kitti_mini_pairs[0])
    moved = odometry.step(*kitti_mini_pairs[1])
    black = np.zeros_like(kitti_mini_pairs[0][0])
    np.testing.assert_array_equal(odometry.step(black, black), moved)  # nothing to track into
    assert odometry.failures == 1
    np.testing.assert_array_equal(odometry.step(*kitti_mini_pairs[3]), moved)  # nothing tracked from
    assert odometry.failures == 2
    odometry.step(*kitti_mini_pairs[4])
    assert odometry.failures == 2 and odometry.last_inliers >= CONFIG.min_inliers
    assert np.linalg.norm(odometry.pose[:3, 3]) == pytest.approx(4 * np.linalg.norm(moved[:3, 3]), rel=0.1)


def test_images_of_different_sizes_are_refused() -> None:
    odometry = StereoOdometry(CAMERA, CONFIG)
    with pytest.raises(ValueError, match="grey images"):
        odometry.step(np.zeros((10, 20), np.uint8), np.zeros((10, 21), np.uint8))
