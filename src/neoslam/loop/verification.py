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
from neoslam.geometry import least_squares_yaw, transform_points
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
    "pair_evidence",
    "evidence_bits",
    "evidence_from",
]

GAUSS_NEWTON_STEPS = 2  # the weighted fit starts at the unweighted one, a step or two from its optimum


@lru_cache(maxsize=4096)
def chi2_bound(probability: float, dof: int) -> float:
    """The chi-square value below which a right fit falls with `probability`, for `dof` degrees of freedom."""
    return float(chi2.ppf(probability, dof))


def _inverse_2x2(matrices: np.ndarray) -> np.ndarray:
    """Inverses of (..., 2, 2) symmetric positive-definite matrices (closed form: many small ones at once)."""
    a, b, d = matrices[..., 0, 0], matrices[..., 0, 1], matrices[..., 1, 1]
    determinant = a * d - b * b
    inverse = np.empty_like(matrices)
    inverse[..., 0, 0], inverse[..., 1, 1] = d / determinant, a / determinant
    inverse[..., 0, 1] = inverse[..., 1, 0] = -b / determinant
    return inverse


def _yaw_rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def pair_covariances(query_cov: np.ndarray, stored_cov: np.ndarray, yaw: float, centre_sigma: float) -> np.ndarray:
    """(k, 2, 2) covariance of each pair's ground-plane residual under a fit turned by `yaw`."""
    return _pair_covariances(query_cov, stored_cov, yaw, _centre_floor(centre_sigma))


def _centre_floor(centre_sigma: float) -> np.ndarray:
    """(2, 2) what `centre_sigma` adds to a pair's covariance, both centres."""
    return 2.0 * centre_sigma**2 * np.eye(2)


def _pair_covariances(query_cov: np.ndarray, stored_cov: np.ndarray, yaw: float, floor: np.ndarray) -> np.ndarray:
    rotation = _yaw_rotation(yaw)
    turned = rotation @ query_cov @ rotation.T
    return turned + stored_cov + floor


class FitResult:
    """A fit of query centres onto stored ones: the (4, 4) transform, its yaw, and the pairs' squared Mahalanobis
    residuals d² (ground plane) and residual lengths (m)."""

    __slots__ = ("transform", "yaw", "d2", "distances")

    def __init__(self, transform: np.ndarray, yaw: float, d2: np.ndarray, distances: np.ndarray) -> None:
        self.transform, self.yaw, self.d2, self.distances = transform, yaw, d2, distances


# A fit's pairs as columns of one (k, 11) array, taken once per trimmed fit and sliced by its inliers: query x, y;
# stored x, y; height offset; the query centre's covariance (a, b, d: [[a, b], [b, d]]); the stored centre's plus
# both centres' floor. The Gauss-Newton sums below are written out over these columns: a fit has a few to a few dozen
# pairs, where numpy's per-call cost over (k, 2, 2) arrays, not the arithmetic, is what a fit takes.
_QX, _QY, _SX, _SY, _DZ, _QA, _QB, _QD, _SA, _SB, _SD = range(11)


def _pair_columns(
    query: np.ndarray, stored: np.ndarray, query_cov: np.ndarray, stored_cov: np.ndarray, centre_sigma: float
) -> np.ndarray:
    floor = 2.0 * centre_sigma**2
    return np.column_stack(
        [
            query[:, 0], query[:, 1], stored[:, 0], stored[:, 1], stored[:, 2] - query[:, 2],
            query_cov[:, 0, 0], query_cov[:, 0, 1], query_cov[:, 1, 1],
            stored_cov[:, 0, 0] + floor, stored_cov[:, 0, 1], stored_cov[:, 1, 1] + floor,
        ]
    )  # fmt: skip


def _weights(pairs: np.ndarray, c: float, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Components (a, b, d) of each pair's information C⁻¹, C = R Σ_q Rᵀ + Σ_s + floor, R turned by (cos, sin)."""
    qa, qb, qd = pairs[:, _QA], pairs[:, _QB], pairs[:, _QD]
    a = c * c * qa - 2.0 * c * s * qb + s * s * qd + pairs[:, _SA]
    d = s * s * qa + 2.0 * c * s * qb + c * c * qd + pairs[:, _SD]
    b = c * s * (qa - qd) + (c * c - s * s) * qb + pairs[:, _SB]
    determinant = a * d - b * b
    return d / determinant, -b / determinant, a / determinant


def _residuals(pairs: np.ndarray, c: float, s: float, tx: float, ty: float) -> tuple[np.ndarray, np.ndarray]:
    """Each pair's residual (x, y): the query centre moved by the fit, minus the stored centre."""
    qx, qy = pairs[:, _QX], pairs[:, _QY]
    return c * qx - s * qy + tx - pairs[:, _SX], s * qx + c * qy + ty - pairs[:, _SY]


def _unweighted_start(pairs: np.ndarray) -> tuple[float, float, float]:
    """Yaw and translation (x, y) of the plain least-squares fit (geometry.fit_yaw_translation, ground plane)."""
    means = pairs[:, :4].mean(axis=0)
    yaw = least_squares_yaw(
        pairs[:, _QX : _QY + 1] - means[_QX : _QY + 1], pairs[:, _SX : _SY + 1] - means[_SX : _SY + 1]
    )
    c, s = math.cos(yaw), math.sin(yaw)
    return yaw, means[_SX] - (c * means[_QX] - s * means[_QY]), means[_SY] - (s * means[_QX] + c * means[_QY])


def _fit_pairs(pairs: np.ndarray) -> FitResult:
    """fit_weighted over pair columns (_pair_columns)."""
    yaw, tx, ty = _unweighted_start(pairs)
    qx, qy = pairs[:, _QX], pairs[:, _QY]
    for _ in range(GAUSS_NEWTON_STEPS):
        c, s = math.cos(yaw), math.sin(yaw)
        wa, wb, wd = _weights(pairs, c, s)
        rx, ry = _residuals(pairs, c, s, tx, ty)
        jx, jy = -s * qx - c * qy, c * qx - s * qy  # ∂r/∂yaw; ∂r/∂translation is I
        ux, uy = wa * jx + wb * jy, wb * jx + wd * jy  # W J, yaw's column
        sums = np.stack([jx * ux + jy * uy, ux, uy, wa, wb, wd, ux * rx + uy * ry, wa * rx + wb * ry,
                         wb * rx + wd * ry]).sum(axis=1)  # fmt: skip
        hessian = sums[[0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(3, 3)  # Jᵀ W J
        try:
            step = -np.linalg.solve(hessian, sums[6:])  # Jᵀ W r
        except np.linalg.LinAlgError:
            break  # degenerate geometry: keep the current fit
        yaw += float(step[0])
        tx, ty = tx + float(step[1]), ty + float(step[2])
        if np.abs(step).max() < 1e-9:
            break
    c, s = math.cos(yaw), math.sin(yaw)
    rx, ry = _residuals(pairs, c, s, tx, ty)
    wa, wb, wd = _weights(pairs, c, s)
    d2 = wa * rx * rx + 2.0 * wb * rx * ry + wd * ry * ry
    transform = np.eye(4)
    transform[:2, :2] = [[c, -s], [s, c]]
    transform[:3, 3] = tx, ty, float(pairs[:, _DZ].mean())
    return FitResult(transform, yaw, d2, np.sqrt(rx * rx + ry * ry))


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
    return _fit_pairs(_pair_columns(query, stored, query_cov, stored_cov, centre_sigma))


def trimmed_fit(
    query: Keyframe, stored: Keyframe, pairs: np.ndarray, config: MatchingConfig, needed: float
) -> tuple[FitResult | None, np.ndarray]:
    """The weighted fit of the pairs (k, 2) (query object, stored object), trimmed: drop the worst pair (by d²) and
    refit until every pair is within the chi-square gate and `max_inlier_distance` (least squares alone lets one
    wrong match drag the fit off all the right ones). Gives up once fewer than `needed` pairs are left, which can
    no longer be verified. Returns the fit (None when given up) and the inlier mask."""
    gate = chi2_bound(config.inlier_probability, 2)
    inliers = np.ones(len(pairs), dtype=bool)
    q_all, s_all = query.centers[pairs[:, 0]], stored.centers[pairs[:, 1]]
    if config.tolerances == "fixed":  # equal weights: the plain least-squares fit
        q_cov = s_cov = np.zeros((len(pairs), 2, 2))
        sigma = 1.0
    else:
        q_cov, s_cov = query.covariances[pairs[:, 0]], stored.covariances[pairs[:, 1]]
        sigma = config.centre_sigma
    columns = _pair_columns(q_all, s_all, q_cov, s_cov, sigma)
    while inliers.sum() >= max(needed, 2):
        fit = _fit_pairs(columns[inliers])
        if config.tolerances == "fixed":
            excess = fit.distances / config.inlier_distance
        else:
            excess = np.maximum(fit.d2 / gate, fit.distances / config.max_inlier_distance)
        worst = int(np.argmax(excess))
        if excess[worst] <= 1.0:
            return fit, inliers
        inliers[np.flatnonzero(inliers)[worst]] = False
    return None, inliers


def fit_consistent(fit: FitResult, config: MatchingConfig) -> bool:
    """Whether the inliers' Σ d² stays within the chi-square bound of `fit_probability` (2k - 3 degrees of
    freedom): the matched objects sit where their covariances allow, not merely each within the gate. With
    `tolerances: fixed`, whether their RMS residual is at most `max_fit_residual`."""
    if config.tolerances == "fixed":
        return bool(np.sqrt(np.mean(fit.distances**2)) <= config.max_fit_residual)
    dof = max(2 * len(fit.d2) - 3, 1)
    return bool(fit.d2.sum() <= chi2_bound(config.fit_probability, dof))


def _ground(centres: np.ndarray, robot: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius (ground plane) of what a keyframe covers: its current object, the one nearest the robot
    (paper 3.2), and the farthest of its objects from it."""
    current = centres[np.argmin(np.linalg.norm(centres[:, :2] - robot[:2], axis=1)), :2]
    return current, float(np.linalg.norm(centres[:, :2] - current, axis=1).max())


def in_view(points: np.ndarray, views: np.ndarray, half_angle_deg: float) -> np.ndarray:
    """Bool per ground point (n, 2): within `half_angle_deg` of the heading of one of the views (m, 3) of x, y,
    yaw, seen from its position."""
    offset = points[:, None, :] - views[None, :, :2]
    bearing = np.arctan2(offset[..., 1], offset[..., 0]) - views[None, :, 2]
    off_axis = np.abs((bearing + np.pi) % (2.0 * np.pi) - np.pi)
    return (off_axis <= np.radians(half_angle_deg)).any(axis=1)


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
    same = np.asarray(labels)[:, None] == np.asarray(other_labels)[None, :]
    offset = points[:, None, :2] - others[None, :, :2]
    near = np.linalg.norm(offset, axis=2) <= config.contradiction_radius
    if config.tolerances == "fixed":
        return (same & near).any(axis=1)
    combined = covariances[:, None] + other_covariances[None, :] + 2.0 * config.centre_sigma**2 * np.eye(2)
    d2 = np.einsum("abi,abij,abj->ab", offset, _inverse_2x2(combined), offset)
    return (same & (near | (d2 <= chi2_bound(config.inlier_probability, 2)))).any(axis=1)


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
    moved = transform_points(transform, query.centers)
    moved_cov = _turned(query.covariances, transform)
    query_centre, query_radius = _ground(moved, (transform @ query.pose)[:3, 3])
    stored_centre, stored_radius = _ground(stored.centers, stored.pose[:3, 3])
    query_views = moved_views(query.views, transform)
    positions, names, seen = [], [], []
    for points, labels, cov, known, others, other_labels, other_cov, centre, radius, views in (
        (moved, query.labels, moved_cov, ~query.provisional, stored.centers, stored.labels, stored.covariances,
         stored_centre, stored_radius, stored.views),
        (stored.centers, stored.labels, stored.covariances, ~stored.provisional, moved, query.labels, moved_cov,
         query_centre, query_radius, query_views),
    ):  # fmt: skip
        inside = known & (np.linalg.norm(points[:, :2] - centre, axis=1) <= radius - config.contradiction_margin)
        labels_inside = np.asarray(labels)[inside]
        found = has_counterpart(points[inside], labels_inside, cov[inside], others, other_labels, other_cov, config)
        missed = points[inside][~found, :2]
        positions.append(missed)
        names.extend(labels_inside[~found].tolist())
        seen.append(in_view(missed, views, config.contradiction_view_deg))
    return np.concatenate(positions), tuple(names), np.concatenate(seen)


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
    covariances = pair_covariances(
        query.covariances[pairs[:, 0]], stored.covariances[pairs[:, 1]], fit.yaw, config.centre_sigma
    )
    shares = label_shares or {}
    label_bits = -np.log2([shares.get(query.labels[i], 1.0) for i in pairs[:, 0]])
    likelihood = np.exp(-0.5 * fit.d2) / (2.0 * np.pi * np.sqrt(np.linalg.det(covariances)))  # N(r; 0, C)
    place_bits = np.log2(likelihood * config.object_area)  # against one object per object_area m², any label
    bits = np.maximum(place_bits + label_bits, 0.0)
    # fixing the fit's 3 parameters took where the best pair and half the next stand, not what they are
    spent = np.sort(np.clip(place_bits, 0.0, bits))[::-1]
    return bits, float(spent[0] + 0.5 * spent[1] if len(spent) > 1 else spent.sum())


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
