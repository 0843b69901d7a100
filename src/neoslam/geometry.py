"""SE(3), quaternion and alignment helpers on scipy's Rotation, and the frame conventions. Pure maths: no I/O.

The one place where NeoSLAM converts between the camera's optical frame and its robot frame:

- Camera optical frame (KITTI poses, stereo measurements): x right, y down, z forward.
- Robot frame (REP-103, TUM files, everything inside NeoSLAM): x forward, y left, z up.

The robot frame's origin is the left camera's optical centre, so the two frames differ by a rotation only:
a KITTI pose T_c0_ci (camera i in the first camera's frame) becomes T_w_ri = S T_c0_ci S^-1 with S the axis
permutation below, and the world frame of a KITTI sequence is the first robot pose (x forward, z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "ROBOT_FROM_CAMERA",
    "camera_poses_to_robot",
    "robot_poses_to_camera",
    "camera_points_to_robot",
    "robot_points_to_camera",
    "make_pose",
    "invert_pose",
    "relative_pose",
    "pose_from_quaternion",
    "quaternion_from_pose",
    "rotation_angle",
    "yaw_of",
    "yaw_pitch_roll",
    "is_rotation_matrix",
    "transform_points",
    "SimilarityTransform",
    "umeyama_alignment",
    "is_single_place",
    "interpolated_pose",
    "integrate_body_velocities",
    "body_velocities",
    "planar_motion",
    "fit_yaw_translation",
    "least_squares_yaw",
]


def make_pose(rotation: np.ndarray | Rotation, translation: np.ndarray) -> np.ndarray:
    """4x4 homogeneous matrix from a rotation (matrix or Rotation) and a translation."""
    pose = np.eye(4)
    pose[:3, :3] = rotation.as_matrix() if isinstance(rotation, Rotation) else rotation
    pose[:3, 3] = translation
    return pose


def invert_pose(pose: np.ndarray) -> np.ndarray:
    """Inverse of one (4, 4) or a stack (n, 4, 4) of rigid transforms."""
    rot_t = np.swapaxes(pose[..., :3, :3], -1, -2)
    inverse = np.zeros_like(pose)
    inverse[..., :3, :3] = rot_t
    inverse[..., :3, 3] = -np.einsum("...ij,...j->...i", rot_t, pose[..., :3, 3])
    inverse[..., 3, 3] = 1.0
    return inverse


def relative_pose(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """T_a_b = T_a^-1 T_b: pose b seen from pose a (stacks broadcast)."""
    return invert_pose(pose_a) @ pose_b


def pose_from_quaternion(translation: np.ndarray, quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Stack of poses from (n, 3) translations and (n, 4) unit quaternions in TUM order (x, y, z, w)."""
    translation = np.atleast_2d(translation)
    poses = np.tile(np.eye(4), (len(translation), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(np.atleast_2d(quaternion_xyzw)).as_matrix()
    poses[:, :3, 3] = translation
    return poses


def quaternion_from_pose(poses: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w) with w >= 0 from (n, 4, 4) poses."""
    quat = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    return np.where(quat[:, 3:4] < 0, -quat, quat)


def rotation_angle(rotation: np.ndarray) -> np.ndarray:
    """Angle in radians of one (3, 3) or a stack of rotation matrices, robust near 0 and pi."""
    trace = np.trace(rotation, axis1=-2, axis2=-1)
    return np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))


def yaw_pitch_roll(poses: np.ndarray) -> np.ndarray:
    """(n, 3) intrinsic z-y'-x'' Euler angles (yaw, pitch, roll) of REP-103 robot poses."""
    return Rotation.from_matrix(poses[..., :3, :3]).as_euler("ZYX")


def yaw_of(poses: np.ndarray) -> np.ndarray:
    """Heading about the world z axis (up), radians."""
    return np.arctan2(poses[..., 1, 0], poses[..., 0, 0])


def is_rotation_matrix(rotation: np.ndarray, tolerance: float) -> bool:
    """True when R R^T = I within `tolerance` (max abs entry) and det R > 0."""
    error = np.abs(rotation @ rotation.T - np.eye(3)).max()
    return bool(error <= tolerance and np.linalg.det(rotation) > 0)


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (n, 3) points."""
    return points @ pose[:3, :3].T + pose[:3, 3]


@dataclass(frozen=True, slots=True)
class SimilarityTransform:
    """x' = s R x + t; with s = 1 a rigid SE(3) transform."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0

    def apply_to_points(self, points: np.ndarray) -> np.ndarray:
        return self.scale * points @ self.rotation.T + self.translation

    def apply_to_poses(self, poses: np.ndarray) -> np.ndarray:
        """Move poses T_world_robot into the target world; positions are scaled, orientations are not."""
        moved = poses.copy()
        moved[..., :3, :3] = self.rotation @ poses[..., :3, :3]
        moved[..., :3, 3] = self.apply_to_points(poses[..., :3, 3])
        return moved

    def as_matrix(self) -> np.ndarray:
        return make_pose(self.scale * self.rotation, self.translation)


def interpolated_pose(times: np.ndarray, poses: np.ndarray, stamp: int, tolerance: int) -> np.ndarray | None:
    """The pose at `stamp` from poses at sorted integer `times` (same unit): the sample at that time, or the
    interpolation of the two around it (position linearly, rotation along the shortest arc) when both lie within
    `tolerance` of it; None otherwise."""
    after = int(np.searchsorted(times, stamp))
    if after < len(times) and times[after] == stamp:
        return poses[after]
    if not (0 < after < len(times)) or stamp - times[after - 1] > tolerance or times[after] - stamp > tolerance:
        return None
    t0, t1 = times[after - 1], times[after]
    share = (stamp - t0) / (t1 - t0)
    start, end = poses[after - 1], poses[after]
    pose = np.eye(4)
    pose[:3, 3] = start[:3, 3] + share * (end[:3, 3] - start[:3, 3])
    turn = Rotation.from_matrix(start[:3, :3].T @ end[:3, :3]).as_rotvec()
    pose[:3, :3] = start[:3, :3] @ Rotation.from_rotvec(share * turn).as_matrix()
    return pose


def is_single_place(points: np.ndarray) -> bool:
    """True when (n, 3) points do not spread beyond float rounding of their magnitude: all at one place."""
    points = np.asarray(points, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):  # huge coordinates spread to inf: not one place
        spread = np.sqrt(((points - points.mean(axis=0)) ** 2).sum(axis=1).mean())
        return bool(spread <= 1e-9 * (1.0 + np.abs(points).max()))


def umeyama_alignment(source: np.ndarray, target: np.ndarray, with_scale: bool = False) -> SimilarityTransform:
    """Least-squares s, R, t with target ≈ s R source + t (Umeyama 1991), for (n, 3) point sets, n >= 3.

    With scale, point sets that do not move are refused (ValueError): the scale is the ratio of their spreads,
    0 or undefined for a set at one place, which would shrink any estimate onto a still truth (an error of 0).
    """
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(f"need two (n, 3) point sets of equal shape, got {source.shape} and {target.shape}")
    if len(source) < 3:
        raise ValueError("alignment needs at least 3 points")
    if with_scale and (is_single_place(source) or is_single_place(target)):
        raise ValueError("degenerate alignment: a point set is at one place, so the scale is undefined")
    mean_src, mean_tgt = source.mean(axis=0), target.mean(axis=0)
    src_c, tgt_c = source - mean_src, target - mean_tgt
    covariance = tgt_c.T @ src_c / len(source)
    if not np.isfinite(covariance).all():
        # LAPACK's SVD can loop forever on inf or NaN (coordinates near 1e308 overflow here): refuse instead.
        raise ValueError("alignment overflows: the coordinates are too large")
    u, singular, vt = np.linalg.svd(covariance)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:  # reflection: flip the weakest axis
        sign[2, 2] = -1.0
    rotation = u @ sign @ vt
    scale = 1.0
    if with_scale:
        variance = (src_c**2).sum() / len(source)
        scale = float(np.trace(np.diag(singular) @ sign) / variance)
    translation = mean_tgt - scale * rotation @ mean_src
    return SimilarityTransform(rotation, translation, scale)


def integrate_body_velocities(
    linear_velocity: np.ndarray, angular_velocity: np.ndarray, timestamps: np.ndarray, start: np.ndarray | None = None
) -> np.ndarray:
    """Dead reckoning: T_i = T_{i-1} [exp(ω_i dt_i), v_i dt_i] with body-frame velocities of step i-1 -> i.

    Row 0 of the velocities is ignored (there is no previous frame); the result starts at `start` (identity).
    """
    count = len(timestamps)
    poses = np.empty((count, 4, 4))
    poses[0] = np.eye(4) if start is None else start
    if count == 1:
        return poses
    dt = np.diff(timestamps)[:, None]
    steps = np.tile(np.eye(4), (count - 1, 1, 1))
    steps[:, :3, :3] = Rotation.from_rotvec(angular_velocity[1:] * dt).as_matrix()
    steps[:, :3, 3] = linear_velocity[1:] * dt
    for i in range(1, count):
        poses[i] = poses[i - 1] @ steps[i - 1]
    return poses


def body_velocities(poses: np.ndarray, timestamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of integrate_body_velocities: (n, 3) linear and angular body velocities, row 0 zero."""
    steps = relative_pose(poses[:-1], poses[1:])
    dt = np.diff(timestamps)[:, None]
    linear = np.zeros((len(poses), 3))
    angular = np.zeros((len(poses), 3))
    linear[1:] = steps[:, :3, 3] / dt
    angular[1:] = Rotation.from_matrix(steps[:, :3, :3]).as_rotvec() / dt
    return linear, angular


def planar_motion(previous: np.ndarray, current: np.ndarray) -> tuple[float, float, float]:
    """The 4-DoF motion NeuroSLAM integrates between two poses T_world_robot: horizontal distance (m), negative
    when the robot moved backwards (against its previous heading), yaw change (rad, wrapped to [-pi, pi)) and
    vertical change (m). The grid cells move along the heading by this distance, so a robot that reverses moves
    them back, not on."""
    step = current[:3, 3] - previous[:3, 3]
    yaw_change = float(yaw_of(current) - yaw_of(previous))
    yaw_change = (yaw_change + np.pi) % (2 * np.pi) - np.pi
    heading = previous[:2, 0]  # the robot's x axis: forward
    direction = -1.0 if float(step[:2] @ heading) < 0 else 1.0
    return direction * float(np.hypot(step[0], step[1])), yaw_change, float(step[2])


def least_squares_yaw(source: np.ndarray, target: np.ndarray) -> float:
    """The yaw (rad) of the rotation that best takes (n, 2) ground-plane points onto (n, 2) others, both sets
    centred on their means (least squares, closed form)."""
    cross = (source[:, 0] * target[:, 1] - source[:, 1] * target[:, 0]).sum()
    return float(np.arctan2(cross, (source * target).sum()))


def fit_yaw_translation(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """4-DoF least squares (rotation about z, translation): the (4, 4) T with target ≈ T source, for (n, 3) points.

    Gravity is known to a robot on the road, so only yaw is fitted: the fit stays well posed for two points or for
    objects in a line along a street, where a full 3-D rotation is not.
    """
    if source.shape != target.shape or len(source) < 2:
        raise ValueError(f"need two (n >= 2, 3) point sets of equal shape, got {source.shape} and {target.shape}")
    mean_src, mean_tgt = source.mean(axis=0), target.mean(axis=0)
    yaw = least_squares_yaw(source[:, :2] - mean_src[:2], target[:, :2] - mean_tgt[:2])
    rotation = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return make_pose(rotation, mean_tgt - rotation @ mean_src)


# Rows: robot x = camera z, robot y = -camera x, robot z = -camera y.
ROBOT_FROM_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_S = np.eye(4)
_S[:3, :3] = ROBOT_FROM_CAMERA
_S_INV = _S.T.copy()


def camera_poses_to_robot(camera_poses: np.ndarray) -> np.ndarray:
    """(n, 4, 4) KITTI camera poses T_c0_ci to robot poses T_w_ri."""
    return _S @ camera_poses @ _S_INV


def robot_poses_to_camera(robot_poses: np.ndarray) -> np.ndarray:
    """(n, 4, 4) robot poses T_w_ri to KITTI camera poses T_c0_ci (inverse of camera_poses_to_robot)."""
    return _S_INV @ robot_poses @ _S


def camera_points_to_robot(points: np.ndarray) -> np.ndarray:
    """(n, 3) points in the camera optical frame to the robot frame."""
    return points @ ROBOT_FROM_CAMERA.T


def robot_points_to_camera(points: np.ndarray) -> np.ndarray:
    """(n, 3) points in the robot frame to the camera optical frame."""
    return points @ ROBOT_FROM_CAMERA
