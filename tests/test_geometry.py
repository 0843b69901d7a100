"""SE(3), quaternion and alignment helpers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.geometry import (
    SimilarityTransform,
    body_velocities,
    integrate_body_velocities,
    invert_pose,
    is_rotation_matrix,
    make_pose,
    pose_from_quaternion,
    quaternion_from_pose,
    relative_pose,
    rotation_angle,
    transform_points,
    umeyama_alignment,
    yaw_of,
    yaw_pitch_roll,
)


def _random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rotations = Rotation.random(n, random_state=seed).as_matrix()
    return np.stack([make_pose(r, t) for r, t in zip(rotations, rng.uniform(-50, 50, (n, 3)), strict=True)])


def test_make_pose_accepts_matrix_and_rotation() -> None:
    rotation = Rotation.from_euler("z", 30, degrees=True)
    pose = make_pose(rotation, np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(pose, make_pose(rotation.as_matrix(), np.array([1.0, 2.0, 3.0])))
    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])


def test_invert_pose_single_and_stack() -> None:
    poses = _random_poses(20)
    inverse = invert_pose(poses)
    np.testing.assert_allclose(inverse @ poses, np.tile(np.eye(4), (20, 1, 1)), atol=1e-12)
    np.testing.assert_allclose(invert_pose(poses[3]), np.linalg.inv(poses[3]), atol=1e-12)


def test_relative_pose() -> None:
    a, b = _random_poses(2, seed=1)
    relative = relative_pose(a, b)
    np.testing.assert_allclose(a @ relative, b, atol=1e-12)
    stack = _random_poses(10, seed=2)
    steps = relative_pose(stack[:-1], stack[1:])
    np.testing.assert_allclose(stack[:-1] @ steps, stack[1:], atol=1e-10)


def test_quaternion_round_trip() -> None:
    poses = _random_poses(50, seed=3)
    quaternions = quaternion_from_pose(poses)
    assert np.all(quaternions[:, 3] >= 0)
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(pose_from_quaternion(poses[:, :3, 3], quaternions), poses, atol=1e-12)


def test_quaternion_order_is_xyzw() -> None:
    half = np.sqrt(0.5)
    pose = pose_from_quaternion(np.zeros(3), np.array([0.0, 0.0, half, half]))[0]  # 90 degrees about z
    np.testing.assert_allclose(pose[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_angles() -> None:
    rotation = Rotation.from_euler("ZYX", [0.7, -0.2, 0.1]).as_matrix()
    pose = make_pose(rotation, np.zeros(3))
    np.testing.assert_allclose(yaw_pitch_roll(pose[None])[0], [0.7, -0.2, 0.1], atol=1e-12)
    np.testing.assert_allclose(yaw_of(pose), 0.7, atol=1e-12)
    np.testing.assert_allclose(rotation_angle(Rotation.from_rotvec([0, 0.4, 0]).as_matrix()), 0.4, atol=1e-12)
    np.testing.assert_allclose(rotation_angle(Rotation.from_rotvec([np.pi, 0, 0]).as_matrix()), np.pi, atol=1e-7)
    np.testing.assert_allclose(rotation_angle(np.eye(3)), 0.0, atol=1e-12)


def test_is_rotation_matrix() -> None:
    rotation = Rotation.from_euler("xyz", [0.1, 0.2, 0.3]).as_matrix()
    assert is_rotation_matrix(rotation, 1e-9)
    assert not is_rotation_matrix(2 * rotation, 1e-3)
    assert not is_rotation_matrix(np.diag([1.0, 1.0, -1.0]), 1e-3)  # a reflection


def test_transform_points() -> None:
    pose = _random_poses(1, seed=4)[0]
    points = np.random.default_rng(0).normal(size=(7, 3))
    homogeneous = np.column_stack([points, np.ones(7)]) @ pose.T
    np.testing.assert_allclose(transform_points(pose, points), homogeneous[:, :3], atol=1e-12)


@pytest.mark.parametrize("with_scale", [False, True])
def test_umeyama_recovers_a_known_transform(with_scale: bool) -> None:
    rng = np.random.default_rng(5)
    source = rng.uniform(-30, 30, (100, 3))
    rotation = Rotation.from_euler("ZYX", [1.1, 0.3, -0.2]).as_matrix()
    translation = np.array([4.0, -7.0, 2.5])
    scale = 1.7 if with_scale else 1.0
    known = SimilarityTransform(rotation, translation, scale)
    target = known.apply_to_points(source)
    found = umeyama_alignment(source, target, with_scale=with_scale)
    np.testing.assert_allclose(found.rotation, rotation, atol=1e-10)
    np.testing.assert_allclose(found.translation, translation, atol=1e-9)
    assert found.scale == pytest.approx(scale, abs=1e-12)
    np.testing.assert_allclose(found.as_matrix()[:3, :3], scale * rotation, atol=1e-9)


def test_umeyama_with_noise_is_close() -> None:
    rng = np.random.default_rng(6)
    source = rng.uniform(-30, 30, (500, 3))
    rotation = Rotation.from_euler("z", 40, degrees=True).as_matrix()
    target = source @ rotation.T + [1.0, 2.0, 3.0] + rng.normal(0, 0.05, source.shape)
    found = umeyama_alignment(source, target)
    assert np.degrees(rotation_angle(found.rotation.T @ rotation)) < 0.05
    np.testing.assert_allclose(found.translation, [1.0, 2.0, 3.0], atol=0.02)


def test_umeyama_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        umeyama_alignment(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        umeyama_alignment(np.zeros((5, 3)), np.zeros((4, 3)))


def test_similarity_moves_poses() -> None:
    poses = _random_poses(5, seed=7)
    transform = SimilarityTransform(Rotation.from_euler("z", 0.5).as_matrix(), np.array([1.0, 0, 0]), 2.0)
    moved = transform.apply_to_poses(poses)
    np.testing.assert_allclose(moved[:, :3, 3], transform.apply_to_points(poses[:, :3, 3]))
    np.testing.assert_allclose(moved[:, :3, :3], transform.rotation @ poses[:, :3, :3])
    np.testing.assert_allclose(poses, _random_poses(5, seed=7))  # input untouched


def _smooth_trajectory(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    stamps = np.cumsum(np.random.default_rng(8).uniform(0.05, 0.15, n))
    yaw, pitch = 0.3 * np.sin(stamps), 0.05 * np.cos(stamps)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, 0 * yaw])).as_matrix()
    poses[:, :3, 3] = np.column_stack([5 * stamps, 10 * np.sin(0.2 * stamps), 0.3 * stamps])
    return stamps, poses


def test_integrate_body_velocities_inverts_body_velocities() -> None:
    stamps, poses = _smooth_trajectory()
    linear, angular = body_velocities(poses, stamps)
    np.testing.assert_array_equal(linear[0], 0.0)
    np.testing.assert_array_equal(angular[0], 0.0)
    integrated = integrate_body_velocities(linear, angular, stamps, start=poses[0])
    np.testing.assert_allclose(integrated, poses, atol=1e-9)
    # without a start the result is the same path seen from the first pose
    from_identity = integrate_body_velocities(linear, angular, stamps)
    np.testing.assert_allclose(from_identity, relative_pose(poses[0], poses), atol=1e-9)
    linear_again, angular_again = body_velocities(integrated, stamps)
    np.testing.assert_allclose(linear_again, linear, atol=1e-8)
    np.testing.assert_allclose(angular_again, angular, atol=1e-8)


def test_body_velocities_of_a_forward_drive() -> None:
    stamps = np.arange(10) * 0.1
    poses = np.tile(np.eye(4), (10, 1, 1))
    poses[:, 0, 3] = 2.0 * stamps  # 2 m/s along x
    linear, angular = body_velocities(poses, stamps)
    np.testing.assert_allclose(linear[1:], np.tile([2.0, 0, 0], (9, 1)), atol=1e-12)
    np.testing.assert_allclose(angular, 0.0, atol=1e-12)


def test_integrate_single_frame() -> None:
    start = _random_poses(1, seed=9)[0]
    poses = integrate_body_velocities(np.zeros((1, 3)), np.zeros((1, 3)), np.array([0.0]), start=start)
    np.testing.assert_allclose(poses, start[None])


def test_planar_motion_is_negative_when_reversing() -> None:
    from neoslam.geometry import planar_motion

    start = make_pose(np.eye(3), np.zeros(3))
    turned = make_pose(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))  # facing +y
    assert planar_motion(start, make_pose(np.eye(3), [2.0, 0.0, 0.5])) == pytest.approx((2.0, 0.0, 0.5))
    assert planar_motion(start, make_pose(np.eye(3), [-2.0, 0.0, 0.0]))[0] == pytest.approx(-2.0)
    assert planar_motion(turned, turned @ make_pose(np.eye(3), [-1.5, 0.0, 0.0]))[0] == pytest.approx(-1.5)
