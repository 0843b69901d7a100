"""Head-direction cells (HDN): a 1-D continuous attractor ring that integrates yaw (paper 3.3: 36 cells).

Cell i prefers yaw i * 2 pi / cells, so cell 0 is yaw 0 (the start) and yaw grows counter-clockwise about z
(REP-103). The dynamics are the grid cells' in 1-D (notes 3.2); path integration shifts the ring by
yaw change / (2 pi / cells) cells. The paper's ring replaces NeuroSLAM's yaw x height network, whose even 8-cell
excitatory kernel biases the packet half a cell and nearly stops slow positive turns (quirks 10, 13): our
kernels have odd extents, and the packet settles in its own sub-cell frame (attractor.settle_and_move), without
which even a symmetric 36-cell ring is pinned to its cells and misses turns slower than about 0.005 rad/frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from neoslam.cells.attractor import (
    circular_shift,
    gaussian_kernel,
    inject_energy,
    nearest_cell,
    packet_centre,
    peak_cell,
    step_network,
    transfer_function,
)
from neoslam.config import HeadDirectionConfig

__all__ = ["HeadDirectionCells", "wrap_angle"]


def wrap_angle(angle: float) -> float:
    """The angle in [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class HeadDirectionCells:
    """Ring of head-direction cells for yaw: `step(yaw_change_rad)` once per frame."""

    def __init__(self, config: HeadDirectionConfig | None = None) -> None:
        self.config = config or HeadDirectionConfig()
        self.cells = self.config.cells
        self.cell_angle = 2.0 * math.pi / self.cells
        excitation = gaussian_kernel(self.config.excitation_size, self.config.excitation_sigma)
        inhibition = gaussian_kernel(self.config.inhibition_size, self.config.inhibition_sigma)
        dtype = np.dtype(self.config.dtype)
        self._transfer = transfer_function((self.cells,), excitation, inhibition).astype(dtype)
        self._activity = np.zeros(self.cells, dtype=dtype)
        self._centre: float | None = None
        self.reset()

    @property
    def activity(self) -> np.ndarray:
        """The ring's activity, summing to 1 after every step (a read-only view)."""
        view = self._activity.view()
        view.flags.writeable = False
        return view

    @property
    def peak(self) -> int:
        """The most active cell."""
        return peak_cell(self._activity)[0]

    @property
    def centre(self) -> float:
        """Sub-cell packet centre in cell units in [0, cells): circular mean around the peak."""
        if self._centre is None:
            self._centre = float(packet_centre(self._activity, self.config.packet_size)[0])
        return self._centre

    @property
    def heading(self) -> float:
        """Decoded yaw in radians, in [-pi, pi)."""
        return wrap_angle(self.centre * self.cell_angle)

    def cell_of(self, yaw_rad: float) -> float:
        """The (fractional) cell state of a yaw, in [0, cells)."""
        cell = (yaw_rad / self.cell_angle) % self.cells
        return 0.0 if cell >= self.cells else cell  # -1e-17 % cells rounds to cells

    def reset(self, cell: float = 0.0) -> None:
        """A single active cell; cell 0 (yaw 0) by default, so the ring starts at the map's heading.

        NeuroSLAM starts at cell 1 of 36, which decodes to 10 degrees while its map starts at 0 (quirk 10).
        """
        self._activity.fill(0.0)
        self._activity[nearest_cell([cell], (self.cells,))] = 1.0
        self._centre = None

    def step(self, yaw_change_rad: float) -> None:
        """One frame: attractor dynamics, then path integration (settle() then path_integrate(), in one pass)."""
        self._update(np.array([yaw_change_rad / self.cell_angle]))

    def settle(self) -> None:
        """Attractor dynamics alone: local excitation and inhibition, global inhibition, normalisation."""
        self._update(None)

    def path_integrate(self, yaw_change_rad: float) -> None:
        """Turn the ring by a yaw change: a shift of yaw / (2 pi / cells) cells."""
        shift = [np.array([yaw_change_rad / self.cell_angle])]
        self._activity = circular_shift(self._activity, shift, self.config.shift_kernel)
        self._centre = None

    def inject(self, cell: float, energy: float | None = None) -> None:
        """Add energy (default `injection_energy`) at the cell nearest to a cell state, wrapped."""
        self.inject_pattern(np.array([nearest_cell([cell], (self.cells,))]), np.ones(1), energy)

    def inject_pattern(
        self, cells: Sequence[int] | np.ndarray, weights: np.ndarray, energy: float | None = None
    ) -> None:
        """Add energy (default `injection_energy`) over integer cells in proportion to weights (k,)."""
        energy = self.config.injection_energy if energy is None else energy
        inject_energy(self._activity, np.asarray(cells).reshape(-1, 1), weights, energy)
        self._centre = None

    def _update(self, displacement: np.ndarray | None) -> None:
        centre = np.array([self.centre]) if self.config.settle_in_packet_frame else None
        self._activity = step_network(
            "head_direction", self._activity, self._transfer, self.config, centre, displacement
        )
        self._centre = None
