"""The one place where NeoSLAM converts between the camera's optical frame and its robot frame.

- Camera optical frame (KITTI poses, stereo measurements): x right, y down, z forward.
- Robot frame (REP-103, TUM files, everything inside NeoSLAM): x forward, y left, z up.

The robot frame's origin is the left camera's optical centre, so the two frames differ by a rotation only:
a KITTI pose T_c0_ci (camera i in the first camera's frame) becomes T_w_ri = S T_c0_ci S^-1 with S the axis
permutation below, and the world frame of a KITTI sequence is the first robot pose (x forward, z up).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ROBOT_FROM_CAMERA",
    "camera_poses_to_robot",
    "robot_poses_to_camera",
    "camera_points_to_robot",
    "robot_points_to_camera",
]

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
