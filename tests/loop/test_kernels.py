"""The compiled inner loops of place matching against the formulas they implement, written with numpy or scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from neoslam.loop import kernels


def _scene(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n ground points (x, y) and an SPD ground covariance for each."""
    points = rng.uniform(-20, 20, (n, 2))
    roots = rng.normal(0, 0.4, (n, 2, 2))
    return points, roots @ roots.transpose(0, 2, 1) + 0.01 * np.eye(2)


def _distances(points: np.ndarray) -> np.ndarray:
    return np.linalg.norm(points[:, None] - points[None], axis=2)


@pytest.mark.parametrize("seed", range(4))
def test_distance_variances_are_each_centres_covariance_along_the_line(seed: int) -> None:
    points, covariances = _scene(np.random.default_rng(seed), 7)
    offset = points[None, :, :] - points[:, None, :]
    direction = offset / np.maximum(np.linalg.norm(offset, axis=2), 1e-9)[:, :, None]
    along = np.einsum("nmi,mij,nmj->nm", direction, covariances, direction)
    expected = along + along.T + 0.125
    np.testing.assert_allclose(kernels.distance_variances(points, covariances, 0.125), expected, rtol=1e-12)


@pytest.mark.parametrize("covariance", [True, False])
@pytest.mark.parametrize("seed", range(4))
def test_the_affinity_is_eq_2_and_4_over_the_candidates(seed: int, covariance: bool) -> None:
    rng = np.random.default_rng(seed)
    query, query_cov = _scene(rng, 9)
    stored = query + rng.normal(0, 0.8, query.shape)
    stored_cov = query_cov
    q = rng.integers(0, 9, 30).astype(np.int64)
    s = rng.integers(0, 9, 30).astype(np.int64)
    e_max, sigmas = 1.5, 2.5
    query_var = kernels.distance_variances(query, query_cov, 0.125)
    stored_var = kernels.distance_variances(stored, stored_cov, 0.125)
    difference = np.abs(_distances(query)[np.ix_(q, q)] - _distances(stored)[np.ix_(s, s)])
    if covariance:
        tolerance = np.maximum(np.sqrt(query_var[np.ix_(q, q)] + stored_var[np.ix_(s, s)]) * sigmas, e_max)
        expected = e_max * np.maximum(1.0 - difference / tolerance, 0.0)
    else:
        expected = np.maximum(e_max - difference, 0.0)
    expected[(q[:, None] == q[None, :]) | (s[:, None] == s[None, :])] = 0.0  # one object cannot match two
    found = kernels.affinity(
        _distances(query), _distances(stored), query_var, stored_var, q, s, e_max, sigmas, covariance
    )
    np.testing.assert_allclose(found, expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("seed", range(4))
def test_the_power_iteration_finds_the_principal_eigenvector(seed: int) -> None:
    rng = np.random.default_rng(seed)
    matrix = rng.uniform(0, 1, (40, 40)) * (rng.uniform(0, 1, (40, 40)) < 0.1)
    matrix = matrix + matrix.T
    values, vectors = np.linalg.eigh(matrix)
    principal = np.abs(vectors[:, -1])
    np.testing.assert_allclose(kernels.principal_eigenvector(matrix, 10_000, 1e-12), principal, atol=1e-8)
    assert not kernels.principal_eigenvector(np.zeros((5, 5)), 50, 1e-5).any()


@pytest.mark.parametrize("seed", range(4))
def test_gauss_newton_reaches_the_weighted_least_squares_optimum(seed: int) -> None:
    """The weights follow the fit's yaw from step to step (the query's covariance turns with it): at convergence the
    fit minimises Σ d² with the covariances of its own yaw."""
    rng = np.random.default_rng(seed)
    query, query_cov = _scene(rng, 8)
    _, stored_cov = _scene(rng, 8)
    yaw, shift = rng.uniform(-np.pi, np.pi), rng.uniform(-5, 5, 2)
    turn = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    stored = query @ turn.T + shift + rng.normal(0, 0.5, query.shape)
    floor = 0.1
    lift = np.zeros((8, 1))
    columns = kernels.pair_columns(np.hstack([query, lift]), np.hstack([stored, lift]), query_cov, stored_cov, floor)
    fit = kernels.fit_pairs(columns, 50)

    at_fit = np.array([[np.cos(fit[0]), -np.sin(fit[0])], [np.sin(fit[0]), np.cos(fit[0])]])
    covariances = at_fit @ query_cov @ at_fit.T + stored_cov + floor * np.eye(2)
    whitening = np.linalg.cholesky(np.linalg.inv(covariances)).transpose(0, 2, 1)

    def whitened(parameters: np.ndarray) -> np.ndarray:
        c, s = np.cos(parameters[0]), np.sin(parameters[0])
        residuals = query @ np.array([[c, -s], [s, c]]).T + parameters[1:] - stored
        return np.einsum("kij,kj->ki", whitening, residuals).ravel()

    best = least_squares(whitened, [yaw, *shift], xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    np.testing.assert_allclose(fit[:3], best, atol=1e-7)
    np.testing.assert_allclose(fit[4].sum(), (whitened(best) ** 2).sum(), rtol=1e-6)


def test_the_pairs_bits_are_the_log_likelihood_ratio_against_a_stranger() -> None:
    rng = np.random.default_rng(3)
    _, query_cov = _scene(rng, 5)
    _, stored_cov = _scene(rng, 5)
    d2, shares, yaw, floor, area = rng.uniform(0, 6, 5), rng.uniform(0.05, 1, 5), 0.4, 0.125, 150.0
    turn = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    covariances = turn @ query_cov @ turn.T + stored_cov + floor * np.eye(2)
    place = np.log2(area * np.exp(-0.5 * d2) / (2 * np.pi * np.sqrt(np.linalg.det(covariances))))
    bits, spent = kernels.pair_bits(query_cov, stored_cov, yaw, floor, d2, shares, area)
    np.testing.assert_allclose(bits, np.maximum(place - np.log2(shares), 0.0), rtol=1e-12)
    best = np.sort(np.clip(place, 0.0, bits))[::-1]
    assert spent == pytest.approx(best[0] + 0.5 * best[1], rel=1e-12)
    np.testing.assert_allclose(kernels.pair_covariances(query_cov, stored_cov, yaw, floor), covariances, rtol=1e-12)


def test_merging_joins_each_object_to_the_nearest_kept_one_of_its_label() -> None:
    rng = np.random.default_rng(5)
    points = rng.uniform(0, 6, (30, 2))
    codes = rng.integers(0, 3, 30).astype(np.int64)
    order = rng.permutation(30).astype(np.int64)
    joined = kernels.merged_objects(points, codes, order, 1.5)
    kept: list[int] = []
    for i in order.tolist():
        near = [(np.linalg.norm(points[i] - points[j]), j) for j in kept if codes[j] == codes[i]]
        near = [(d, j) for d, j in near if d <= 1.5]
        if near:
            assert joined[i] == min(near)[1]
        else:
            assert joined[i] == -1
            kept.append(i)
