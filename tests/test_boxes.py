"""How much of an image box others cover."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.boxes import covered_share


def test_covered_share_counts_overlapping_covers_once() -> None:
    box = np.array([0.0, 0.0, 100.0, 50.0])
    assert covered_share(box, np.zeros((0, 4)), 20) == 0.0
    assert covered_share(box, np.array([[50, -10, 200, 60]]), 20) == pytest.approx(0.5)
    both = np.array([[50, -10, 200, 60], [60, 0, 100, 50]])  # the second lies inside the first
    assert covered_share(box, both, 20) == pytest.approx(0.5)
    assert covered_share(box, np.array([[-1, -1, 101, 51]]), 20) == 1.0
