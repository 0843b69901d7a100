"""Axis-aligned image boxes (x1, y1, x2, y2 in px): how much of one box others cover. Pure numpy, shared by the
perception front end and the simulator, which must judge occlusion alike."""

from __future__ import annotations

import numpy as np

__all__ = ["covered_share"]


def covered_share(box: np.ndarray, others: np.ndarray, samples: int) -> float:
    """The share of `box` that the union of the boxes `others` (k, 4) covers, measured on a regular grid of samples
    x samples points over it (so that overlapping covers count once)."""
    others = np.asarray(others, dtype=float).reshape(-1, 4)
    if len(others) == 0:
        return 0.0
    steps = (np.arange(samples) + 0.5) / samples
    u, v = (
        grid.ravel() for grid in np.meshgrid(box[0] + steps * (box[2] - box[0]), box[1] + steps * (box[3] - box[1]))
    )
    inside = (u[:, None] >= others[:, 0]) & (u[:, None] <= others[:, 2])
    inside &= (v[:, None] >= others[:, 1]) & (v[:, None] <= others[:, 3])
    return float(inside.any(axis=1).mean())
