"""The odometry's noise, estimated online from the objects it sees (beyond the paper): the motion detector's tracks
allow for the odometry's heading and position error since a view was made (`moving_objects.odometry_heading_noise`,
`odometry_distance_noise`), and a user with wheel odometry or another VO rarely knows those figures.

Over an interval, a static object seems to move in the odometry frame by the odometry's error increment: the heading
error w turns it about the robot, by its distance a from the robot (taken from where the robot was midway: the error
grew all along), and the position error t shifts it. Across its arm (the line from the robot), its displacement is
d = w a + t_across + n, n the stereo noise of its two views. With both errors random walks of rates s_h and s_d
(variance per second),
    var(d) = (a^2 s_h + s_d) * dt + var(n).
The stereo noise of an object's centre is not known well enough to subtract as modelled (the object map's floor of
0.3 m bounds the visible surface's offset, which changes slowly, not the noise between two frames), so it is
cancelled: per view of a track seen at least `lag` frames before, the long interval's squared displacement (from
the latest view that old) and the mean of the two short intervals' at its ends (to the view after that one, and
from the track's last view: the same views, so their stereo noise is alike) are kept. Over the last `window` views,
in `bins` groups of equal count by a^2,
    median(d_long^2) / median(chi2_1) - median(mean of the d_short^2) / median(chi2_2 / 2)
        = (a^2 s_h + s_d) * (dt_long - dt_short)
is fitted for s_h >= 0 and s_d >= 0 by weighted least squares (medians: views of a car not yet found moving are a
minority). Sparse streets give an object or two a frame, so each view is a sample of its own, not a frame's joint
fit. Measured on simulated KITTI 05 and 00 (`python -m benchmarks.kitti_sim --parts moving`; drawn: `heavy` 0.032 rad
and 0.32 m per root second, `vo` 0.0032 and 0.063): 0.024-0.028 and 0.063-0.57 under `heavy`, 0.003-0.004 and at most
0.063 under `vo`, static or with 20 % of the objects moving (the position term is reported as the larger of the
estimate and the floor).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy.optimize import nnls

__all__ = ["OdometryNoiseEstimate"]

_MEDIAN_CHI2_1 = 0.454936  # median of chi-square with 1 degree of freedom: d^2 / var(d)
_MEDIAN_CHI2_2 = 2.0 * np.log(2.0)  # with 2: the short intervals' mean square is var(d) chi2_2 / 2


class OdometryNoiseEstimate:
    """The odometry's heading and position random walks (rad and m per square root of a second) from the last
    `window` views' displacements across their arms; None until `min_views` are held."""

    def __init__(self, window: int, min_views: int, bins: int) -> None:
        self.min_views = min_views
        self.bins = bins
        self._held: deque[tuple[float, float, float, float]] = deque(maxlen=window)
        self._cached: tuple[float, float] | None = None
        self._stale = False

    def add(self, arms: np.ndarray, long: np.ndarray, first: np.ndarray, last: np.ndarray, longer: np.ndarray) -> None:
        """Views of objects `arms` (n,) m from the robot midway: their displacements across the arm over a long
        interval and over the short ones at its ends (n,) m; the long ones are `longer` (n,) s longer than those."""
        short = (first**2 + last**2) / 2.0
        self._held.extend(zip(arms**2, long**2, short, longer, strict=True))
        self._stale = True

    @property
    def views(self) -> int:
        """Views held."""
        return len(self._held)

    def noise(self) -> tuple[float, float] | None:
        """(heading, distance) random walks, or None while too few views are held."""
        if self.views < self.min_views:
            return None
        if self._stale:
            self._cached, self._stale = self._estimate(), False
        return self._cached

    def _estimate(self) -> tuple[float, float]:
        held = np.array(self._held)
        held = held[np.argsort(held[:, 0], kind="stable")]
        groups = np.array_split(held, min(self.bins, len(held)))
        arm = np.array([np.median(g[:, 0]) for g in groups])
        long = np.array([np.median(g[:, 1]) / _MEDIAN_CHI2_1 for g in groups])
        short = np.array([2.0 * np.median(g[:, 2]) / _MEDIAN_CHI2_2 for g in groups])
        longer = np.array([np.median(g[:, 3]) for g in groups])
        timed = longer > 0  # frames with one timestamp make intervals of none: they tell no growth
        if np.count_nonzero(timed) < 2:
            return 0.0, 0.0
        arm, long, short, longer = arm[timed], long[timed], short[timed], longer[timed]
        growth = (long - short) / longer
        # A median's error is in proportion to the spread it measures: the near groups fix the position's term.
        weights = longer / np.maximum(long, np.finfo(float).tiny)
        heading, distance = _non_negative_line(arm, growth, weights)
        return float(np.sqrt(heading)), float(np.sqrt(distance))


def _non_negative_line(x: np.ndarray, y: np.ndarray, weights: np.ndarray | None = None) -> tuple[float, float]:
    """Slope and intercept, both at least 0, of the line y = slope x + intercept by least squares, each point's
    residual times its weight (default 1)."""
    weights = np.ones_like(x) if weights is None else weights
    (slope, intercept), _ = nnls(np.column_stack([weights * x, weights]), weights * y)
    return float(slope), float(intercept)
