"""The compiled inner loops of place matching against the formulas they implement, written with numpy or scipy."""

from __future__ import annotations

from itertools import combinations

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
    starts, columns, values = kernels.affinity(
        _distances(query), _distances(stored), query_var, stored_var, q, s, e_max, sigmas, covariance
    )
    found = np.zeros((len(q), len(q)))
    for row in range(len(q)):
        assert np.all(np.diff(columns[starts[row] : starts[row + 1]]) > 0)  # each row's columns increasing
        found[row, columns[starts[row] : starts[row + 1]]] = values[starts[row] : starts[row + 1]]
    assert np.all(values != 0.0)  # the non-zero entries only
    np.testing.assert_allclose(found, expected, rtol=1e-12, atol=1e-15)
    for built, dense in zip((starts, columns, values), kernels.compressed(found), strict=True):
        np.testing.assert_array_equal(built, dense)


def test_a_block_is_the_matrix_at_the_indices() -> None:
    rng = np.random.default_rng(2)
    matrix = rng.uniform(0, 1, (30, 30)) * (rng.uniform(0, 1, (30, 30)) < 0.2)
    indices = rng.permutation(30)[:9].astype(np.int64)
    np.testing.assert_array_equal(kernels.block(*kernels.compressed(matrix), indices), matrix[np.ix_(indices, indices)])


@pytest.mark.parametrize("seed", range(4))
def test_the_power_iteration_finds_the_principal_eigenvector(seed: int) -> None:
    rng = np.random.default_rng(seed)
    matrix = rng.uniform(0, 1, (40, 40)) * (rng.uniform(0, 1, (40, 40)) < 0.1)
    matrix = matrix + matrix.T
    values, vectors = np.linalg.eigh(matrix)
    principal = np.abs(vectors[:, -1])
    found = kernels.principal_eigenvector(*kernels.compressed(matrix), 10_000, 1e-12)
    np.testing.assert_allclose(found, principal, atol=1e-8)
    assert not kernels.principal_eigenvector(*kernels.compressed(np.zeros((5, 5))), 50, 1e-5).any()


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


def test_the_kept_objects_are_the_unjoined_ones_provisional_only_when_all_their_estimates_are() -> None:
    rng = np.random.default_rng(6)
    points = rng.uniform(0, 6, (30, 2))
    codes = rng.integers(0, 3, 30).astype(np.int64)
    order = rng.permutation(30).astype(np.int64)
    provisional = rng.random(30) < 0.6
    joined = kernels.merged_objects(points, codes, order, 1.5)
    keep, kept_provisional = kernels.kept_objects(points, codes, order, 1.5, provisional)
    assert keep.tolist() == [i for i in order.tolist() if joined[i] < 0]
    for i, flag in zip(keep.tolist(), kept_provisional.tolist(), strict=True):
        estimates = [i, *np.flatnonzero(joined == i).tolist()]
        assert flag == all(provisional[j] for j in estimates)


def _ground(points: np.ndarray, robot: np.ndarray) -> tuple[np.ndarray, float]:
    centre = points[np.argmin(np.linalg.norm(points - robot, axis=1))]
    return centre, float(np.linalg.norm(points - centre, axis=1).max())


@pytest.mark.parametrize("seed", range(4))
def test_missed_objects_are_known_well_inside_the_other_ground_with_no_counterpart(seed: int) -> None:
    rng = np.random.default_rng(seed)
    here, here_cov = _scene(rng, 12)
    there, there_cov = _scene(rng, 10)
    there[:6] = here[:6] + rng.normal(0, 0.5, (6, 2))  # a shared part, the rest strangers
    codes, other_codes = rng.integers(0, 2, 12).astype(np.int64), rng.integers(0, 2, 10).astype(np.int64)
    other_codes[:6] = codes[:6]
    known, other_known = rng.random(12) < 0.8, rng.random(10) < 0.8
    robot, other_robot = rng.uniform(-5, 5, 2), rng.uniform(-5, 5, 2)
    margin, radius, gate, floor = 2.0, 1.0, 9.21, 0.1
    found = kernels.missed_objects(
        (here, codes, here_cov, known, robot),
        (there, other_codes, there_cov, other_known, other_robot),
        margin,
        (radius, gate, floor, True),
    )

    def missed(points, point_codes, covs, point_known, others, others_codes, others_covs, others_robot):
        centre, reach = _ground(others, others_robot)
        expected = []
        for p, code, cov, is_known in zip(points, point_codes, covs, point_known, strict=True):
            inside = is_known and np.linalg.norm(p - centre) <= reach - margin
            counterpart = any(
                code == other_code
                and (
                    np.linalg.norm(p - other) <= radius
                    or (p - other) @ np.linalg.inv(cov + other_cov + floor * np.eye(2)) @ (p - other) <= gate
                )
                for other, other_code, other_cov in zip(others, others_codes, others_covs, strict=True)
            )
            expected.append(bool(inside and not counterpart))
        return expected

    assert found[0].tolist() == missed(here, codes, here_cov, known, there, other_codes, there_cov, other_robot)
    assert found[1].tolist() == missed(there, other_codes, there_cov, other_known, here, codes, here_cov, robot)


def _reference_keys(
    centres: np.ndarray, robot: np.ndarray, codes: np.ndarray, max_objects: int, max_side: float, side_bin: float,
    spread: bool,
) -> np.ndarray:  # fmt: skip
    """loop.triangles' keys written with numpy: every three of the objects nearest the current one, sides sorted."""
    current = np.argmin(np.linalg.norm(centres - robot, axis=1))
    nearest = np.argsort(np.linalg.norm(centres - centres[current], axis=1), kind="stable")[:max_objects]
    triples = nearest[np.array(list(combinations(range(len(nearest)), 3)), dtype=np.int64).reshape(-1, 3)]
    points = centres[triples]
    sides = np.linalg.norm(points[:, [1, 2, 0]] - points[:, [2, 0, 1]], axis=2)  # side opposite each vertex
    order = np.argsort(sides, axis=1, kind="stable")
    sides, labels = np.take_along_axis(sides, order, axis=1), np.take_along_axis(codes[triples], order, axis=1)
    labels, sides = labels[sides[:, 2] <= max_side], sides[sides[:, 2] <= max_side]
    bins = np.floor(sides / side_bin).astype(np.int64)
    choices = [np.zeros(3, dtype=bool)]
    if spread:
        choices = list(((np.arange(8)[:, None] >> np.arange(3)) & 1).astype(bool))
    neighbour = np.where(sides / side_bin - bins >= 0.5, bins + 1, bins - 1)
    keys = []
    for choice in choices:
        chosen = np.where(choice, neighbour, bins)
        valid = ((chosen >= 0) & (chosen < 256)).all(axis=1) if spread else np.ones(len(chosen), dtype=bool)
        key = np.zeros(int(valid.sum()), dtype=np.int64)
        for column in range(3):
            key = (key << 6) | labels[valid, column]
        for column in range(3):
            key = (key << 8) | chosen[valid, column]
        keys.append(key)
    return np.unique(np.concatenate(keys))


@pytest.mark.parametrize("spread", [False, True])
@pytest.mark.parametrize("seed", range(4))
def test_triangle_keys_are_the_sorted_sides_and_labels_packed(seed: int, spread: bool) -> None:
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-25, 25, (int(rng.integers(3, 20)), 2))
    codes = rng.integers(1, 5, len(centres)).astype(np.int64)
    robot = rng.uniform(-5, 5, 2)
    found = kernels.triangle_keys(centres, robot, codes, 8, 30.0, 0.75, spread, 6, 8)
    np.testing.assert_array_equal(found, _reference_keys(centres, robot, codes, 8, 30.0, 0.75, spread))
    assert len(kernels.triangle_keys(centres[:2], robot, codes[:2], 8, 30.0, 0.75, spread, 6, 8)) == 0


def test_triangle_scores_are_the_summed_idf_over_the_root_of_the_keys() -> None:
    rng = np.random.default_rng(4)
    stored = 40
    per_slot = [np.unique(rng.integers(0, 60, int(rng.integers(0, 25)))) for _ in range(stored)]
    keys = np.concatenate(per_slot).astype(np.int64)
    slots = np.concatenate([np.full(len(k), slot) for slot, k in enumerate(per_slot)]).astype(np.int32)
    main = slots < 30  # the first 30 keyframes merged, the last 10 in the tail
    order = np.argsort(keys[main], kind="stable")
    tail_order = np.argsort(keys[~main], kind="stable")
    query = np.unique(rng.integers(0, 80, 30)).astype(np.int64)
    counts = np.array([len(k) for k in per_slot], dtype=float)
    scores, shared = kernels.triangle_scores(
        keys[main][order], slots[main][order], keys[~main][tail_order], slots[~main][tail_order], query, counts
    )
    holding = np.array([[key in set(k.tolist()) for k in per_slot] for key in query.tolist()])  # (keys, slots)
    idf = np.log((stored + 1.0) / (holding.sum(axis=1) + 0.5))
    np.testing.assert_array_equal(shared, holding.sum(axis=0))
    np.testing.assert_allclose(
        scores, (idf[:, None] * holding).sum(axis=0) / np.sqrt(np.maximum(counts, 1)), rtol=1e-12
    )


def test_label_codes_are_equal_where_the_labels_are_across_calls() -> None:
    (first,) = kernels.label_codes(("car", "truck", "car"))
    second, third = kernels.label_codes(["truck", "bicycle"], ("car",))
    assert first[0] == first[2] == third[0] != first[1] == second[0] != second[1]


def test_a_side_without_objects_misses_nothing_and_covers_no_ground() -> None:
    points, covariances = _scene(np.random.default_rng(8), 5)
    codes, known = np.zeros(5, dtype=np.int64), np.ones(5, dtype=bool)
    empty = (np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros((0, 2, 2)), np.zeros(0, dtype=bool), np.zeros(2))
    for margin in (0.0, 2.0):
        here, there = kernels.missed_objects(
            (points, codes, covariances, known, np.zeros(2)), empty, margin, (1.0, 9.2, 0.1, True)
        )
        assert not here.any() and len(there) == 0
    assert kernels.ground(np.zeros((0, 2)), np.array([3.0, 4.0])) == (3.0, 4.0, -np.inf)
