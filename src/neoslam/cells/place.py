"""A place relative to a stored one, in the cells' own units: what recalling a place (Hebbian recall) or
relocalising at it (a later session) moves the cells by."""

from __future__ import annotations

import numpy as np

from neoslam.cells.grid_cells import GridCells
from neoslam.cells.head_direction import HeadDirectionCells

__all__ = ["offset_in_cells"]


def offset_in_cells(
    heading_rad: float, stored_pose: np.ndarray, robot: np.ndarray, grid: GridCells, head: HeadDirectionCells
) -> tuple[np.ndarray, float]:
    """Where the robot is (`robot`, T_stored_robot) from a stored place whose cells faced `heading_rad`, in cells:
    the grid-cell shift (x, y, z) and the head-direction turn. The stored heading, not the odometry's there, turns
    the offset into the cells' frame (after a recall the two differ by the drift); the stored pose's tilt gives the
    height change."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    x, y, _ = robot[:3, 3]
    offset = np.array([c * x - s * y, s * x + c * y, (stored_pose[:3, :3] @ robot[:3, 3])[2]])
    turn = float(np.arctan2(robot[1, 0], robot[0, 0])) / head.cell_angle
    return offset / grid.cell_size_m, turn
