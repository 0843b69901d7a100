"""Verification of a keyframe match: a rigid 4-DoF fit (yaw, translation) of the matched object centres that knows
each centre's uncertainty, and the checks that the fit explains the place.

Stereo depth error grows with the square of the depth, so a keyframe object 40 m from the views that placed it is
known to a metre along their rays and to centimetres across them, one 10 m away to a few decimetres. A fixed
tolerance in metres is then too strict for far objects and too loose for near ones. Here each matched pair's
residual r (query centre moved by the fit, minus the stored centre, ground plane) is judged by its covariance
C = R Σ_q Rᵀ + Σ_s + 2 σ_c² I (the two centres' covariances from their views, the query's turned by the fit's yaw,
and `matching.centre_sigma` for what no number of views averages away: the footprint model that moves a view from
the visible surface to the object's middle, and the odometry's drift within the keyframe's window):
d² = rᵀ C⁻¹ r is chi-square with 2 degrees of freedom for a right pair.

- The fit minimises Σ d² (Gauss-Newton from the unweighted least-squares fit), trimmed: the worst pair is dropped
  and the fit redone until every pair is within the chi-square gate of `inlier_probability`, and, as a bound in
  metres whatever the covariances, within `max_inlier_distance`.
- The fit is consistent when Σ d² over the inliers stays within the chi-square bound of `fit_probability` with
  2k - 3 degrees of freedom (k pairs, 3 parameters).
- A contradiction is an object of either keyframe well inside the other's ground with no object of its label there
  within `contradiction_radius`, or within the chi-square gate of the two centres' covariances. It is in view when
  it also stands within `contradiction_view_deg` of the heading of one of the robot poses the other's objects were
  seen from: only those count against `max_contradictions`, since an object at the edge of the camera's view is
  seen by one pass and missed by another that looked a few degrees away, and cost `contradiction_bits` (the others
  `out_of_view_contradiction_bits`).
- The match must carry enough evidence that the two keyframes show one place and not two streets that happen to
  align: in bits, the log-likelihood ratio of the inliers' residuals, Σ log2(N(r; 0, C) / ρ_label), where ρ_label is
  the density of objects of the pair's label (one per `object_area` m² of street, times the label's share among the
  stored objects): how much likelier the object sits where it does if the places are one than if a stranger of its
  label happened to stand there. A far object's wide covariance and a common label give little, a near truck fitted
  closely much. The fit's three parameters are chosen to make the pairs coincide, so the pairs' bits overstate the
  evidence by what fixing them took: one pair fixes the translation (any first pair can be made to coincide) and
  half of another the yaw; the position bits of the best pair and half the next are left out of the sum (their
  labels still count: a stranger of a rare label is rarely there to be aligned with). Each contradiction
  costs `contradiction_bits`; a match needs `min_evidence_bits`. Five parked cars in a row fit another row of cars
  now and then; eight objects, or five near ones and a bicycle, rarely.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.stats import chi2

from neoslam.config import MatchingConfig
from neoslam.geometry import transform_points
from neoslam.loop import kernels
from neoslam.types import Keyframe, moved_views

__all__ = [
    "FitResult",
    "pair_covariances",
    "fit_weighted",
    "trimmed_fit",
    "fit_consistent",
    "contradictions",
    "contradicted_objects",
    "has_counterpart",
    "in_view",
    "chi2_bound",
    "centre_floor",
    "pair_evidence",
    "evidence_bits",
    "evidence_from",
]

GAUSS_NEWTON_STEPS = 2  # the weighted fit starts at the unweighted one, a step or two from its optimum


@lru_cache(maxsize=4096)
def chi2_bound(probability: float, dof: int) -> float:
    """The chi-square value below which a right fit falls with `probability`, for `dof` degrees of freedom."""
    return float(chi2.ppf(probability, dof))


def centre_floor(centre_sigma: float) -> float:
    """The variance `matching.centre_sigma` adds along each axis to a pair of centres (both of them): 2 σ_c²."""
    return 2.0 * centre_sigma**2


def pair_covariances(query_cov: np.ndarray, stored_cov: np.ndarray, yaw: float, centre_sigma: float) -> np.ndarray:
    """(k, 2, 2) covariance of each pair's ground-plane residual under a fit turned by `yaw`:
    C = R Σ_q Rᵀ + Σ_s + 2 σ_c² I."""
    return kernels.pair_covariances(
        np.asarray(query_cov, dtype=float), np.asarray(stored_cov, dtype=float), float(yaw), centre_floor(centre_sigma)
    )


class FitResult:
    """A fit of query centres onto stored ones: the (4, 4) transform, its yaw, and the pairs' squared Mahalanobis
    residuals d² (ground plane) and residual lengths (m)."""

    __slots__ = ("transform", "yaw", "d2", "distances")

    def __init__(self, transform: np.ndarray, yaw: float, d2: np.ndarray, distances: np.ndarray) -> None:
        self.transform, self.yaw, self.d2, self.distances = transform, yaw, d2, distances


# A fit's pairs as columns of one (k, 11) array, taken once per trimmed fit: query x, y; stored x, y; height offset;
# the query centre's covariance (a, b, d: [[a, b], [b, d]]); the stored centre's plus both centres' floor. The
# Gauss-Newton sums over them are written out in loop.kernels: a fit has a few to a few dozen pairs, where numpy's
# per-call cost over (k, 2, 2) arrays, not the arithmetic, is what a fit took.
def _pair_columns(
    query: np.ndarray, stored: np.ndarray, query_cov: np.ndarray, stored_cov: np.ndarray, centre_sigma: float
) -> np.ndarray:
    return kernels.pair_columns(
        np.asarray(query, dtype=float), np.asarray(stored, dtype=float), np.asarray(query_cov, dtype=float),
        np.asarray(stored_cov, dtype=float), centre_floor(centre_sigma),
    )  # fmt: skip


def _fit_result(yaw: float, tx: float, ty: float, tz: float, d2: np.ndarray, distances: np.ndarray) -> FitResult:
    transform = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    transform[:2, :2] = [[c, -s], [s, c]]
    transform[:3, 3] = tx, ty, tz
    return FitResult(transform, yaw, d2, distances)


def fit_weighted(
    query: np.ndarray,
    stored: np.ndarray,
    query_cov: np.ndarray,
    stored_cov: np.ndarray,
    centre_sigma: float,
) -> FitResult:
    """Yaw and translation minimising Σ d² of the pairs (query (k, 3) -> stored (k, 3) centres, their (k, 2, 2)
    ground-plane covariances), by Gauss-Newton from the unweighted least-squares fit; the height offset is the mean
    one (objects' heights say little about a place)."""
    columns = _pair_columns(query, stored, query_cov, stored_cov, centre_sigma)
    return _fit_result(*kernels.fit_pairs(columns, GAUSS_NEWTON_STEPS))


def trimmed_fit(
    query: Keyframe, stored: Keyframe, pairs: np.ndarray, config: MatchingConfig, needed: float
) -> tuple[FitResult | None, np.ndarray]:
    """The weighted fit of the pairs (k, 2) (query object, stored object), trimmed: drop the worst pair (by d²) and
    refit until every pair is within the chi-square gate and `max_inlier_distance` (least squares alone lets one
    wrong match drag the fit off all the right ones). Gives up once fewer than `needed` pairs are left, which can
    no longer be verified. Returns the fit (None when given up) and the inlier mask."""
    gate = chi2_bound(config.inlier_probability, 2)
    q_all, s_all = query.centers[pairs[:, 0]], stored.centers[pairs[:, 1]]
    fixed = config.tolerances == "fixed"
    if fixed:  # equal weights: the plain least-squares fit
        q_cov = s_cov = np.zeros((len(pairs), 2, 2))
        sigma = 1.0
    else:
        q_cov, s_cov = query.covariances[pairs[:, 0]], stored.covariances[pairs[:, 1]]
        sigma = config.centre_sigma
    columns = _pair_columns(q_all, s_all, q_cov, s_cov, sigma)
    bound = config.inlier_distance if fixed else config.max_inlier_distance
    found, *fit, inliers = kernels.trimmed(columns, GAUSS_NEWTON_STEPS, float(needed), gate, bound, fixed)
    return (_fit_result(*fit) if found else None), inliers


def fit_consistent(fit: FitResult, config: MatchingConfig) -> bool:
    """Whether the inliers' Σ d² stays within the chi-square bound of `fit_probability` (2k - 3 degrees of
    freedom): the matched objects sit where their covariances allow, not merely each within the gate. With
    `tolerances: fixed`, whether their RMS residual is at most `max_fit_residual`."""
    if config.tolerances == "fixed":
        return bool(np.sqrt(np.mean(fit.distances**2)) <= config.max_fit_residual)
    dof = max(2 * len(fit.d2) - 3, 1)
    return bool(fit.d2.sum() <= chi2_bound(config.fit_probability, dof))


def in_view(points: np.ndarray, views: np.ndarray, half_angle_deg: float) -> np.ndarray:
    """Bool per ground point (n, 2): within `half_angle_deg` of the heading of one of the views (m, 3) of x, y,
    yaw, seen from its position."""
    return kernels.in_view(kernels.plane(points), kernels.plane(views, 3), math.radians(half_angle_deg))


def has_counterpart(
    points: np.ndarray,
    labels,
    covariances: np.ndarray,
    others: np.ndarray,
    other_labels,
    other_covariances: np.ndarray,
    config: MatchingConfig,
) -> np.ndarray:
    """Bool per point: an object of the same label stands among the others within `contradiction_radius` or (with
    `tolerances: covariance`) within the chi-square gate of the two centres' covariances (ground plane; covariances
    in one frame)."""
    codes, other_codes = kernels.label_codes(labels, other_labels)
    return kernels.counterparts(
        kernels.plane(points), codes, np.asarray(covariances, dtype=float), kernels.plane(others), other_codes,
        np.asarray(other_covariances, dtype=float), *_counterpart_tolerances(config),
    )  # fmt: skip


def _counterpart_tolerances(config: MatchingConfig) -> tuple[float, float, float, bool]:
    """What kernels.counterparts asks: the radius, the d² gate, the floor of a centre's covariance and whether the
    covariances count (`tolerances: covariance`)."""
    return (
        config.contradiction_radius, chi2_bound(config.inlier_probability, 2), centre_floor(config.centre_sigma),
        config.tolerances != "fixed",
    )  # fmt: skip


def _turned(covariances: np.ndarray, transform: np.ndarray) -> np.ndarray:
    rotation = transform[:2, :2]
    return rotation @ covariances @ rotation.T


def contradictions(query: Keyframe, stored: Keyframe, transform: np.ndarray, config: MatchingConfig) -> int:
    """Objects of either keyframe that the fit (query world -> stored world) puts at least `contradiction_margin`
    inside the other keyframe's ground with no counterpart there (has_counterpart); provisional objects (not known
    to be static) are not counted."""
    return len(contradicted_objects(query, stored, transform, config)[1])


def contradicted_objects(
    query: Keyframe, stored: Keyframe, transform: np.ndarray, config: MatchingConfig
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """The contradicted objects (contradictions): their ground positions (m, 2) in the stored world, labels, and
    whether each stands in view of the other keyframe (in_view with `contradiction_view_deg` of one of the robot
    poses its objects were seen from)."""
    moved = kernels.plane(transform_points(transform, query.centers))
    moved_cov = np.ascontiguousarray(_turned(query.covariances, transform))
    stored_points = kernels.plane(stored.centers)
    query_codes, stored_codes = kernels.label_codes(query.labels, stored.labels)
    query_robot, stored_robot = (transform @ query.pose)[:2, 3].copy(), stored.pose[:2, 3].copy()
    query_missed, stored_missed = kernels.missed_objects(
        (moved, query_codes, moved_cov, ~query.provisional, query_robot),
        (stored_points, stored_codes, stored.covariances, ~stored.provisional, stored_robot),
        config.contradiction_margin, _counterpart_tolerances(config),
    )  # fmt: skip
    names = [label for label, out in zip(query.labels, query_missed.tolist(), strict=True) if out]
    names += [label for label, out in zip(stored.labels, stored_missed.tolist(), strict=True) if out]
    points = np.concatenate([moved[query_missed], stored_points[stored_missed]])
    if not names:
        return points, (), np.zeros(0, dtype=bool)
    seen = [
        in_view(moved[query_missed], stored.views, config.contradiction_view_deg),
        in_view(stored_points[stored_missed], moved_views(query.views, transform), config.contradiction_view_deg),
    ]
    return points, tuple(names), np.concatenate(seen)


def pair_evidence(
    query: Keyframe,
    stored: Keyframe,
    pairs: np.ndarray,
    fit: FitResult,
    label_shares: dict[str, float] | None,
    config: MatchingConfig,
) -> tuple[np.ndarray, float]:
    """Each inlier pair's bits (k,) and the bits spent fixing the fit's parameters (module docstring): the evidence
    before contradictions is their sum minus what was spent. `label_shares`: each label's share among the stored
    objects (None or a missing label: 1, nothing from labels). A pair gives no negative evidence: a stranger in the
    gate is as likely as a bad fit of a right one."""
    shares = label_shares or {}
    label_shares_of_pairs = np.array([shares.get(query.labels[i], 1.0) for i in pairs[:, 0].tolist()])
    bits, spent = kernels.pair_bits(
        query.covariances[pairs[:, 0]], stored.covariances[pairs[:, 1]], fit.yaw, centre_floor(config.centre_sigma),
        np.asarray(fit.d2, dtype=float), label_shares_of_pairs, config.object_area,
    )  # fmt: skip
    return bits, float(spent)


def evidence_bits(
    query: Keyframe,
    stored: Keyframe,
    pairs: np.ndarray,
    fit: FitResult,
    contradicted: int,
    label_shares: dict[str, float] | None,
    config: MatchingConfig,
) -> float:
    """The evidence (bits) that the inlier pairs (k, 2), with the fit's d², show one place (module docstring):
    pair_evidence, less `contradiction_bits` for each of the `contradicted` objects."""
    bits, spent = pair_evidence(query, stored, pairs, fit, label_shares, config)
    return evidence_from(bits, spent, contradicted, config)


def evidence_from(
    bits: np.ndarray, spent: float, contradicted: int, config: MatchingConfig, out_of_view: int = 0
) -> float:
    """A match's evidence from its pairs' bits and what fixing the fit spent (pair_evidence), less
    `contradiction_bits` for each contradicted object in view of the other keyframe and
    `out_of_view_contradiction_bits` for each of the `out_of_view` others among the `contradicted`."""
    in_view = contradicted - out_of_view
    cost = config.contradiction_bits * in_view + config.out_of_view_contradiction_bits * out_of_view
    return float(bits.sum() - spent - cost)
