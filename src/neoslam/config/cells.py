"""The neural cells: 3-D grid cells, head-direction cells, object-vector cells and the Hebbian memory."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator

from neoslam.config.base import Section

__all__ = ["GridCellConfig", "HeadDirectionConfig", "ObjectVectorConfig", "HebbianConfig"]


# Cells along one grid-cell axis: fewer than 4 leave no room for a packet (below 3 the activity dies at once);
# 128^3 cells already cost ~50 ms a frame.
GridAxis = Annotated[int, Field(ge=4, le=128)]


def _odd_extent(size: int) -> int:
    """A kernel extent must be odd: an even one has no centre cell and biases the packet by half a cell."""
    if size % 2 == 0:
        raise ValueError(f"must be odd (a centre cell and as many cells each side), got {size}")
    return size


class GridCellConfig(Section):
    """3-D grid-cell continuous attractor network (paper 3.3, eq. 6; NeuroSLAM defaults)."""

    dims: tuple[GridAxis, GridAxis, GridAxis] = Field((36, 36, 36), description="cells along x, y, z (all cyclic)")
    excitation_size: int = Field(7, gt=0, le=99, description="excitatory kernel extent, cells")
    excitation_sigma: float = Field(1.5, ge=0.01, le=100, description="δx = δy = δz of eq. 6, cells")
    inhibition_size: int = Field(5, gt=0, le=99, description="inhibitory kernel extent, cells")
    inhibition_sigma: float = Field(2.0, ge=0.01, le=100, description="inhibitory kernel σ, cells")
    global_inhibition: float = Field(2e-4, ge=0, le=1, description="subtracted from every cell each step")
    injection_energy: float = Field(0.1, ge=0, le=10, description="energy added at a recalled cell state")
    packet_size: int = Field(4, ge=0, le=64, description="decode window = peak ± packet_size cells")
    metres_per_cell: float = Field(
        8.0,
        ge=0.01,
        le=1000,
        description="horizontal metres of motion per cell (8: the paper's 7-bin check of loop candidates then "
        "admits 56 m of odometry drift)",
    )
    metres_per_cell_vertical: float = Field(1.0, ge=0.01, le=1000, description="vertical metres of motion per cell")
    shift_kernel: Literal["zero-skew", "linear"] = Field(
        "zero-skew",
        description="sub-cell path-integration shift: 3-tap zero-skew blend, or NeuroSLAM's 2-tap linear one "
        "(under-integrates slow motion by up to 10 %)",
    )
    settle_in_packet_frame: bool = Field(
        True, description="settle with the packet moved onto its nearest cell: no lattice pinning (NeuroSLAM: no)"
    )
    dtype: Literal["float32", "float64"] = Field("float32", description="activity precision (float32: faster)")

    _odd_kernels = field_validator("excitation_size", "inhibition_size")(_odd_extent)


class HeadDirectionConfig(Section):
    """1-D ring of head-direction cells for yaw (paper 3.3: 36 cells)."""

    cells: int = Field(36, ge=4, le=3600, description="cells around the ring (10 degrees each)")
    excitation_size: int = Field(7, gt=0, le=99, description="excitatory kernel extent, cells")
    excitation_sigma: float = Field(1.9, ge=0.01, le=100, description="excitatory σ, cells (NeuroSLAM)")
    inhibition_size: int = Field(5, gt=0, le=99, description="inhibitory kernel extent, cells")
    inhibition_sigma: float = Field(3.0, ge=0.01, le=100, description="inhibitory σ, cells (NeuroSLAM)")
    global_inhibition: float = Field(2e-4, ge=0, le=1, description="subtracted from every cell each step")
    injection_energy: float = Field(0.1, ge=0, le=10, description="energy added at a recalled cell state")
    packet_size: int = Field(5, ge=0, le=1800, description="decode window = peak ± packet_size cells")
    shift_kernel: Literal["zero-skew", "linear"] = Field(
        "zero-skew",
        description="sub-cell path-integration shift: 3-tap zero-skew blend, or NeuroSLAM's 2-tap linear one",
    )
    settle_in_packet_frame: bool = Field(
        True, description="settle with the packet moved onto its nearest cell: no lattice pinning (NeuroSLAM: no)"
    )
    dtype: Literal["float32", "float64"] = Field("float32", description="activity precision (float32: faster)")

    _odd_kernels = field_validator("excitation_size", "inhibition_size")(_odd_extent)


class ObjectVectorConfig(Section):
    """Object-vector cells network (paper 3.4, eq. 7-13)."""

    peak_rate: float = Field(1.2, ge=-1000, le=1000, description="a of eq. 7, Hz")
    baseline_rate: float = Field(0.0, ge=-1000, le=1000, description="b of eq. 7, Hz")
    field_sigma: float = Field(5.0, ge=0.01, le=1e4, description="σ of eq. 10 along the preferred direction, m")
    field_sigma_across: float | None = Field(
        None,
        ge=0.01,
        le=1e4,
        description="σ across the preferred direction, m (elliptical field); None: equal, as eq. 10",
    )
    preferred_distance: float = Field(10.0, ge=0, le=1e4, description="distance of the field's centre, m")
    preferred_direction: float = Field(
        0.0, ge=-10, le=10, description="allocentric direction of the field's centre, rad (φ, eq. 9)"
    )
    distance_scale: float = Field(
        10.0,
        ge=0.01,
        le=1e4,
        description="inputs d are divided by this, m: about 2σ, so the field spans as much of d as of φ",
    )
    direction_encoding: Literal["cos_sin", "raw"] = Field(
        "cos_sin", description="φ as (cos φ, sin φ), continuous across ±π (fits better), or raw radians / π"
    )
    hidden_units: int = Field(32, gt=0, le=4096, description="N hidden ELU units (eq. 12)")
    optimizer: Literal["adam", "sgd"] = Field(
        "adam", description="weight optimiser: adam, or plain SGD (which hardly learns in 10 epochs at lr 0.001)"
    )
    learning_rate: float = Field(0.001, gt=0, le=10, description="optimiser learning rate (paper: 0.001)")
    batch_size: int = Field(
        1, gt=0, le=100_000, description="object vectors per update; 1: one per observation, as eq. 13"
    )
    epochs: int = Field(10, gt=0, le=1000, description="training epochs (paper: 10)")
    keyframes_per_epoch: int = Field(20, gt=0, le=100_000, description="keyframes per training epoch (paper: 20)")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="weight initialisation and shuffling seed")


class HebbianConfig(Section):
    """Keyframe-to-cell associations (eq. 14)."""

    learning_rate: float = Field(1.0, gt=0, le=1e6, description="τ of eq. 14")
    sparsity: float = Field(0.1, gt=0, le=1, description="store only cells above this fraction of the peak")
    recall_gain: float = Field(
        20.0,
        ge=0,
        description="a recall injects this many times the cells' injection_energy (NeuroSLAM's energy per frame of "
        "a re-seen view): 2.0 against a packet of 1 by default, enough for a verified closure to re-anchor the cells",
    )
    recall_on: Literal["detected", "accepted"] = Field(
        "accepted",
        description="which closures recall their place in the cells: accepted, only those the experience map's "
        "closure gate accepted (the paper's order: a false closure cannot re-anchor the cells and so open the gate "
        "for the next); detected, every one the loop detector accepts (NeuroSLAM's local-view calibration)",
    )
