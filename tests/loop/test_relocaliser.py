"""Evidence that accumulates over a run of keyframes (loop.runs), each matched object counted once: a later
session's relocalisation in a stored map (loop.relocaliser), and the loop detector within a session with
`matching.evidence: run`; neither closes a loop on streets the map does not hold."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.config import KeyframeConfig, MapStoreConfig, MatchingConfig
from neoslam.geometry import transform_points
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.relocaliser import MapRelocaliser
from neoslam.types import Keyframe

REACH = 15.0  # a keyframe holds objects within this distance along the street
STREETS = 8  # stored streets, 500 m apart: the whole map's threshold is 6 + log2(8 x 29) = 13.9 bits
STORED_X = np.arange(0.0, 141.0, 5.0)
SESSION_X = np.arange(12.0, 130.0, 12.0)  # a session keyframe every 12 m: no query window joins two
VARIANCE = 0.5  # m², each object centre's ground-plane variance: far objects, a few bits each
SEEN = 6  # objects a session keyframe sees of those near it: its evidence alone is often under the whole map's
SESSIONS = range(8)
SEEN_FROM = np.array([30.0, 20.0, 10.0, 0.0])  # m behind a keyframe's robot, where its objects were seen from


def _keyframe(make_keyframe, street, rng, x, frame, id, seen=None) -> Keyframe:
    near = np.flatnonzero(np.abs(street.centers[:, 0] - x) <= REACH)
    if seen is not None:
        near = np.sort(rng.choice(near, size=min(seen, len(near)), replace=False))
    centres = transform_points(frame, street.centers[near]) + rng.normal(0, 0.3, (len(near), 3))
    pose = frame.copy()
    pose[:3, 3] = transform_points(frame, np.array([[x, 0.0, 1.65]]))[0]
    keyframe = make_keyframe(centres, [street.labels[i] for i in near], street.patches(rng, near), pose, id, id)
    covariances = np.tile(VARIANCE * np.eye(2), (len(near), 1, 1))
    # seen from the robot's poses as it drove up the street to x: its objects ahead of one of them
    behind = transform_points(frame, np.column_stack([x - SEEN_FROM, 0.0 * SEEN_FROM, 0.0 * SEEN_FROM]))
    views = np.column_stack([behind[:, :2], np.full(len(SEEN_FROM), np.arctan2(frame[1, 0], frame[0, 0]))])
    return Keyframe(
        keyframe.id, keyframe.frame_index, pose, centres, keyframe.labels, keyframe.patches, None, covariances, views
    )


@pytest.fixture
def stored_map(make_street, make_keyframe, make_yaw_pose):
    rng = np.random.default_rng(3)
    streets = [make_street(rng, count=60, length=140.0) for _ in range(STREETS)]
    stored = []
    for s, street in enumerate(streets):
        frame = make_yaw_pose(0.0, (0.0, 500.0 * s, 0.0))
        for x in STORED_X:
            stored.append(_keyframe(make_keyframe, street, rng, x, frame, len(stored)))
    return streets, stored


def _session(make_keyframe, make_yaw_pose, street, relocaliser, seed, first_id=10_000, odometer=0.0):
    """The session's closures per keyframe along the street, from a frame turned and moved from the map's;
    `odometer`, the reading at its first keyframe."""
    rng = np.random.default_rng(seed)
    frame = make_yaw_pose(0.6, (35.0, -20.0, 0.0))
    closures = []
    for j, x in enumerate(SESSION_X):
        keyframe = _keyframe(make_keyframe, street, rng, x, frame, first_id + j, SEEN)
        closures.append(relocaliser.query(keyframe, odometer + (x - SESSION_X[0])))
    return closures


# Within a session: the stored streets were driven a kilometre before (the odometry may have drifted the 40 m and
# 34° of the session's frame since), every stored keyframe within the search radius, as in the whole map.
IN_SESSION = {"search_radius": 1e5, "drift_radius": 40.0}
ODOMETER = 1000.0


def _in_session(stored, evidence: str) -> LoopClosureDetector:
    detector = LoopClosureDetector(KeyframeConfig(), MatchingConfig(evidence=evidence, **IN_SESSION))
    for keyframe in stored:
        detector.add(keyframe, 0.0)
    return detector


def _relocaliser(stored, evidence: str) -> MapRelocaliser:
    store = MapStoreConfig(relocalisation_evidence=evidence)
    return MapRelocaliser(KeyframeConfig(), MatchingConfig(), store, stored)


def _right(closures, street: int = 0) -> bool:
    """Whether every closure puts the session's keyframe at the stored keyframe of its true place (within 5 m)."""
    for closure in closures:
        x = SESSION_X[closure.query_keyframe - 10_000]
        if (
            closure.match_keyframe // len(STORED_X) != street
            or abs(STORED_X[closure.match_keyframe % len(STORED_X)] - x) > 5.0
        ):
            return False
    return True


def test_a_run_of_keyframes_relocalises_where_each_alone_shows_too_little(
    stored_map, make_keyframe, make_yaw_pose
) -> None:
    streets, stored = stored_map
    found = {}
    for evidence in ("keyframe", "run"):
        sessions = [
            _session(make_keyframe, make_yaw_pose, streets[0], _relocaliser(stored, evidence), seed)
            for seed in SESSIONS
        ]
        found[evidence] = [next((j for j, c in enumerate(s) if c), None) for s in sessions]
        assert all(_right(c) for s in sessions for c in s)  # every closure at the true place
    relocalised = {evidence: sum(j is not None for j in first) for evidence, first in found.items()}
    assert relocalised["run"] >= 5 and relocalised["keyframe"] <= 1
    for keyframe_first, run_first in zip(found["keyframe"], found["run"], strict=True):
        assert keyframe_first is None or (run_first is not None and run_first <= keyframe_first)


@pytest.mark.parametrize("evidence", ["keyframe", "run"])
def test_a_street_the_map_does_not_hold_never_relocalises(
    stored_map, make_street, make_keyframe, make_yaw_pose, evidence
) -> None:
    _, stored = stored_map
    for seed in SESSIONS:
        stranger = make_street(np.random.default_rng(100 + seed), count=60, length=140.0)
        closures = _session(make_keyframe, make_yaw_pose, stranger, _relocaliser(stored, evidence), seed)
        assert not any(closures)


def test_a_run_counts_each_object_once(stored_map, make_keyframe, make_yaw_pose) -> None:
    """The same keyframe queried three times in a row (consecutive ids): the run holds what one of them shows."""
    streets, stored = stored_map
    relocaliser = _relocaliser(stored, "run")
    keyframe = _keyframe(make_keyframe, streets[0], np.random.default_rng(5), 60.0, np.eye(4), 10_000)
    steps = []
    for k in range(3):
        again = Keyframe(10_000 + k, 10_000 + k, keyframe.pose, keyframe.centers, keyframe.labels, keyframe.patches,
                         None, keyframe.covariances)  # fmt: skip
        relocaliser._queried.clear()  # each one alone, not joined by the query window
        steps.append(max(relocaliser._verified(again, 0.0), key=lambda step: step.evidence))
    single = steps[0].evidence
    assert single > 0 and relocaliser.runs.bits(tuple(steps)) == pytest.approx(single)


def test_a_fresh_relocaliser_waits_for_consecutive_keyframes(stored_map, make_keyframe) -> None:
    """Its first keyframe, however well it matches, closes nothing alone."""
    streets, stored = stored_map
    for evidence in ("keyframe", "run"):
        relocaliser = _relocaliser(stored, evidence)
        keyframe = _keyframe(make_keyframe, streets[0], np.random.default_rng(5), 60.0, np.eye(4), 10_000)
        assert relocaliser._verified(keyframe, 0.0)  # it matches its place
        relocaliser = _relocaliser(stored, evidence)
        assert relocaliser.query(keyframe, 0.0) == []


def test_within_a_session_a_run_closes_loops_where_each_keyframe_alone_shows_too_little(
    stored_map, make_keyframe, make_yaw_pose
) -> None:
    """The same streets and sessions as above, driven within one session: each keyframe alone falls short of the
    threshold of every stored keyframe it could have matched, a run of them does not, and every closure is right."""
    streets, stored = stored_map
    closed = {}
    for evidence in ("keyframe", "run"):
        sessions = [
            _session(make_keyframe, make_yaw_pose, streets[0], _in_session(stored, evidence), seed, odometer=ODOMETER)
            for seed in SESSIONS
        ]
        assert all(_right(c) for s in sessions for c in s)
        closed[evidence] = sum(bool(c) for s in sessions for c in s)
    assert closed["run"] >= 2 * max(closed["keyframe"], 5)


def test_within_a_session_a_run_closes_nothing_on_a_street_the_map_does_not_hold(
    stored_map, make_street, make_keyframe, make_yaw_pose
) -> None:
    _, stored = stored_map
    for seed in SESSIONS:
        stranger = make_street(np.random.default_rng(100 + seed), count=60, length=140.0)
        detector = _in_session(stored, "run")
        assert not any(_session(make_keyframe, make_yaw_pose, stranger, detector, seed, odometer=ODOMETER))
