"""Keyframe matching (paper eq. 2-5) and its verification.

Candidate assignments (i, i') pair a query object with a stored one of the same label (H^l, eq. 3) whose
appearance patches differ by at most the RMSE threshold. Over these candidates only, the affinity
M_(a,b) = max(0, e_max − |e_ij − e_i'j'|) (eq. 2, 4) rewards pairs of assignments that keep the distance between
their objects; X* = argmax Xᵀ M X (eq. 5) is approximated by spectral matching: the principal eigenvector of M,
then a greedy discretisation that takes candidates in order of their weight and drops those in conflict. With
`tolerances: covariance` (the default), the tolerance e_max of a pair of assignments widens to `affinity_sigmas`
standard deviations of |e_ij − e_i'j'| where the four centres' covariances make it larger: far objects are allowed
their depth noise, near ones keep the paper's e_max. M is then e_max · max(0, 1 − |e_ij − e_i'j'| / tolerance).

Verification keeps precision: a match must be supported by other matches with consistent distances, then a
rigid 4-DoF fit (yaw, translation) of the matched centres must explain at least `min_inliers` of them (and
`min_inlier_ratio` of the smaller keyframe), each within its chi-square gate, with a residual its covariances allow
(loop.verification; `tolerances: fixed`: within `inlier_distance` in the ground plane and an RMS residual of at
most `max_fit_residual`, whatever the objects' distances). The fit is also the metric constraint between the two
keyframes. Most pairs of keyframes share no place: a match that can no longer reach the number of matches it needs
is given up as soon as that shows, before or during the fit. Last, the fit must not be contradicted: objects of
either keyframe that the fit puts well inside the other's ground should find an object of their label there. A
street whose layout shares a regular stretch with another (cars parked every few metres) fits on that stretch, but
the bicycles, trucks and gaps around it do not follow.

Objects a keyframe holds as provisional (not known to be static yet: moving_objects.unjudged wait) are matched as
any other and count in the share of objects a match must explain, but not as contradictions: a car that has driven
on is not there when the place is seen again. (Leaving them out of that share as well let two false closures through
on simulated KITTI 00 with `heavy` odometry, where parked objects are often provisional.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import MatchingConfig
from neoslam.loop import kernels
from neoslam.loop.verification import (
    centre_floor,
    contradicted_objects,
    contradictions,
    evidence_from,
    fit_consistent,
    pair_evidence,
    trimmed_fit,
)
from neoslam.types import Keyframe

__all__ = [
    "KeyframeMatch",
    "MatchSide",
    "match_side",
    "candidate_assignments",
    "affinity_matrix",
    "principal_eigenvector",
    "spectral_matching",
    "contradictions",
    "distance_variances",
    "match_keyframes",
]


@dataclass(frozen=True)
class KeyframeMatch:
    """The outcome of matching a query keyframe against a stored one."""

    query: int
    match: int
    score: float  # X*ᵀ M X / e_max of the spectral solution: about the number of consistent pairs (paper: > 1)
    pairs: np.ndarray  # (k, 2) (query object, stored object) index pairs: verified, or as far as matching got
    transform: np.ndarray  # (4, 4) maps query world points onto the stored keyframe's world points
    residual_rms: float  # m, of the verified pairs under `transform`
    verified: bool
    verified_score: float  # the score over the verified pairs only; 0 when the match is not verified
    evidence: float = 0.0  # bits that the fit shows one place (loop.verification); 0 when it got no fit
    pair_bits: np.ndarray | None = None  # (k,) each verified pair's bits (loop.verification.pair_evidence)
    spent_bits: float = 0.0  # what fixing the fit spent of them
    contradicted: np.ndarray | None = None  # (m, 2) ground positions of the contradicted objects, stored world
    contradicted_labels: tuple[str, ...] = ()
    contradicted_in_view: np.ndarray | None = None  # (m,) bool: in view of the other keyframe (verification)

    @property
    def n_matches(self) -> int:
        return len(self.pairs)


@dataclass(frozen=True)
class MatchSide:
    """What matching uses of one keyframe, worked out once for it: a query is matched against up to
    `matching.candidates` places."""

    keyframe: Keyframe
    labels: np.ndarray  # (n,) label codes (loop.kernels.label_codes)
    patches: np.ndarray  # (n, p) grey levels, float: the keyframe's own when they are floats
    patch_squares: np.ndarray  # (n,) sum of squares of each patch
    variances: np.ndarray | None  # (n, n) distance_variances with `tolerances: covariance`, else None

    @property
    def nbytes(self) -> int:
        """Memory held beside the keyframe's own arrays, bytes."""
        variances = 0 if self.variances is None else self.variances.nbytes
        patches = 0 if np.may_share_memory(self.patches, self.keyframe.patches) else self.patches.nbytes
        return self.labels.nbytes + patches + self.patch_squares.nbytes + variances


def match_side(keyframe: Keyframe | MatchSide, config: MatchingConfig) -> MatchSide:
    """The keyframe's side of a match (a MatchSide is given back as it is)."""
    if isinstance(keyframe, MatchSide):
        return keyframe
    rows = keyframe.patches
    patches = np.asarray(rows.reshape(len(rows), int(np.prod(rows.shape[1:]))), dtype=float)  # 0 rows too
    variances = None if config.tolerances == "fixed" else distance_variances(keyframe, config.centre_sigma)
    (codes,) = kernels.label_codes(keyframe.labels)
    return MatchSide(keyframe, codes, patches, (patches**2).sum(1), variances)


def _patch_rmse(query: MatchSide, stored: MatchSide) -> np.ndarray:
    """(n, m) RMSE between every query and stored patch, grey levels."""
    q, s = query.patches, stored.patches
    squared = query.patch_squares[:, None] + stored.patch_squares[None, :] - 2 * q @ s.T
    return np.sqrt(np.maximum(squared, 0.0) / q.shape[1])


def candidate_assignments(
    query: Keyframe | MatchSide, stored: Keyframe | MatchSide, config: MatchingConfig
) -> np.ndarray:
    """(c, 2) pairs (i, i') with equal labels (H^l, eq. 3) and similar appearance (RMSE <= threshold)."""
    query, stored = match_side(query, config), match_side(stored, config)
    same_label = query.labels[:, None] == stored.labels[None, :]
    similar = _patch_rmse(query, stored) <= config.appearance_rmse_threshold
    return np.argwhere(same_label & similar)


def distance_variances(keyframe: Keyframe, centre_sigma: float) -> np.ndarray:
    """(n, n) variance of each pairwise distance e_ij (eq. 1), from the two centres' ground-plane covariances along
    the line between them, each with `centre_sigma` added."""
    return kernels.distance_variances(kernels.plane(keyframe.centers), keyframe.covariances, centre_floor(centre_sigma))


def affinity_matrix(
    query: Keyframe | MatchSide,
    stored: Keyframe | MatchSide,
    candidates: np.ndarray,
    e_max: float,
    config: MatchingConfig | None = None,
) -> np.ndarray:
    """M over the candidates (eq. 2, 4): e_max − |e_ij − e_i'j'| clipped at 0, or with `tolerances: covariance`
    e_max · (1 − |e_ij − e_i'j'| / tolerance) clipped at 0, the tolerance at least e_max and `affinity_sigmas`
    standard deviations of the difference; 0 for assignments in conflict. Without a config: the paper's form."""
    starts, columns, values = _sparse_affinity(query, stored, candidates, e_max, config)
    dense = np.zeros((len(starts) - 1, len(starts) - 1))
    dense[np.repeat(np.arange(len(starts) - 1), np.diff(starts)), columns] = values
    return dense


def _sparse_affinity(
    query: Keyframe | MatchSide,
    stored: Keyframe | MatchSide,
    candidates: np.ndarray,
    e_max: float,
    config: MatchingConfig | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """affinity_matrix as compressed rows (starts, columns, values) of its non-zero entries, as matching uses it."""
    query_keyframe = query.keyframe if isinstance(query, MatchSide) else query
    stored_keyframe = stored.keyframe if isinstance(stored, MatchSide) else stored
    covariance = config is not None and config.tolerances != "fixed"
    if covariance:
        query, stored = match_side(query, config), match_side(stored, config)
        query_variances, stored_variances, sigmas = query.variances, stored.variances, config.affinity_sigmas
    else:
        query_variances = stored_variances = np.zeros((0, 0))
        sigmas = 0.0
    query_objects, stored_objects = _objects(candidates)
    return kernels.affinity(
        query_keyframe.distances, stored_keyframe.distances, query_variances, stored_variances, query_objects,
        stored_objects, float(e_max), float(sigmas), covariance,
    )  # fmt: skip


def _objects(candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The query and stored objects of (c, 2) candidate assignments, as the kernels take them."""
    candidates = np.asarray(candidates, dtype=np.int64).reshape(-1, 2)
    return np.ascontiguousarray(candidates[:, 0]), np.ascontiguousarray(candidates[:, 1])


def principal_eigenvector(affinity: np.ndarray, iterations: int = 100, tolerance: float = 1e-9) -> np.ndarray:
    """Power iteration from the all-ones vector: M is symmetric and non-negative, so the principal eigenvector is
    non-negative (Perron-Frobenius) and converges in a few dozen products, far cheaper than a full eigensolver.
    Iterating on M + I keeps the same eigenvectors and breaks the tie of eigenvalues +λ and −λ (a bipartite
    consistency graph), on which plain iteration oscillates. Stops after `iterations` products or once no entry
    moves by more than `tolerance`."""
    return kernels.principal_eigenvector(*kernels.compressed(np.asarray(affinity, dtype=float)), iterations, tolerance)


def spectral_matching(affinity: np.ndarray, candidates: np.ndarray, config: MatchingConfig | None = None) -> np.ndarray:
    """Indices into `candidates` of X* (eq. 5): principal eigenvector, then greedy conflict-free discretisation."""
    return _spectral(kernels.compressed(np.asarray(affinity, dtype=float)), candidates, config or MatchingConfig())


def _spectral(
    affinity: tuple[np.ndarray, np.ndarray, np.ndarray], candidates: np.ndarray, config: MatchingConfig
) -> np.ndarray:
    """spectral_matching of M as compressed rows."""
    if len(candidates) == 0:
        return np.empty(0, dtype=int)
    weight = kernels.principal_eigenvector(*affinity, config.power_iterations, config.power_tolerance)
    query_objects, stored_objects = _objects(candidates)
    n_query, n_stored = int(query_objects.max()) + 1, int(stored_objects.max()) + 1
    return kernels.greedy_assignment(weight, query_objects, stored_objects, n_query, n_stored)


def _supported(affinity: np.ndarray, chosen: np.ndarray, min_support: int) -> np.ndarray:
    """Repeatedly drop matches with fewer than `min_support` distance-consistent partners among the others."""
    return kernels.supported(affinity, np.asarray(chosen, dtype=np.int64), min_support)


def _required_matches(query: Keyframe, stored: Keyframe, config: MatchingConfig) -> float:
    """Verified matches needed: `min_inliers`, and `min_inlier_ratio` of the smaller keyframe's objects."""
    return max(config.min_inliers, 2, config.min_inlier_ratio * min(len(query.labels), len(stored.labels)))


def _unverified(query: Keyframe, stored: Keyframe, score: float, pairs: np.ndarray) -> KeyframeMatch:
    """A match that failed verification, with the pairs it got as far as."""
    return KeyframeMatch(query.id, stored.id, score, pairs, np.eye(4), float("inf"), False, 0.0)


def match_keyframes(
    query: Keyframe | MatchSide,
    stored: Keyframe | MatchSide,
    config: MatchingConfig,
    e_max: float,
    label_shares: dict[str, float] | None = None,
    tested: int = 1,
) -> KeyframeMatch:
    """Match two keyframes and verify the result (see the module docstring); `label_shares`, each label's share
    among the stored objects, weighs the evidence of a match (loop.verification.evidence_bits), and `tested`, the
    number of stored places the query could have matched, raises the evidence needed by log2 of it: the more places
    are compared, the likelier one of them aligns by chance. Either keyframe may be given as its MatchSide (made
    with the same config), worked out once for many matches."""
    query_side, stored_side = match_side(query, config), match_side(stored, config)
    query, stored = query_side.keyframe, stored_side.keyframe
    candidates = candidate_assignments(query_side, stored_side, config)
    affinity = _sparse_affinity(query_side, stored_side, candidates, e_max, config)
    needed = _required_matches(query, stored, config)
    chosen = _spectral(affinity, candidates, config)
    # M among the chosen assignments, all that the score and the support test read
    among = kernels.block(*affinity, chosen)
    score = kernels.group_sum(among, np.arange(len(chosen))) / e_max
    supported = _supported(among, np.arange(len(chosen)), config.min_support)  # positions in chosen
    kept = chosen[supported]
    pairs = candidates[kept]
    if len(kept) < needed or score <= config.score_threshold:
        return _unverified(query, stored, score, pairs)
    fit, inliers = trimmed_fit(query, stored, pairs, config, needed)
    supported, pairs = supported[inliers], pairs[inliers]
    if fit is None or len(pairs) < needed:
        return _unverified(query, stored, score, pairs)
    residual_rms = float(np.sqrt(np.mean(fit.distances**2)))
    against, against_labels, in_view = contradicted_objects(query, stored, fit.transform, config)
    bits, spent = pair_evidence(query, stored, pairs, fit, label_shares, config)
    evidence = evidence_from(bits, spent, len(against_labels), config, len(in_view) - np.count_nonzero(in_view))
    verified = bool(
        fit_consistent(fit, config)
        and np.count_nonzero(in_view) <= config.max_contradictions
        and (config.tolerances == "fixed" or evidence >= config.min_evidence_bits + np.log2(max(tested, 1)))
    )
    verified_score = kernels.group_sum(among, supported) / e_max if verified else 0.0
    return KeyframeMatch(
        query.id, stored.id, score, pairs, fit.transform, residual_rms, verified, verified_score, evidence, bits, spent,
        against, against_labels, in_view,
    )  # fmt: skip
