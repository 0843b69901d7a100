"""The odometry noise estimate on its own: views' displacements drawn from known random walks and stereo noise."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.mapping.odometry_noise import OdometryNoiseEstimate, _non_negative_line

LONG, SHORT = 1.0, 0.1  # s


def draw(rng: np.random.Generator, n: int, heading: float, distance: float, stereo: float):
    """n views at 5-40 m: displacements across their arms over a long interval and the two short ones at its ends,
    with stereo noise `stereo` m per view (two views per displacement) that no model states."""
    arms = rng.uniform(5.0, 40.0, n)
    rate = arms**2 * heading**2 + distance**2

    def across(interval: float) -> np.ndarray:
        return rng.normal(0.0, np.sqrt(rate * interval + 2 * stereo**2))

    return arms, across(LONG), across(SHORT), across(SHORT), np.full(n, LONG - SHORT)


@pytest.mark.parametrize(("heading", "distance"), [(0.032, 0.32), (0.01, 0.0), (0.0, 0.2)])
def test_random_walks_are_recovered_through_unknown_stereo_noise(heading: float, distance: float) -> None:
    estimate = OdometryNoiseEstimate(window=4000, min_views=100, bins=4)
    estimate.add(*draw(np.random.default_rng(1), 4000, heading, distance, stereo=0.2))
    found = estimate.noise()
    assert found is not None  # within about what ten seeds give
    assert found[0] == pytest.approx(heading, abs=0.2 * 0.032)
    assert found[1] == pytest.approx(distance, abs=0.25 * 0.32)


def test_a_minority_of_movers_moves_the_estimate_little() -> None:
    """13 % of the views from cars not yet found moving: the heading term stays, the position term rises by half."""
    rng = np.random.default_rng(2)
    estimate = OdometryNoiseEstimate(window=5000, min_views=100, bins=4)
    estimate.add(*draw(rng, 4000, 0.032, 0.32, stereo=0.2))
    arms = rng.uniform(5.0, 40.0, 600)  # cars not yet found moving: 3 m/s across
    estimate.add(
        arms, rng.normal(3.0, 1.0, 600), rng.normal(0.3, 0.2, 600), rng.normal(0.3, 0.2, 600), np.full(600, 0.9)
    )
    heading, distance = estimate.noise()
    assert heading == pytest.approx(0.032, rel=0.25) and distance == pytest.approx(0.32, rel=0.6)


def test_no_estimate_before_enough_views_and_the_window_keeps_the_latest() -> None:
    rng = np.random.default_rng(3)
    estimate = OdometryNoiseEstimate(window=500, min_views=200, bins=4)
    estimate.add(*draw(rng, 150, 0.032, 0.32, stereo=0.2))
    assert estimate.noise() is None
    estimate.add(*draw(rng, 500, 0.0, 0.0, stereo=0.2))  # the odometry became exact: the old views have left
    assert estimate.views == 500
    heading, distance = estimate.noise()
    assert heading < 0.005 and distance < 0.06


def test_few_views_or_intervals_of_no_time_give_no_noise_and_no_error() -> None:
    estimate = OdometryNoiseEstimate(window=10, min_views=1, bins=4)
    estimate.add(np.array([10.0]), np.array([1.0]), np.array([0.1]), np.array([0.1]), np.array([0.9]))
    assert estimate.noise() == (0.0, 0.0)  # one view: one group, no line
    estimate.add(np.full(5, 20.0), np.ones(5), np.zeros(5), np.zeros(5), np.zeros(5))
    assert estimate.noise() == (0.0, 0.0)  # only one group spans any time


def test_the_line_fit_keeps_both_terms_non_negative() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert _non_negative_line(x, 2.0 * x + 1.0) == pytest.approx((2.0, 1.0))
    assert _non_negative_line(x, 2.0 * x - 1.0)[1] == 0.0  # would be negative: through the origin
    assert _non_negative_line(x, 5.0 - x)[0] == 0.0  # falling: a level
    assert _non_negative_line(x, -x) == (0.0, 0.0)
    weighted = _non_negative_line(x, np.array([3.0, 5.0, 7.0, 100.0]), np.array([1.0, 1.0, 1.0, 1e-9]))
    assert weighted == pytest.approx((2.0, 1.0), abs=1e-6)  # a point of no weight does not count
