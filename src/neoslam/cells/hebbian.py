"""Hebbian place memory (paper 3.5, eq. 14): ties each keyframe template to the grid-cell and head-direction cell
activity present when it was learnt, so that recognising the keyframe can inject that activity again.

    β_{k,x,y,z,θ} ← max(τ · O^k · P_{x,y,z,θ}, β_{k,x,y,z,θ}),   P = GC(x,y,z) ⊗ HD(θ),   β starts at 0.

A dense β holds X·Y·Z·Θ numbers per keyframe (1.7e6 at 36^4, 1.7e9 for 1,000 keyframes). The grid cells and the
head-direction cells are injected separately, so what recall needs of β_k are its two max-marginals:

    G_k(x,y,z) = max_θ β_k = τ·O^k·GC(x,y,z)·max HD,    H_k(θ) = max_xyz β_k = τ·O^k·max GC·HD(θ).

Maxima commute, so re-associating by element-wise max of the marginals is exactly eq. 14 seen through them. Each
marginal keeps only the packet neighbourhood: cells at or above `sparsity` of its factor's peak, as flat int32
indices and float32 weights, so memory grows with the number of keyframes, not keyframes × cells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.cells.attractor import peak_cell
from neoslam.config import HebbianConfig
from neoslam.types import HebbianTrace

__all__ = ["HebbianMemory", "HebbianRecall", "HebbianTrace"]

_INDEX_DTYPE = np.int32  # 36^3 = 46,656 grid cells; int32 holds any grid up to 2^31 cells
_WEIGHT_DTYPE = np.float32


@dataclass(frozen=True, slots=True)
class HebbianRecall:
    """What keyframe k gives back: the activity to inject and the cell state it was stored with (read-only arrays).

    Weights are τ·O^k times the cells' activity (eq. 14); all zero when the template activity was never above 0.
    """

    gc_indices: np.ndarray  # (n,) int32 flat C-order indices into the (X, Y, Z) grid-cell array
    gc_weights: np.ndarray  # (n,) float32, G_k at those cells
    hd_indices: np.ndarray  # (m,) int32 head-direction cells
    hd_weights: np.ndarray  # (m,) float32, H_k at those cells
    gc_shape: tuple[int, int, int]
    gc_peak: tuple[int, int, int]  # peak grid cell of the strongest association (experience-map cell distance)
    hd_peak: int  # peak head-direction cell of the strongest association
    strength: float  # τ·O^k·max GC·max HD of the strongest association: the peak of β_k

    @property
    def gc_cells(self) -> np.ndarray:
        """(n, 3) integer (x, y, z) cells of gc_indices, as GridCells.inject_pattern takes them."""
        return np.stack(np.unravel_index(self.gc_indices, self.gc_shape), axis=1)


def _packet(activity: np.ndarray, sparsity: float, name: str) -> tuple[np.ndarray, float]:
    """Flat indices of the cells at or above `sparsity` of the peak (the packet neighbourhood), and the peak."""
    if not np.all(np.isfinite(activity)):
        raise ValueError(f"{name} activity holds non-finite values")
    peak = float(activity.max())
    if peak <= 0:
        raise ValueError(f"{name} activity has no positive peak: nothing to associate")
    return np.flatnonzero(activity >= sparsity * peak).astype(_INDEX_DTYPE), peak


def _marginal_weights(activity: np.ndarray, indices: np.ndarray, gain: float) -> np.ndarray:
    """max(gain · activity, 0) at `indices`: eq. 14 against β = 0 (a negative O^k stores nothing)."""
    return np.maximum(gain * activity.ravel()[indices], 0.0).astype(_WEIGHT_DTYPE)


def _max_union(
    indices_a: np.ndarray, weights_a: np.ndarray, indices_b: np.ndarray, weights_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Element-wise max of two sparse vectors (eq. 14); indices come back sorted and unique."""
    indices = np.concatenate([indices_a, indices_b])
    weights = np.concatenate([weights_a, weights_b])
    order = np.lexsort((-weights, indices))  # by cell, the largest weight first
    indices, weights = indices[order], weights[order]
    first = np.ones(len(indices), dtype=bool)
    first[1:] = indices[1:] != indices[:-1]
    return indices[first], weights[first]


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


class HebbianMemory:
    """β of eq. 14 for every keyframe template, stored as sparse max-marginals over grid and head-direction cells."""

    def __init__(self, config: HebbianConfig | None = None) -> None:
        self.config = config or HebbianConfig()
        self._traces: dict[int, HebbianTrace] = {}
        self._gc_shape: tuple[int, int, int] | None = None
        self._hd_cells: int | None = None

    def __len__(self) -> int:
        return len(self._traces)

    def __contains__(self, keyframe_id: object) -> bool:
        return keyframe_id in self._traces

    @property
    def nbytes(self) -> int:
        """Bytes of the stored indices and weights (Python object overhead, ~0.5 kB per keyframe, not counted)."""
        return sum(trace.nbytes for trace in self._traces.values())

    def dense_nbytes(self) -> int:
        """Bytes a dense float32 β over every keyframe and every grid × head-direction cell would take."""
        if self._gc_shape is None or self._hd_cells is None:
            return 0
        cells = int(np.prod(self._gc_shape)) * self._hd_cells
        return len(self) * cells * np.dtype(_WEIGHT_DTYPE).itemsize

    def traces(self) -> dict[int, HebbianTrace]:
        """Every keyframe's association (a map file stores them)."""
        return dict(self._traces)

    def restore(self, traces: dict[int, HebbianTrace], gc_shape: tuple[int, int, int], hd_cells: int) -> None:
        """Take the associations of a stored map (learnt with cells of these shapes)."""
        self._traces.update(traces)
        if traces:
            self._gc_shape, self._hd_cells = gc_shape, hd_cells

    def associate(
        self, keyframe_id: int, template_activity: float, gc_activity: np.ndarray, hd_activity: np.ndarray
    ) -> None:
        """Learn eq. 14 between keyframe template k (activity O^k) and P = GC ⊗ HD; a known keyframe keeps the max."""
        gc_activity, hd_activity = self._checked(template_activity, gc_activity, hd_activity)
        trace = self._trace(float(template_activity), gc_activity, hd_activity)
        stored = self._traces.get(keyframe_id)
        self._traces[keyframe_id] = trace if stored is None else _strongest(stored, trace)

    def recall(self, keyframe_id: int) -> HebbianRecall:
        """The activity keyframe k injects into the grid and head-direction cells, and its stored cell state."""
        try:
            trace = self._traces[keyframe_id]
        except KeyError:
            raise KeyError(
                f"keyframe {keyframe_id} has no Hebbian association ({len(self)} keyframes associated)"
            ) from None
        assert self._gc_shape is not None  # set by the first association
        return HebbianRecall(
            trace.gc_indices,
            trace.gc_weights,
            trace.hd_indices,
            trace.hd_weights,
            self._gc_shape,
            trace.gc_peak,
            trace.hd_peak,
            trace.strength,
        )

    def _checked(
        self, template_activity: float, gc_activity: np.ndarray, hd_activity: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The activities as arrays, of the shapes the first association fixed."""
        if not np.isfinite(template_activity):
            raise ValueError(f"template activity must be finite, got {template_activity}")
        gc_activity = np.asarray(gc_activity, dtype=float)
        hd_activity = np.asarray(hd_activity, dtype=float)
        if gc_activity.ndim != 3 or hd_activity.ndim != 1:
            raise ValueError(
                f"need (X, Y, Z) grid-cell and (θ,) head-direction activity, got "
                f"{gc_activity.shape} and {hd_activity.shape}"
            )
        if self._gc_shape is None:
            self._gc_shape = (gc_activity.shape[0], gc_activity.shape[1], gc_activity.shape[2])
            self._hd_cells = hd_activity.shape[0]
        if gc_activity.shape != self._gc_shape or hd_activity.shape != (self._hd_cells,):
            raise ValueError(
                f"activity shapes {gc_activity.shape} and {hd_activity.shape} differ from the memory's "
                f"{self._gc_shape} and ({self._hd_cells},)"
            )
        return gc_activity, hd_activity

    def _trace(self, template_activity: float, gc_activity: np.ndarray, hd_activity: np.ndarray) -> HebbianTrace:
        """One association's sparse max-marginals of τ·O^k·P (eq. 14 against β = 0)."""
        gc_indices, gc_peak = _packet(gc_activity, self.config.sparsity, "grid-cell")
        hd_indices, hd_peak = _packet(hd_activity, self.config.sparsity, "head-direction")
        gain = self.config.learning_rate * template_activity  # τ·O^k
        x, y, z = peak_cell(gc_activity)
        return HebbianTrace(
            gc_indices=_read_only(gc_indices),
            gc_weights=_read_only(_marginal_weights(gc_activity, gc_indices, gain * hd_peak)),
            hd_indices=_read_only(hd_indices),
            hd_weights=_read_only(_marginal_weights(hd_activity, hd_indices, gain * gc_peak)),
            gc_peak=(x, y, z),
            hd_peak=peak_cell(hd_activity)[0],
            strength=max(gain * gc_peak * hd_peak, 0.0),
        )


def _strongest(stored: HebbianTrace, new: HebbianTrace) -> HebbianTrace:
    """Eq. 14 for a known keyframe: element-wise max of the marginals; the cell state of the stronger association."""
    gc_indices, gc_weights = _max_union(stored.gc_indices, stored.gc_weights, new.gc_indices, new.gc_weights)
    hd_indices, hd_weights = _max_union(stored.hd_indices, stored.hd_weights, new.hd_indices, new.hd_weights)
    state = new if new.strength > stored.strength else stored  # ties keep the first: the place it was learnt
    return HebbianTrace(
        _read_only(gc_indices),
        _read_only(gc_weights),
        _read_only(hd_indices),
        _read_only(hd_weights),
        state.gc_peak,
        state.hd_peak,
        max(stored.strength, new.strength),
    )
