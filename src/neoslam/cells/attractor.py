"""Continuous-attractor maths shared by the grid cells (3-D) and the head-direction cells (1-D ring).

One attractor update follows NeuroSLAM (notes 3.2): local excitation with the Gaussian kernel of eq. 6, local
inhibition A <- A - K_inh * A, global inhibition (subtract, clip at 0), normalisation to sum 1. Every axis is
cyclic, so the convolutions are circular; both are linear, so they run as one product of separable spectra
(an FFT of the whole volume), never as a dense 3-D convolution. Path integration moves the activity by a
fractional number of cells per axis with a convex blend of integer circular shifts.

Two departures from NeuroSLAM keep path integration faithful to the odometry (see shift_taps and
settle_and_move): the blend has no skew (NeuroSLAM's linear one makes the packet lag: gain 0.90-0.96), and the
packet settles in its own sub-cell frame (on the lattice it is pinned to cells and misses slow motion).

Cells are 0-based; a decoded centre is in cell units in [0, n) per axis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal, Protocol

import numpy as np
import scipy.fft
from scipy.ndimage import correlate1d

from neoslam.errors import ConfigError

__all__ = [
    "ShiftKernel",
    "gaussian_kernel",
    "transfer_function",
    "attractor_dynamics",
    "settle_and_move",
    "step_network",
    "shift_taps",
    "circular_shift",
    "nearest_cell",
    "inject_energy",
    "peak_cell",
    "circular_mean",
    "packet_centre",
    "circular_difference",
]

# "zero-skew": three taps whose blend has the displacement as mean and no third central moment (default).
# "linear": NeuroSLAM's two-tap linear interpolation; its skewed blend makes the attractor under-integrate slow
# motion (measured: gain 0.90 at 0.02 cells/step, 0.96 at 0.25; NeuroSLAM notes quirk 13: 0.91-0.945).
ShiftKernel = Literal["zero-skew", "linear"]


def gaussian_kernel(size: int, sigma: float) -> np.ndarray:
    """1-D factor of eq. 6 on offsets -size//2 ... size//2, normalised to sum 1 (the 1/(σ√2π) cancels)."""
    if size < 1 or size % 2 == 0:
        # An even extent has no centre cell: NeuroSLAM's 8-cell kernel biases the packet by half a cell and
        # makes it resist motion in one direction (notes quirks 10 and 13).
        raise ValueError(f"kernel extent must be odd and positive, got {size}")
    offsets = np.arange(size) - size // 2
    kernel = np.exp(-(offsets**2) / (2.0 * sigma**2))
    return kernel / kernel.sum()


def _circular_spectrum(kernel: np.ndarray, cells: int) -> np.ndarray:
    """DFT of a centred odd kernel laid on a ring of `cells` (real: the kernel is symmetric)."""
    ring = np.zeros(cells)
    offsets = np.arange(len(kernel)) - len(kernel) // 2
    np.add.at(ring, offsets % cells, kernel)  # a kernel wider than the ring wraps onto itself
    return np.fft.fft(ring).real


def _separable_spectrum(dims: Sequence[int], kernel: np.ndarray) -> np.ndarray:
    """Spectrum (rfftn layout) of the separable kernel kernel(u) kernel(v) ... on a torus of shape `dims`."""
    spectrum = np.ones(())
    for axis, cells in enumerate(dims):
        factor = _circular_spectrum(kernel, cells)
        if axis == len(dims) - 1:
            factor = factor[: cells // 2 + 1]  # rfftn keeps half of the last axis
        shape = [1] * len(dims)
        shape[axis] = len(factor)
        spectrum = spectrum * factor.reshape(shape)
    return spectrum


def transfer_function(dims: Sequence[int], excitation: np.ndarray, inhibition: np.ndarray) -> np.ndarray:
    """Spectrum of A -> B - K_inh * B with B = K_exc * A: local excitation (eq. 6) then local inhibition."""
    excite = _separable_spectrum(dims, excitation)
    return excite * (1.0 - _separable_spectrum(dims, inhibition))


def attractor_dynamics(
    activity: np.ndarray,
    transfer: np.ndarray,
    global_inhibition: float,
    pre_shift: Sequence[float] | None = None,
    kernel: ShiftKernel = "zero-skew",
) -> np.ndarray:
    """One attractor update: local excitation and inhibition, global inhibition (clip at 0), sum to 1.

    `pre_shift` first moves the activity by that many cells per axis (as circular_shift does); in the Fourier
    domain it costs one product instead of a pass over the volume per axis.
    """
    spectrum = scipy.fft.rfftn(activity)
    spectrum *= transfer
    if pre_shift is not None:
        for axis, cells in enumerate(pre_shift):
            spectrum *= _shift_factor(activity.shape, axis, *shift_taps(float(cells), kernel)).astype(spectrum.dtype)
    shaped = scipy.fft.irfftn(spectrum, s=activity.shape)
    shaped -= global_inhibition
    np.maximum(shaped, 0.0, out=shaped)
    total = shaped.sum()
    if not total > 0:
        # Only a spread-out activity (no cell above its neighbourhood) dies like this; nothing can recover it.
        raise FloatingPointError("attractor activity vanished: no cell survived the inhibition")
    shaped /= total
    return shaped


def settle_and_move(
    activity: np.ndarray,
    transfer: np.ndarray,
    global_inhibition: float,
    kernel: ShiftKernel,
    packet_centre: np.ndarray | None = None,
    displacement: Sequence[float] | None = None,
) -> np.ndarray:
    """One frame of a network: attractor dynamics, then path integration by `displacement` cells per axis.

    With `packet_centre` (the decoded centre), the dynamics run with the packet moved onto its nearest cell and
    moved back after. On a lattice the clipped packet has preferred sub-cell positions: settled where it is, a
    packet between cells drifts towards one (up to 0.4 cells at rest on the 36-cell ring) and motion slower
    than that drift is lost (a turn of 0.005 rad/frame does not move the ring at all). In the packet's own
    frame the dynamics are the same at every sub-cell position, as in the continuous model; with zero-skew
    shifts the round trip is a symmetric blur, so settling keeps the centre where it was.
    """
    pre_shift = None
    after: list[Sequence[float]] = []
    if packet_centre is not None:
        offset = packet_centre - np.floor(packet_centre + 0.5)
        pre_shift = -offset
        after.append(offset)
    if displacement is not None:
        after.append(displacement)
    settled = attractor_dynamics(activity, transfer, global_inhibition, pre_shift, kernel)
    return circular_shift(settled, after, kernel) if after else settled


class _NetworkConfig(Protocol):
    global_inhibition: float
    shift_kernel: ShiftKernel
    inhibition_size: int
    inhibition_sigma: float


def step_network(
    section: str,
    activity: np.ndarray,
    transfer: np.ndarray,
    config: _NetworkConfig,
    packet_centre: np.ndarray | None,
    displacement: Sequence[float] | None,
) -> np.ndarray:
    """`settle_and_move` with a network's config. Activity that vanishes is a ConfigError naming the values: only
    the configuration does that (an inhibition that outweighs the excitation)."""
    try:
        return settle_and_move(
            activity, transfer, config.global_inhibition, config.shift_kernel, packet_centre, displacement
        )
    except FloatingPointError:
        raise ConfigError(
            f"{section}: the attractor activity vanished, no cell survived the inhibition (global_inhibition "
            f"{config.global_inhibition:g}, inhibition_size {config.inhibition_size}, inhibition_sigma "
            f"{config.inhibition_sigma:g}): weaken it"
        ) from None


def shift_taps(displacement: float, kernel: ShiftKernel = "zero-skew") -> tuple[int, np.ndarray]:
    """First integer offset and weights of the convex blend of consecutive circular shifts that moves by
    `displacement` cells: activity' = sum_k weights[k] * roll(activity, first + k).

    Both blends have the displacement as their mean. The linear one is skewed, and the attractor's sharpening
    pulls a skewed packet towards its mode, i.e. back; the zero-skew one is the unique 3-tap convex blend with
    mean r and third central moment 0 (r = offset from the nearest cell, |r| <= 1/2). It equals the linear
    blend at half cells and is continuous in the displacement; its price is a little symmetric spreading
    (variance (1 - r^2)/3 cells^2), which the attractor removes.
    """
    if not math.isfinite(displacement):
        raise ValueError(f"cannot shift by {displacement} cells")
    if kernel == "linear":
        first = math.floor(displacement)
        fraction = displacement - first
        return first, np.array([1.0 - fraction, fraction])
    if kernel != "zero-skew":
        raise ValueError(f"unknown shift kernel {kernel!r} (expected 'zero-skew' or 'linear')")
    nearest = math.floor(displacement + 0.5)
    r = displacement - nearest
    weights = np.array(
        [(1.0 - r) * (1.0 - 2.0 * r) / 6.0, 2.0 * (1.0 - r * r) / 3.0, (1.0 + r) * (1.0 + 2.0 * r) / 6.0]
    )
    return nearest - 1, weights


def _shift_factor(shape: Sequence[int], axis: int, first: int, weights: np.ndarray) -> np.ndarray:
    """DFT along `axis` (rfftn layout, broadcastable) of sum_k weights[k] * roll(a, first + k, axis)."""
    cells = shape[axis]
    frequencies = np.arange(cells // 2 + 1 if axis == len(shape) - 1 else cells)
    offsets = first + np.arange(len(weights))
    factor = np.exp(-2j * np.pi * np.outer(frequencies, offsets) / cells) @ weights  # roll by o: e^(-2 pi i o m / n)
    broadcast = [1] * len(shape)
    broadcast[axis] = len(factor)
    return factor.reshape(broadcast)


def _within_one_turn(first: int, taps: int, cells: int) -> int:
    """The first offset of a blend of `taps` consecutive shifts, moved by whole turns of the ring so that the blend
    is centred within half a turn of zero. Rolling by n cells is rolling by n mod cells: a displacement of a
    million cells (a huge step or a wrong value) then costs what a short one does, instead of a kernel a million
    taps long. Displacements within half a turn are unchanged."""
    half = (taps - 1) // 2
    centre = (first + half) % cells  # integer arithmetic: exact for any Python int
    if centre >= (cells + 1) // 2:
        centre -= cells
    return centre - half


def _roll_kernel(first: int, weights: np.ndarray) -> np.ndarray:
    """Weights of sum_k weights[k] * roll(a, first + k) as an odd correlation kernel centred on offset 0."""
    reach = max(abs(first), abs(first + len(weights) - 1))
    kernel = np.zeros(2 * reach + 1, dtype=weights.dtype)
    # roll(a, o)[i] = a[i - o] is the correlation tap at position reach - o
    kernel[reach - first - np.arange(len(weights))] = weights
    return kernel


def circular_shift(
    activity: np.ndarray, displacements: Sequence[Sequence[float]], kernel: ShiftKernel = "zero-skew"
) -> np.ndarray:
    """The activity moved by each displacement in turn (cells per axis, cyclic), as convex blends of integer
    shifts. Successive blends along an axis compose into one (their weights convolve): one pass per axis."""
    result = activity
    for axis in range(activity.ndim):
        first, weights = 0, np.ones(1)
        for displacement in displacements:
            if len(displacement) != activity.ndim:
                raise ValueError(f"{len(displacement)} displacements for a {activity.ndim}-D activity")
            offset, taps = shift_taps(float(displacement[axis]), kernel)
            first, weights = first + offset, np.convolve(weights, taps)
        first = _within_one_turn(first, len(weights), activity.shape[axis])
        if len(weights) > 1 or first != 0:
            taps = _roll_kernel(first, weights.astype(activity.dtype))
            result = correlate1d(result, taps, axis=axis, mode="wrap")
    return result


def nearest_cell(cell: Sequence[float], dims: Sequence[int]) -> tuple[int, ...]:
    """Index of the cell nearest to a (fractional, possibly unwrapped) cell state."""
    if len(cell) != len(dims):
        raise ValueError(f"a cell state needs {len(dims)} coordinates, got {len(cell)}")
    return tuple(int(math.floor(float(c) + 0.5)) % n for c, n in zip(cell, dims, strict=True))


def inject_energy(activity: np.ndarray, cells: np.ndarray, weights: np.ndarray, energy: float) -> None:
    """Add `energy` in place, spread over integer `cells` (k, ndim) in proportion to `weights` (k,); cells wrap."""
    cells = np.asarray(cells)
    weights = np.asarray(weights, dtype=float)
    if cells.ndim != 2 or cells.shape[1] != activity.ndim or cells.shape[0] != weights.shape[0]:
        raise ValueError(f"need (k, {activity.ndim}) cells and (k,) weights, got {cells.shape} and {weights.shape}")
    if not np.issubdtype(cells.dtype, np.integer):
        raise ValueError("pattern cells must be integer indices")
    if (weights < 0).any() or not weights.sum() > 0:
        raise ValueError("pattern weights must be non-negative with a positive sum")
    wrapped = tuple((cells % np.asarray(activity.shape)).T)
    shares = (energy * weights / weights.sum()).astype(activity.dtype)
    np.add.at(activity, wrapped, shares)  # add.at: repeated cells add up


def peak_cell(activity: np.ndarray) -> tuple[int, ...]:
    """Index of the most active cell (the first one on ties)."""
    return tuple(int(i) for i in np.unravel_index(np.argmax(activity), activity.shape))


def circular_mean(cells: np.ndarray, weights: np.ndarray, n: int) -> float:
    """Weighted circular mean of cell indices on a ring of n cells, in cell units in [0, n)."""
    angles = cells * (2.0 * np.pi / n)
    angle = math.atan2(float(weights @ np.sin(angles)), float(weights @ np.cos(angles)))
    centre = (angle / (2.0 * np.pi / n)) % n
    return 0.0 if centre >= n else centre  # -1e-17 % n rounds to n


def packet_centre(activity: np.ndarray, half_window: int) -> np.ndarray:
    """Sub-cell centre of the packet around the peak (notes 3.4): circular means of the marginals of the
    peak +- half_window window (wrapped), in cell units in [0, n) per axis. Activity outside is ignored, so a
    second, weaker packet does not pull the estimate."""
    peak = peak_cell(activity)
    windows = []
    for centre, cells in zip(peak, activity.shape, strict=True):
        half = min(half_window, (cells - 1) // 2)  # a window wider than the ring would count cells twice
        windows.append((centre + np.arange(-half, half + 1)) % cells)
    packet = activity[np.ix_(*windows)]
    axes = range(activity.ndim)
    return np.array(
        [
            circular_mean(windows[axis], packet.sum(axis=tuple(a for a in axes if a != axis)), cells)
            for axis, cells in enumerate(activity.shape)
        ]
    )


def circular_difference(a: np.ndarray | float, b: np.ndarray | float, dims: Sequence[int] | int) -> np.ndarray:
    """Signed shortest difference a - b per axis on rings of `dims` cells, in [-n/2, n/2).

    Summing circular_difference(centre_t, centre_t-1, dims) over frames unwraps a decoded centre over time.
    """
    n = np.asarray(dims, dtype=float)
    return np.mod(np.asarray(a, dtype=float) - np.asarray(b, dtype=float) + n / 2.0, n) - n / 2.0
