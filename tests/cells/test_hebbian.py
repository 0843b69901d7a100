"""Hebbian place memory (eq. 14) on realistic packets: a Gaussian blob of grid cells in 36^3 and of a 36-cell ring."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.cells.hebbian import HebbianMemory
from neoslam.config import HebbianConfig

GC_SHAPE = (36, 36, 36)
HD_CELLS = 36
GC_SIGMA = 1.5  # cells, the grid-cell excitation σ of eq. 6 (GridCellConfig)
HD_SIGMA = 1.9  # cells, the head-direction excitation σ (HeadDirectionConfig)
KEEP_ALL = 1e-12  # a sparsity that stores every cell with activity, for comparisons with dense β


def packet(shape: tuple[int, ...], centre: tuple[int, ...], sigma: float) -> np.ndarray:
    """A Gaussian activity packet on a cyclic grid, summing to 1 like the attractor's activity."""
    squared = np.zeros(shape)
    for axis, (n, c) in enumerate(zip(shape, centre, strict=True)):
        offset = (np.arange(n) - c + n // 2) % n - n // 2  # cyclic distance
        squared = squared + (offset**2).reshape([-1 if i == axis else 1 for i in range(len(shape))])
    activity = np.exp(-squared / (2 * sigma**2))
    return activity / activity.sum()


def gc_packet(centre: tuple[int, int, int], shape: tuple[int, int, int] = GC_SHAPE) -> np.ndarray:
    return packet(shape, centre, GC_SIGMA)


def hd_packet(centre: int, cells: int = HD_CELLS) -> np.ndarray:
    return packet((cells,), (centre,), HD_SIGMA)


def dense_beta(associations, gc_shape, hd_cells, tau):
    """β of eq. 14 in full, for keyframe k's associations [(O, gc, hd), ...]."""
    beta = np.zeros((*gc_shape, hd_cells))
    for template, gc, hd in associations:
        beta = np.maximum(tau * template * gc[..., None] * hd, beta)
    return beta


def test_memory_grows_linearly_with_keyframes_and_stays_far_below_dense():
    rng = np.random.default_rng(0)
    sizes = {}
    memory = HebbianMemory()
    # One packet rolled to each centre: the cyclic blob has the same cells everywhere, so bytes are exact.
    gc_base, hd_base = gc_packet((0, 0, 0)), hd_packet(0)
    for keyframe in range(1000):
        shift = rng.integers(0, 36, size=4)
        gc = np.roll(gc_base, tuple(shift[:3]), axis=(0, 1, 2))
        memory.associate(keyframe, 0.8, gc, np.roll(hd_base, shift[3]))
        if len(memory) in (10, 100, 1000):
            sizes[len(memory)] = memory.nbytes
    per_keyframe = sizes[10] / 10
    assert sizes[100] == 100 * per_keyframe and sizes[1000] == 1000 * per_keyframe
    assert per_keyframe < 2_000  # measured 1,248 bytes: 147 grid cells and 9 head-direction cells, 8 bytes each
    assert sizes[1000] < 1e-3 * memory.dense_nbytes()  # dense: 6.7 MB per keyframe at 36^4 float32


def test_recall_peaks_at_the_stored_cell_state():
    memory = HebbianMemory(HebbianConfig(learning_rate=2.0))
    gc, hd = gc_packet((5, 30, 17)), hd_packet(34)
    memory.associate(3, 0.6, gc, hd)
    recall = memory.recall(3)
    assert recall.gc_peak == (5, 30, 17) and recall.hd_peak == 34
    assert tuple(recall.gc_cells[np.argmax(recall.gc_weights)]) == (5, 30, 17)
    assert recall.hd_indices[np.argmax(recall.hd_weights)] == 34
    # max-marginals of τ·O·GC⊗HD: the grid part carries max HD, the head-direction part max GC.
    assert recall.gc_weights.max() == pytest.approx(2.0 * 0.6 * gc.max() * hd.max(), rel=1e-6)
    assert recall.strength == pytest.approx(2.0 * 0.6 * gc.max() * hd.max())
    np.testing.assert_allclose(recall.hd_weights, 2.0 * 0.6 * gc.max() * hd[recall.hd_indices], rtol=1e-6)


def test_only_the_packet_neighbourhood_is_stored():
    memory = HebbianMemory(HebbianConfig(sparsity=0.1))
    gc, hd = gc_packet((10, 10, 10)), hd_packet(18)
    memory.associate(0, 1.0, gc, hd)
    recall = memory.recall(0)
    stored = gc.ravel()[recall.gc_indices]
    assert stored.min() >= 0.1 * gc.max()
    assert len(recall.gc_indices) == np.count_nonzero(gc >= 0.1 * gc.max())
    assert len(recall.hd_indices) == np.count_nonzero(hd >= 0.1 * hd.max())


def test_reassociation_keeps_the_max():
    memory = HebbianMemory()
    first = (0.5, gc_packet((4, 4, 4)), hd_packet(3))
    stronger = (1.0, gc_packet((6, 4, 4)), hd_packet(5))
    weaker = (0.1, gc_packet((20, 20, 20)), hd_packet(20))
    memory.associate(1, *first)
    first_recall = memory.recall(1)
    memory.associate(1, *stronger)
    memory.associate(1, *weaker)
    recall = memory.recall(1)
    assert len(memory) == 1
    gc = dict(zip(recall.gc_indices.tolist(), recall.gc_weights.tolist(), strict=True))
    expected = np.maximum.reduce([1.0 * o * g * h.max() for o, g, h in (first, stronger, weaker)]).ravel()
    for index, weight in gc.items():
        assert weight == pytest.approx(expected[index], rel=1e-6)
    assert set(first_recall.gc_indices.tolist()) <= set(gc)  # nothing learnt is forgotten
    assert recall.gc_peak == (6, 4, 4) and recall.hd_peak == 5  # the state of the strongest association
    memory.associate(1, *weaker)  # the same association again changes nothing
    np.testing.assert_array_equal(memory.recall(1).gc_weights, recall.gc_weights)


def test_marginals_equal_the_max_marginals_of_dense_beta():
    shape, cells, tau = (8, 8, 8), 8, 1.5
    memory = HebbianMemory(HebbianConfig(learning_rate=tau, sparsity=KEEP_ALL))
    associations = [
        (0.7, packet(shape, (1, 2, 3), GC_SIGMA), packet((cells,), (2,), HD_SIGMA)),
        (0.9, packet(shape, (5, 5, 0), GC_SIGMA), packet((cells,), (6,), HD_SIGMA)),
        (0.3, packet(shape, (2, 2, 3), GC_SIGMA), packet((cells,), (1,), HD_SIGMA)),
    ]
    for association in associations:
        memory.associate(9, *association)
    beta = dense_beta(associations, shape, cells, tau)
    recall = memory.recall(9)
    gc = np.zeros(shape)
    gc.ravel()[recall.gc_indices] = recall.gc_weights
    hd = np.zeros(cells)
    hd[recall.hd_indices] = recall.hd_weights
    np.testing.assert_allclose(gc, beta.max(axis=3), rtol=1e-6)
    np.testing.assert_allclose(hd, beta.max(axis=(0, 1, 2)), rtol=1e-6)


def test_non_positive_template_activity_stores_nothing_above_zero():
    memory = HebbianMemory()
    memory.associate(0, -0.2, gc_packet((1, 1, 1)), hd_packet(1))
    recall = memory.recall(0)
    assert not recall.gc_weights.any() and not recall.hd_weights.any() and recall.strength == 0.0
    assert recall.gc_peak == (1, 1, 1)  # the cell state is kept for the experience map's distance check


def test_unknown_keyframe_raises_a_clear_key_error():
    memory = HebbianMemory()
    memory.associate(0, 1.0, gc_packet((1, 1, 1)), hd_packet(1))
    with pytest.raises(KeyError, match="keyframe 7 has no Hebbian association"):
        memory.recall(7)
    assert 0 in memory and 7 not in memory


def test_recalled_arrays_are_read_only():
    memory = HebbianMemory()
    memory.associate(0, 1.0, gc_packet((1, 1, 1)), hd_packet(1))
    with pytest.raises(ValueError, match="read-only"):
        memory.recall(0).gc_weights[0] = 5.0


def test_bad_activity_is_refused():
    memory = HebbianMemory()
    memory.associate(0, 1.0, gc_packet((1, 1, 1)), hd_packet(1))
    with pytest.raises(ValueError, match="differ from the memory's"):
        memory.associate(1, 1.0, gc_packet((1, 1, 1), shape=(8, 8, 8)), hd_packet(1))
    with pytest.raises(ValueError, match="no positive peak"):
        memory.associate(1, 1.0, np.zeros(GC_SHAPE), hd_packet(1))
    with pytest.raises(ValueError, match=r"\(X, Y, Z\)"):
        memory.associate(1, 1.0, np.zeros((36, 36)), hd_packet(1))
    with pytest.raises(ValueError, match="finite"):
        memory.associate(1, float("nan"), gc_packet((1, 1, 1)), hd_packet(1))
