"""Why revisits were missed: each keyframe that truly revisits a place but gets no true closure, put in one class.

Ground truth is read here only, for the judgement, never by the detector. A missed keyframe is matched against the
stored keyframe nearest to it in truth (at least the frame gap earlier):

- relocalised alone: the detector did relocalise it, but no consecutive keyframe confirmed it;
- beyond the place offset: it verifies against that keyframe, but the fit puts the robot further from it than
  `max_place_offset` (the place is the same, the poses too far apart to call one place);
- verifies, not found: it verifies within the offset, yet retrieval or the other gates did not take it;
- too few shared objects: fewer objects of the two keyframes stand at one place in truth than verification needs;
- fails verification: enough shared objects, but the match or its fit does not verify.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from neoslam.evaluation.loops import LoopCriteria, judge_closures, true_revisits
from neoslam.geometry import invert_pose, transform_points
from neoslam.loop.matching import _has_counterpart, _required_matches, match_keyframes
from neoslam.pipeline import NeoSLAM
from neoslam.types import Keyframe

SAME_OBJECT_M = 2.5  # objects of two keyframes this close in the true world, of one label, are one object
CLASSES = (
    "relocalised alone",
    "beyond the place offset",
    "verifies, not found",
    "too few shared objects",
    "fails verification",
)


def _true_centres(keyframe: Keyframe, truth: np.ndarray) -> np.ndarray:
    """The keyframe's object centres moved from its odometry world to the true world at its frame."""
    return transform_points(truth[keyframe.frame_index] @ invert_pose(keyframe.pose), keyframe.centers)


def _shared_objects(query: Keyframe, stored: Keyframe, truth: np.ndarray) -> int:
    q, s = _true_centres(query, truth), _true_centres(stored, truth)
    return int(_has_counterpart(q, query.labels, s, stored.labels, SAME_OBJECT_M).sum())


def _classify(slam: NeoSLAM, query: Keyframe, stored: Keyframe, truth: np.ndarray, relocalised: bool) -> str:
    if relocalised:
        return CLASSES[0]
    config = slam.config
    match = match_keyframes(query, stored, config.matching, config.keyframes.e_max)
    if match.verified:
        offset = (invert_pose(stored.pose) @ match.transform @ query.pose)[:2, 3]
        return CLASSES[1] if np.linalg.norm(offset) > config.matching.max_place_offset else CLASSES[2]
    if _shared_objects(query, stored, truth) < _required_matches(query, stored, config.matching):
        return CLASSES[3]
    return CLASSES[4]


def classify_misses(slam: NeoSLAM, truth: np.ndarray, relocalised: set[int]) -> Counter:
    """Count the missed revisit keyframes of a drive by class; `truth` holds the true poses (n, 4, 4)."""
    keyframes = slam.loop_detector.index.keyframes
    frames = np.array([k.frame_index for k in keyframes])
    criteria = LoopCriteria()
    positions = truth[:, :2, 3]
    revisit = true_revisits(positions, criteria, frames)
    correct = judge_closures(slam.detected_closures, positions, criteria)
    recalled = {c.query_keyframe for c, right in zip(slam.detected_closures, correct, strict=True) if right}
    misses: Counter = Counter({name: 0 for name in CLASSES})
    for k in np.flatnonzero(revisit):
        if k in recalled:
            continue
        older = np.flatnonzero(frames <= frames[k] - criteria.min_frame_gap)
        nearest = int(older[np.argmin(np.linalg.norm(positions[frames[older]] - positions[frames[k]], axis=1))])
        misses[_classify(slam, keyframes[k], keyframes[nearest], truth, int(k) in relocalised)] += 1
    return misses
