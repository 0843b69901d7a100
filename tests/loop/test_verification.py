"""Verification that knows each object's uncertainty: the weighted fit, the chi-square gate and test, counterparts
and the evidence of a match."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.config import KeyframeConfig, MatchingConfig
from neoslam.geometry import invert_pose, transform_points, yaw_of
from neoslam.loop.keyframes import view_covariances
from neoslam.loop.matching import match_keyframes
from neoslam.loop.verification import (
    chi2_bound,
    evidence_bits,
    fit_consistent,
    fit_weighted,
    has_counterpart,
    pair_covariances,
    trimmed_fit,
)
from neoslam.types import Keyframe

CONFIG = MatchingConfig()
E_MAX = 1.5
ROBOT = np.eye(4)


def _keyframe(centres, labels=None, covariances=None, pose=None, id=0) -> Keyframe:
    centres = np.asarray(centres, dtype=float)
    n = len(centres)
    return Keyframe(
        id=id,
        frame_index=0,
        pose=np.eye(4) if pose is None else pose,
        centers=centres,
        labels=tuple(labels or ["car"] * n),
        patches=np.full((n, 16, 16), 128, np.uint8),
        covariances=covariances,
    )


def _seen_from_origin(centres: np.ndarray, depth_sigma_at_1m: float = 0.0007) -> np.ndarray:
    """Covariances of centres placed by single views from the origin: depth std growing with depth squared."""
    rays = centres[:, :2]
    depth = np.linalg.norm(rays, axis=1)
    return view_covariances(rays, depth_sigma_at_1m * depth, KeyframeConfig().bearing_sigma)


def test_pair_covariance_turns_the_query_and_adds_the_floor() -> None:
    query = np.array([[[4.0, 0.0], [0.0, 0.0]]])  # spread along x only
    stored = np.zeros((1, 2, 2))
    turned = pair_covariances(query, stored, np.pi / 2, 0.5)[0]  # a quarter turn: now along y
    np.testing.assert_allclose(turned, [[0.5, 0.0], [0.0, 4.5]], atol=1e-12)


@pytest.mark.parametrize("yaw_deg", [0.0, 25.0, -170.0])
def test_the_weighted_fit_recovers_an_exact_motion(yaw_deg: float) -> None:
    rng = np.random.default_rng(1)
    stored = np.column_stack([rng.uniform(-30, 30, 7), rng.uniform(-8, 8, 7), rng.uniform(0, 1.5, 7)])
    yaw = np.radians(yaw_deg)
    motion = np.eye(4)
    motion[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    motion[:3, 3] = [120.0, -40.0, 2.0]
    query = transform_points(invert_pose(motion), stored)
    covariances = np.tile(np.diag([0.3, 0.05]), (7, 1, 1))
    fit = fit_weighted(query, stored, covariances, covariances, CONFIG.centre_sigma)
    np.testing.assert_allclose(fit.transform, motion, atol=1e-9)
    assert fit.d2.max() < 1e-12 and yaw_of(fit.transform) == pytest.approx(yaw)


def test_a_far_object_noisy_along_its_ray_does_not_drag_the_weighted_fit() -> None:
    # Four near objects placed exactly, one 45 m away placed 2 m short along its viewing ray (its depth noise):
    # weighted by their covariances the fit stays on the near ones; unweighted it is pulled off them.
    stored = np.array([[8.0, 4.0, 0.0], [10.0, -4.0, 0.0], [14.0, 4.5, 0.0], [16.0, -5.0, 0.0], [45.0, 6.0, 0.0]])
    covariances = _seen_from_origin(stored)
    query = stored.copy()
    query[4, :2] *= 1 - 2.0 / np.linalg.norm(stored[4, :2])
    weighted = fit_weighted(query, stored, covariances, covariances, CONFIG.centre_sigma)
    plain = fit_weighted(query, stored, np.zeros((5, 2, 2)), np.zeros((5, 2, 2)), 1.0)
    assert weighted.distances[:4].max() < 0.1 < plain.distances[:4].max()
    assert weighted.d2[4] < chi2_bound(CONFIG.inlier_probability, 2)  # and the far one is still an inlier


def test_a_far_object_keeps_its_noise_a_near_one_stays_strict() -> None:
    # The same 2.5 m error along the viewing ray: 50 m away it is within the object's gate; 10 m away it is not.
    near = np.array([[6.0, 5.0, 0.0], [9.0, -5.0, 0.0], [13.0, 5.5, 0.0], [17.0, -5.0, 0.0], [21.0, 5.0, 0.0]])
    for extra, kept in [([50.0, 5.0, 0.0], True), ([10.0, 4.0, 0.0], False)]:
        stored_centres = np.vstack([near, extra])
        covariances = _seen_from_origin(stored_centres)
        query_centres = stored_centres.copy()
        ray = query_centres[5, :2] / np.linalg.norm(query_centres[5, :2])
        query_centres[5, :2] += 2.5 * ray
        query = _keyframe(query_centres, covariances=covariances)
        stored = _keyframe(stored_centres, covariances=covariances)
        pairs = np.column_stack([np.arange(6), np.arange(6)])
        fit, inliers = trimmed_fit(query, stored, pairs, CONFIG, needed=4)
        assert fit is not None and bool(inliers[5]) is kept
        fixed = CONFIG.model_copy(update={"tolerances": "fixed"})
        assert not trimmed_fit(query, stored, pairs, fixed, needed=4)[1][5]  # 2.5 m: out, whatever the depth


def test_the_fit_test_is_a_chi_square_bound_on_the_inliers() -> None:
    stored = np.column_stack([np.arange(0.0, 40.0, 5.0), np.tile([5.0, -5.0], 4), np.zeros(8)])
    covariances = np.zeros((8, 2, 2))
    rng = np.random.default_rng(3)
    sigma = np.sqrt(2) * CONFIG.centre_sigma  # the pair's std per axis: the floor of both centres
    trials = []
    for scale in (1.0, 3.0):
        passed = 0
        for _ in range(200):
            query = stored + np.column_stack([rng.normal(0, scale * sigma, (8, 2)), np.zeros(8)])
            passed += fit_consistent(fit_weighted(query, stored, covariances, covariances, CONFIG.centre_sigma), CONFIG)
        trials.append(passed / 200)
    assert trials[0] > 0.98 and trials[1] < 0.05  # right noise passes; three times the noise does not


def test_counterparts_are_found_within_the_radius_or_the_gate() -> None:
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    others = np.array([[4.0, 0.0, 0.0]])  # 4 m off along x, beyond contradiction_radius (2.5 m)
    wide = np.array([[[4.0, 0.0], [0.0, 0.01]]])  # a far view: 2 m depth std along x
    tight = np.zeros((1, 2, 2))
    found = has_counterpart(points[:1], ["car"], wide, others, ["car"], tight, CONFIG)
    assert found.tolist() == [True]
    assert has_counterpart(points[:1], ["car"], tight, others, ["car"], tight, CONFIG).tolist() == [False]
    assert has_counterpart(points[:1], ["truck"], wide, others, ["car"], tight, CONFIG).tolist() == [False]
    fixed = CONFIG.model_copy(update={"tolerances": "fixed"})
    assert has_counterpart(points[:1], ["car"], wide, others, ["car"], tight, fixed).tolist() == [False]


def _row(labels, spacing=6.0, depth_sigma_at_1m=None):
    n = len(labels)
    centres = np.column_stack([np.arange(n) * spacing + 8.0, np.tile([5.0, -5.0], 10)[:n], np.zeros(n)])
    covariances = None if depth_sigma_at_1m is None else _seen_from_origin(centres, depth_sigma_at_1m)
    return _keyframe(centres, labels, covariances)


def _evidence(keyframe: Keyframe, shares=None, contradicted: int = 0) -> float:
    pairs = np.column_stack([np.arange(len(keyframe.labels))] * 2)
    fit = fit_weighted(keyframe.centers, keyframe.centers, keyframe.covariances, keyframe.covariances, 0.35)
    return evidence_bits(keyframe, keyframe, pairs, fit, contradicted, shares, CONFIG)


def test_evidence_grows_with_objects_and_rare_labels_and_falls_with_distance_and_contradictions() -> None:
    five, eight = _row(["car"] * 5), _row(["car"] * 8)
    assert 0 < _evidence(five) < _evidence(eight)
    shares = {"car": 0.85, "bicycle": 0.05}
    with_bicycle = _row(["car"] * 4 + ["bicycle"])
    assert _evidence(with_bicycle, shares) > _evidence(five, shares) + 3  # a rare label says more than a car
    far = _row(["car"] * 5, depth_sigma_at_1m=0.003)  # the same objects known less well
    assert _evidence(far) < _evidence(five)
    assert _evidence(five, contradicted=1) == pytest.approx(_evidence(five) - CONFIG.contradiction_bits)


def test_the_fit_parameters_cost_the_best_pair_and_half_the_next() -> None:
    two = _row(["car"] * 2)
    # Two identical pairs: one is spent fixing the translation, half of the other the yaw.
    one_pair_bits = np.log2(CONFIG.object_area / (2 * np.pi * 2 * CONFIG.centre_sigma**2))
    assert _evidence(two) == pytest.approx(0.5 * one_pair_bits, rel=1e-6)


def test_a_match_needs_more_evidence_the_more_places_it_was_compared_with() -> None:
    stored = _row(["car"] * 6)
    query = _keyframe(stored.centers + [200.0, 50.0, 0.0], stored.labels)
    match = match_keyframes(query, stored, CONFIG, E_MAX)
    assert match.verified
    needed = match.evidence - CONFIG.min_evidence_bits  # log2 of the number of places that makes it too little
    assert match_keyframes(query, stored, CONFIG, E_MAX, tested=int(2 ** (needed - 0.1))).verified
    assert not match_keyframes(query, stored, CONFIG, E_MAX, tested=int(2 ** (needed + 0.1)) + 1).verified
