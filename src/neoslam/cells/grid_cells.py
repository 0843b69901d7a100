"""Grid cells (GCN): a 3-D continuous attractor network that path-integrates the robot's motion (paper 3.3).

The activity lives on a torus of `dims` cells (x, y, z: array axes 0, 1, 2, all cyclic). Each frame the network
settles (local excitation with the Gaussian of eq. 6, local inhibition, global inhibition, normalisation) and is
then moved by the frame's motion, in NeuroSLAM's order (notes 3.2, 3.3). Heading 0 moves the packet along +x,
heading pi/2 along +y: REP-103, counter-clockwise about z (NeuroSLAM's heading 0 moves along its 2nd index).

Unlike NeuroSLAM, motion enters in metres through `metres_per_cell` (their transV is used as cells per step,
quirk 4), the sub-cell shift is a convex blend of integer shifts along each axis, valid for any heading and
speed (their quarter-turn bilinear scheme is convex only up to one cell per step), and the packet settles in
its own sub-cell frame (see `settle_and_move`), so slow motion is not lost to the lattice.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from neoslam.cells.attractor import (
    circular_difference,
    circular_shift,
    gaussian_kernel,
    inject_energy,
    nearest_cell,
    packet_centre,
    peak_cell,
    step_network,
    transfer_function,
)
from neoslam.config import GridCellConfig

__all__ = ["GridCells", "circular_difference"]


class GridCells:
    """3-D grid-cell attractor: `step(horizontal_m, heading_rad, vertical_m)` once per frame."""

    def __init__(self, config: GridCellConfig | None = None) -> None:
        self.config = config or GridCellConfig()
        self.dims: tuple[int, int, int] = tuple(self.config.dims)
        excitation = gaussian_kernel(self.config.excitation_size, self.config.excitation_sigma)
        inhibition = gaussian_kernel(self.config.inhibition_size, self.config.inhibition_sigma)
        dtype = np.dtype(self.config.dtype)
        self._transfer = transfer_function(self.dims, excitation, inhibition).astype(dtype)
        self._activity = np.zeros(self.dims, dtype=dtype)
        self._centre: np.ndarray | None = None
        self.reset()

    @property
    def start_cell(self) -> tuple[int, int, int]:
        """The centre cell, where NeuroSLAM starts (floor(dim / 2) per axis)."""
        return tuple(n // 2 for n in self.dims)

    @property
    def cell_size_m(self) -> np.ndarray:
        """Metres of motion per cell along x, y, z: an unwrapped cell displacement times this is metres."""
        horizontal = self.config.metres_per_cell
        return np.array([horizontal, horizontal, self.config.metres_per_cell_vertical])

    @property
    def activity(self) -> np.ndarray:
        """The (x, y, z) activity, summing to 1 after every step (a read-only view)."""
        view = self._activity.view()
        view.flags.writeable = False
        return view

    @property
    def peak(self) -> tuple[int, int, int]:
        """The most active cell."""
        return peak_cell(self._activity)

    @property
    def centre(self) -> np.ndarray:
        """Sub-cell packet centre (x, y, z) in cell units, each in [0, dim): circular mean around the peak."""
        if self._centre is None:
            self._centre = packet_centre(self._activity, self.config.packet_size)
        return self._centre.copy()

    def reset(self, cell: Sequence[float] | None = None) -> None:
        """A single active cell (the centre cell by default), as NeuroSLAM starts."""
        self._activity.fill(0.0)
        self._activity[nearest_cell(self.start_cell if cell is None else cell, self.dims)] = 1.0
        self._centre = None

    def displacement_cells(self, horizontal_m: float, heading_rad: float, vertical_m: float) -> np.ndarray:
        """Cells to move along x, y, z for a horizontal distance along a heading and a vertical change."""
        along = horizontal_m / self.config.metres_per_cell
        vertical = vertical_m / self.config.metres_per_cell_vertical
        return np.array([along * math.cos(heading_rad), along * math.sin(heading_rad), vertical])

    def step(self, horizontal_m: float, heading_rad: float, vertical_m: float) -> None:
        """One frame: attractor dynamics, then path integration (settle() then path_integrate(), in one pass)."""
        self._update(self.displacement_cells(horizontal_m, heading_rad, vertical_m))

    def settle(self) -> None:
        """Attractor dynamics alone: local excitation (eq. 6), local and global inhibition, normalisation."""
        self._update(None)

    def path_integrate(self, horizontal_m: float, heading_rad: float, vertical_m: float) -> None:
        """Move the activity by the motion, a fractional number of cells per axis (cyclic)."""
        displacement = self.displacement_cells(horizontal_m, heading_rad, vertical_m)
        self._activity = circular_shift(self._activity, [displacement], self.config.shift_kernel)
        self._centre = None

    def inject(self, cell: Sequence[float], energy: float | None = None) -> None:
        """Add energy (default `injection_energy`) at the cell nearest to a cell state (x, y, z), wrapped."""
        self.inject_pattern(np.array([nearest_cell(cell, self.dims)]), np.ones(1), energy)

    def inject_pattern(self, cells: np.ndarray, weights: np.ndarray, energy: float | None = None) -> None:
        """Add energy (default `injection_energy`) over integer cells (k, 3) in proportion to weights (k,):
        a recalled sparse activity pattern."""
        energy = self.config.injection_energy if energy is None else energy
        inject_energy(self._activity, cells, weights, energy)
        self._centre = None

    def _update(self, displacement: np.ndarray | None) -> None:
        centre = self.centre if self.config.settle_in_packet_frame else None
        self._activity = step_network("grid_cells", self._activity, self._transfer, self.config, centre, displacement)
        self._centre = None
