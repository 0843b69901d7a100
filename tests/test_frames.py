"""Camera optical frame (x right, y down, z forward) <-> robot frame (REP-103: x forward, y left, z up)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.geometry import (
    ROBOT_FROM_CAMERA,
    camera_points_to_robot,
    camera_poses_to_robot,
    is_rotation_matrix,
    make_pose,
    robot_points_to_camera,
    robot_poses_to_camera,
    transform_points,
    yaw_of,
)


def _camera_poses(rotation: np.ndarray, translations: np.ndarray) -> np.ndarray:
    return np.stack([make_pose(rotation, t) for t in translations])


def test_axis_permutation_is_a_rotation() -> None:
    assert is_rotation_matrix(ROBOT_FROM_CAMERA, 1e-12)
    np.testing.assert_array_equal(camera_points_to_robot(np.array([[0.0, 0.0, 1.0]])), [[1.0, 0.0, 0.0]])  # forward
    np.testing.assert_array_equal(camera_points_to_robot(np.array([[1.0, 0.0, 0.0]])), [[0.0, -1.0, 0.0]])  # right
    np.testing.assert_array_equal(camera_points_to_robot(np.array([[0.0, 1.0, 0.0]])), [[0.0, 0.0, -1.0]])  # down


def test_forward_along_camera_z_is_robot_plus_x() -> None:
    camera = _camera_poses(np.eye(3), np.array([[0.0, 0.0, z] for z in range(5)]))
    robot = camera_poses_to_robot(camera)
    np.testing.assert_allclose(robot[:, :3, 3], [[x, 0.0, 0.0] for x in range(5)], atol=1e-12)
    np.testing.assert_allclose(robot[:, :3, :3], np.tile(np.eye(3), (5, 1, 1)), atol=1e-12)


def test_camera_up_and_right_become_robot_z_and_minus_y() -> None:
    robot = camera_poses_to_robot(_camera_poses(np.eye(3), np.array([[2.0, -3.0, 0.0]])))
    np.testing.assert_allclose(robot[0, :3, 3], [0.0, -2.0, 3.0], atol=1e-12)  # right 2, up 3


def test_turning_left_is_positive_yaw() -> None:
    # A left turn in the camera frame: the forward axis z swings towards -x, a rotation about -y (y points down).
    angle = np.radians(30.0)
    left = Rotation.from_rotvec([0.0, -angle, 0.0]).as_matrix()
    np.testing.assert_allclose(left @ [0, 0, 1], [-np.sin(angle), 0, np.cos(angle)], atol=1e-12)
    robot = camera_poses_to_robot(_camera_poses(left, np.zeros((1, 3))))
    np.testing.assert_allclose(yaw_of(robot), [angle], atol=1e-12)
    # driving 10 m forward after the turn goes to +x and +y (left) in the robot world
    step = make_pose(np.eye(3), np.array([0.0, 0.0, 10.0]))
    moved = camera_poses_to_robot(_camera_poses(left, np.zeros((1, 3))) @ step)
    assert moved[0, 0, 3] > 0 and moved[0, 1, 3] > 0
    np.testing.assert_allclose(moved[0, :2, 3], 10 * np.array([np.cos(angle), np.sin(angle)]), atol=1e-12)


def test_pose_round_trip() -> None:
    rng = np.random.default_rng(0)
    rotations = Rotation.random(30, random_state=1).as_matrix()
    poses = np.stack([make_pose(r, t) for r, t in zip(rotations, rng.uniform(-9, 9, (30, 3)), strict=True)])
    np.testing.assert_allclose(robot_poses_to_camera(camera_poses_to_robot(poses)), poses, atol=1e-12)
    np.testing.assert_allclose(camera_poses_to_robot(robot_poses_to_camera(poses)), poses, atol=1e-12)


def test_point_round_trip_and_consistency_with_poses() -> None:
    rng = np.random.default_rng(2)
    points = rng.normal(size=(20, 3))
    np.testing.assert_allclose(robot_points_to_camera(camera_points_to_robot(points)), points, atol=1e-12)
    # a point seen by camera pose T_c0_ci lands at the same world point whichever frame is used
    camera_pose = make_pose(Rotation.random(random_state=3).as_matrix(), rng.normal(size=3))
    in_camera_world = transform_points(camera_pose, points)
    robot_pose = camera_poses_to_robot(camera_pose[None])[0]
    in_robot_world = transform_points(robot_pose, camera_points_to_robot(points))
    np.testing.assert_allclose(in_robot_world, camera_points_to_robot(in_camera_world), atol=1e-12)
