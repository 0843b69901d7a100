"""Where revisits are lost: the loop detector replayed over a drive's keyframes, every keyframe stored, and each
keyframe that truly revisits a place but gets no true closure put in one class, with the detector's state as it was
when the keyframe was queried.

Ground truth is read here only, for the judgement, never by the detector. The true place of a keyframe is the
stored keyframe nearest to it in truth (at least the evaluation's frame gap earlier, within its distance); the place
the detector would match for it is that keyframe's place (loop.places), and the query its query window.

- relocalised alone: the detector relocalised it at the true place, but no consecutive keyframe confirmed it;
- relocalised elsewhere: it relocalised at another place (a false or a too distant match);
- not retrieved: the true place is not among the places the detector tried (retrieval);
- too few shared objects: fewer objects of the query window and the true place stand at one place in truth than a
  match needs;
- matching fails: enough shared objects, but the spectral matching and its support, or the trimmed fit, keep fewer
  pairs than needed;
- verification rejects: the fit is found, but its chi-square test, contradictions or evidence reject it;
- drift, place, turn or ambiguity: the match verifies, and the drift prior (the evidence less what the fit's move
  of the robot costs), the robot's offset from the place, the fit's turn, or another place verifying as well
  reject it.

Also the retrieval rank of each revisit keyframe's true place among the places tried (0: first), and whether the
place appears among the first `candidates`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from neoslam.config import NeoSLAMConfig
from neoslam.evaluation.loops import LoopCriteria, judge_closures, true_revisits
from neoslam.geometry import invert_pose, transform_points
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.matching import (
    _required_matches,
    _supported,
    affinity_matrix,
    candidate_assignments,
    spectral_matching,
)
from neoslam.loop.verification import contradictions, evidence_bits, fit_consistent, trimmed_fit
from neoslam.types import Keyframe, LoopClosure

SAME_OBJECT_M = 2.5  # objects of two keyframes this close in the true world, of one label, are one object
RANKED_PLACES = 100  # retrieval ranks are looked for among this many places
CLASSES = (
    "relocalised alone",
    "relocalised elsewhere",
    "not retrieved",
    "too few shared objects",
    "matching fails",
    "verification rejects",
    "drift, place, turn or ambiguity",
)


@dataclass
class Replay:
    """What the detector did on a drive: its closures, the misses by class and the true places' retrieval ranks."""

    closures: list[LoopClosure] = field(default_factory=list)
    misses: Counter = field(default_factory=lambda: Counter({name: 0 for name in CLASSES}))
    ranks: list[int] = field(default_factory=list)  # -1: not among the first RANKED_PLACES places
    query_s: list[float] = field(default_factory=list)


def _true_centres(keyframe: Keyframe, anchor: Keyframe, truth: np.ndarray) -> np.ndarray:
    """A keyframe's object centres (in the odometry world of `anchor`'s pass) moved to the true world."""
    return transform_points(truth[anchor.frame_index] @ invert_pose(anchor.pose), keyframe.centers)


def _shared(query: Keyframe, place: Keyframe, anchor: Keyframe, truth: np.ndarray) -> int:
    q, s = _true_centres(query, query, truth), _true_centres(place, anchor, truth)
    same = np.asarray(query.labels)[:, None] == np.asarray(place.labels)[None, :]
    near = np.linalg.norm(q[:, None, :2] - s[None, :, :2], axis=2) <= SAME_OBJECT_M
    return int((same & near).any(axis=1).sum())


def _match_stage(detector: LoopClosureDetector, query: Keyframe, place: Keyframe, tested: int) -> str:
    """How far the match of the query window against a place gets: the class of a miss, or 'verifies'."""
    config, e_max = detector.config, detector.e_max
    candidates = candidate_assignments(query, place, config)
    affinity = affinity_matrix(query, place, candidates, e_max, config)
    needed = _required_matches(query, place, config)
    kept = _supported(affinity, spectral_matching(affinity, candidates, config), config.min_support)
    if len(kept) < needed:
        return "matching fails"
    pairs = candidates[kept]
    fit, inliers = trimmed_fit(query, place, pairs, config, needed)
    if fit is None or inliers.sum() < needed:
        return "matching fails"
    contradicted = contradictions(query, place, fit.transform, config)
    evidence = evidence_bits(query, place, pairs[inliers], fit, contradicted, detector.index.label_shares(), config)
    if (
        not fit_consistent(fit, config)
        or contradicted > config.max_contradictions
        or (config.tolerances == "covariance" and evidence < config.min_evidence_bits + np.log2(max(tested, 1)))
    ):
        return "verification rejects"
    return "verifies"


def _places_tried(
    detector: LoopClosureDetector, query: Keyframe, eligible: np.ndarray, odometer: float
) -> list[tuple[tuple[int, ...], bool]]:
    """The members of each place the detector comes to for a query, in its order, as far as RANKED_PLACES places,
    and whether it matches it (not when none of its keyframes shares enough triangles with the query)."""
    tried: set[int] = set()
    places = []
    minimum = detector.config.min_shared_triangles
    for candidate, shared in detector.ordered_candidates(query, eligible):
        if candidate in tried:
            continue
        members = detector.place(candidate, odometer).members
        tried.update(members)
        places.append((members, shared is None or max(shared[detector.index.slot(m)] for m in members) >= minimum))
        if len(places) == RANKED_PLACES:
            break
    return places


def _classify(
    detector: LoopClosureDetector, keyframe: Keyframe, odometer: float, true_id: int, truth: np.ndarray, found
) -> tuple[str, int]:
    """The class of a missed revisit keyframe, and its true place's retrieval rank."""
    eligible = detector.index.eligible(keyframe.pose[:3, 3], odometer)
    places = _places_tried(detector, detector.query_window(keyframe), eligible, odometer)
    rank = next((i for i, (members, _) in enumerate(places) if true_id in members), -1)
    matched = rank >= 0 and places[rank][1]
    if found is not None:
        match_frame = found.closure.match_frame
        right = (
            np.linalg.norm(truth[keyframe.frame_index, :2, 3] - truth[match_frame, :2, 3])
            <= LoopCriteria().max_distance_m
        )
        return ("relocalised alone" if right else "relocalised elsewhere"), rank
    if not (0 <= rank < detector.config.candidates and matched):
        return "not retrieved", rank
    query = detector.query_window(keyframe)
    place = detector.place(true_id, odometer)
    anchor = detector.index.keyframes[true_id]
    if _shared(query, place.keyframe, anchor, truth) < _required_matches(query, place.keyframe, detector.config):
        return "too few shared objects", rank
    stage = _match_stage(detector, query, place.keyframe, len(eligible))
    return (stage if stage != "verifies" else "drift, place, turn or ambiguity"), rank


def replay(
    keyframes: list[Keyframe], odometers: list[float], config: NeoSLAMConfig, truth: np.ndarray, classify: bool = True
) -> Replay:
    """Drive a fresh detector over the keyframes (every one stored after its query, as with reuse_places off) and
    judge it against the true poses (n, 4, 4); `classify`: also sort the misses and rank the true places."""
    import time

    detector = LoopClosureDetector(config.keyframes, config.matching)
    criteria = LoopCriteria(config.evaluation.loop_max_distance, config.evaluation.loop_min_frame_gap)
    frames = np.array([k.frame_index for k in keyframes])
    positions = truth[:, :2, 3]
    revisit = true_revisits(positions, criteria, frames)
    out = Replay()
    pending: dict[int, tuple[Keyframe, float, int, object]] = {}  # revisit keyframes not yet known recalled
    for k, (keyframe, odometer) in enumerate(zip(keyframes, odometers, strict=True)):
        if classify and revisit[k]:
            older = np.flatnonzero(frames <= frames[k] - criteria.min_frame_gap)
            nearest = older[np.argmin(np.linalg.norm(positions[frames[older]] - positions[frames[k]], axis=1))]
            found = detector.relocalise(keyframe, odometer)
            cls, rank = _classify(detector, keyframe, odometer, keyframes[nearest].id, truth, found)
            pending[keyframe.id] = (cls, rank)
        start = time.perf_counter()
        out.closures += detector.query(keyframe, odometer)
        out.query_s.append(time.perf_counter() - start)
        detector.add(keyframe, odometer)
    if classify:
        right = judge_closures(out.closures, positions, criteria)
        recalled = {c.query_keyframe for c, ok in zip(out.closures, right, strict=True) if ok}
        for keyframe_id, (cls, rank) in pending.items():
            out.ranks.append(rank)
            if keyframe_id not in recalled:
                out.misses[cls] += 1
    return out
