"""Loop-closure detection: a street driven twice, built by hand; then simulated routes (the block route through
the whole pipeline, the town route's repeated layout through the keyframes and the detector)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from neoslam.config import (
    EvaluationConfig,
    KeyframeConfig,
    MapStoreConfig,
    MatchingConfig,
    NeoSLAMConfig,
    SimulatorConfig,
)
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.evaluation.loops import LoopCriteria, evaluate_closures
from neoslam.geometry import invert_pose, make_pose, planar_motion, rotation_angle, transform_points
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.keyframes import KeyframeBuilder
from neoslam.loop.matching import KeyframeMatch, match_keyframes
from neoslam.loop.relocaliser import MapRelocaliser
from neoslam.pipeline import run
from neoslam.sim.routes import ROUTES
from neoslam.sim.simulator import simulate_route
from neoslam.types import Keyframe

KEYFRAMES = KeyframeConfig()
MATCHING = MatchingConfig()
CAMERA_HEIGHT = 1.65
REACH = 15.0  # a hand-made keyframe holds the objects within this distance along the street
FIRST_PASS = np.arange(0.0, 101.0, 5.0)  # a stored keyframe every 5 m along x
SECOND_PASS_ODOMETER = 400.0  # round the block and back


class TwoPasses:
    """A street on the x axis with objects on both sides; the first pass stores keyframes with the true poses, the
    second comes back later with drifted odometry D (estimate = D @ truth, for the poses and the objects)."""

    def __init__(self, make_street, make_keyframe, make_yaw_pose, seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.street = make_street(self.rng, count=60, length=140.0)
        self.street.centers[:, 0] -= 20.0  # objects from x = -20 to 120
        self.make_keyframe = make_keyframe
        self.yaw_pose = make_yaw_pose
        self.next_id = 0

    def keyframe(self, true_pose: np.ndarray, drift: np.ndarray, frame: int, street=None):
        street = street or self.street
        near = np.flatnonzero(np.abs(street.centers[:, 0] - true_pose[0, 3]) <= REACH)
        centres = transform_points(drift, street.centers[near]) + self.rng.normal(0, 0.1, (len(near), 3))
        keyframe = self.make_keyframe(
            centres,
            [street.labels[i] for i in near],
            street.patches(self.rng, near),
            pose=drift @ true_pose,
            id=self.next_id,
            frame_index=frame,
        )
        self.next_id += 1
        return keyframe

    def first_pass(self, detector: LoopClosureDetector, drift: np.ndarray | None = None) -> list[np.ndarray]:
        poses = []
        for i, x in enumerate(FIRST_PASS):
            pose = self.yaw_pose(0.0, (x, 0.0, CAMERA_HEIGHT))
            keyframe = self.keyframe(pose, np.eye(4) if drift is None else drift, frame=10 * i)
            assert detector.query(keyframe, 5.0 * i) == []  # nothing old enough to close a loop with
            detector.add(keyframe, 5.0 * i)
            poses.append(pose)
        return poses

    def second_pass_pose(self, x: float, yaw: float = 0.0, offset=(0.5, 0.8, 0.0)) -> np.ndarray:
        return self.yaw_pose(yaw, (x + offset[0], offset[1], CAMERA_HEIGHT + offset[2]))


def _stored_at(x: float) -> int:
    """The first-pass keyframe made at x."""
    return int(np.argmin(np.abs(FIRST_PASS - x)))


DRIFT_YAW, DRIFT = np.radians(3.0), (2.0, -1.5, 0.0)


def _second_pass(
    passes: TwoPasses, detector, xs, drifts=None, yaw=0.0, offset=(0.5, 0.8, 0.0), skip=(), start=SECOND_PASS_ODOMETER
):
    """Query and store a keyframe at each x; returns the closures accepted at each, and the true poses."""
    accepted, truths = [], []
    for j, x in enumerate(xs):
        drift = passes.yaw_pose(DRIFT_YAW, DRIFT) if drifts is None else drifts[j]
        true_pose = passes.second_pass_pose(x, yaw, offset)
        if j in skip:
            passes.next_id += 1  # a keyframe the detector never hears of
        odometer = start + 5.0 * j
        keyframe = passes.keyframe(true_pose, drift, frame=int(1000 + 10 * (start - SECOND_PASS_ODOMETER) + 10 * j))
        accepted.append(detector.query(keyframe, odometer))
        detector.add(keyframe, odometer)
        truths.append(true_pose)
    return accepted, truths


@pytest.fixture
def passes(make_street, make_keyframe, make_yaw_pose) -> TwoPasses:
    return TwoPasses(make_street, make_keyframe, make_yaw_pose)


@pytest.mark.parametrize("evidence", ["keyframe", "run"])
@pytest.mark.parametrize("yaw", [0.0, np.pi], ids=["same-direction", "opposite-direction"])
def test_a_revisit_is_accepted_once_two_keyframes_agree(passes: TwoPasses, yaw: float, evidence: str) -> None:
    detector = LoopClosureDetector(KEYFRAMES, MATCHING.model_copy(update={"evidence": evidence}))
    stored_poses = passes.first_pass(detector)
    xs = np.arange(20.0, 81.0, 5.0)
    accepted, truths = _second_pass(passes, detector, xs, yaw=yaw)

    # The first relocalisation waits; the second confirms it and both are accepted; then one each.
    first_query = len(FIRST_PASS)
    assert [[c.query_keyframe for c in closures] for closures in accepted] == [
        [],
        [first_query, first_query + 1],
        *[[first_query + j] for j in range(2, len(xs))],
    ]
    closures = [c for group in accepted for c in group]
    for c, x, true_pose in zip(closures, xs, truths, strict=True):
        stored = _stored_at(x)  # the same place (the robot is 0.9 m off it)
        assert (c.match_keyframe, c.match_frame) == (stored, 10 * stored)
        assert c.query_frame == 1000 + 10 * (c.query_keyframe - first_query)
        assert c.n_matches >= MATCHING.min_inliers and c.score > MATCHING.score_threshold
        # relative_pose is T_stored_query: the true second-pass pose seen from the stored one, drift undone.
        expected = invert_pose(stored_poses[stored]) @ true_pose
        np.testing.assert_allclose(c.relative_pose[:3, 3], expected[:3, 3], atol=0.25)
        assert np.degrees(rotation_angle(c.relative_pose[:3, :3].T @ expected[:3, :3])) < 1.0


def _turned_about(point: np.ndarray, yaw: float) -> np.ndarray:
    """A rotation by `yaw` about the vertical through `point`."""
    rotation = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return make_pose(rotation, point - rotation @ point)


def test_consistency_is_judged_at_the_place_not_at_the_world_origin(passes: TwoPasses) -> None:
    # The street lies kilometres from the origin of the estimated world, as after a long drive, and consecutive
    # fits differ by 0.5° of yaw about the keyframe (what noisy object centres do to a fit). Both put the robot at
    # the same place; only at the far-away origin do the transforms differ by many metres.
    far = make_pose(np.eye(3), np.array([3000.0, 2000.0, 0.0]))  # odometry frame of both passes
    detector = LoopClosureDetector(KEYFRAMES, MATCHING)
    passes.first_pass(detector, drift=far)
    xs = np.arange(20.0, 81.0, 5.0)
    base = far @ passes.yaw_pose(DRIFT_YAW, DRIFT)
    drifts = []
    for j, x in enumerate(xs):
        place = (base @ passes.second_pass_pose(x))[:3, 3]
        drifts.append(_turned_about(place, np.radians(0.25 if j % 2 else -0.25)) @ base)
    at_origin = drifts[0] @ invert_pose(drifts[1])  # how the two relocalisations' transforms differ at the origin
    assert np.linalg.norm(at_origin[:3, 3]) > 10 * MATCHING.consistent_distance

    accepted, _ = _second_pass(passes, detector, xs, drifts=drifts)
    first_query = len(FIRST_PASS)
    assert [[c.query_keyframe for c in closures] for closures in accepted] == [
        [],
        [first_query, first_query + 1],
        *[[first_query + j] for j in range(2, len(xs))],
    ]
    assert all(c.match_keyframe == _stored_at(x) for c, x in zip(sum(accepted, []), xs, strict=True))


@pytest.mark.parametrize(("evidence", "run_gap"), [("keyframe", 0), ("run", 0)])
def test_an_isolated_relocalisation_is_not_accepted(passes: TwoPasses, make_street, evidence, run_gap) -> None:
    # Every other keyframe shows another street at the same place, which no drive gives: each keyframe alone, not
    # merged with the one before (query_radius 0), the window being what a real drive keeps consistent. (A run
    # allowed a gap goes on past the other street's keyframes: test_a_run_goes_on_past_a_keyframe_that_sees_nothing.)
    update = {"query_radius": 0.0, "evidence": evidence, "run_gap": run_gap}
    detector = LoopClosureDetector(KEYFRAMES, MATCHING.model_copy(update=update))
    passes.first_pass(detector)
    elsewhere = make_street(np.random.default_rng(99), count=60, length=140.0)  # other objects, other looks
    xs = np.arange(20.0, 81.0, 5.0)
    accepted = []
    for j, x in enumerate(xs):
        keyframe = passes.keyframe(
            passes.second_pass_pose(x), passes.yaw_pose(DRIFT_YAW, DRIFT), 1000 + j, None if j % 2 == 0 else elsewhere
        )
        if j % 2 == 0:  # the revisited street relocalises, on its own
            assert detector.relocalise(keyframe, SECOND_PASS_ODOMETER + 5.0 * j) is not None
        accepted += detector.query(keyframe, SECOND_PASS_ODOMETER + 5.0 * j)
        detector.add(keyframe, SECOND_PASS_ODOMETER + 5.0 * j)
    assert accepted == []


@pytest.mark.parametrize("evidence", ["keyframe", "run"])
def test_relocalisations_of_keyframes_that_are_not_consecutive_are_not_accepted(passes: TwoPasses, evidence) -> None:
    # a keyframe the detector never heard of between each two: a run with no gap ends there (a run allowed a gap of
    # one goes on: test_a_run_goes_on_past_a_keyframe_that_sees_nothing)
    detector = LoopClosureDetector(KEYFRAMES, MATCHING.model_copy(update={"evidence": evidence, "run_gap": 0}))
    passes.first_pass(detector)
    accepted, _ = _second_pass(passes, detector, [30.0, 35.0, 40.0], skip={1, 2})
    assert accepted == [[], [], []]


def test_a_run_goes_on_past_a_keyframe_that_sees_nothing(passes: TwoPasses) -> None:
    """With evidence run and a gap of one keyframe, two relocalisations one keyframe apart that agree close the
    loop (the keyframe between them saw too few objects, or traffic hid them); with no gap, they do not."""
    for run_gap, closed in ((1, 1), (0, 0)):
        config = MATCHING.model_copy(update={"evidence": "run", "run_gap": run_gap, "query_radius": 0.0})
        detector = LoopClosureDetector(KEYFRAMES, config)
        passes.first_pass(detector)
        drift = passes.yaw_pose(DRIFT_YAW, DRIFT)
        accepted = []
        for j, x in enumerate((30.0, 35.0, 40.0)):
            keyframe = passes.keyframe(passes.second_pass_pose(x), drift, 1000 + j)
            if j == 1:  # it saw nothing of the street
                seen = slice(0, 2)
                keyframe = replace(
                    keyframe, centers=keyframe.centers[seen], labels=keyframe.labels[seen],
                    patches=keyframe.patches[seen], provisional=None, covariances=None, views=None,
                )  # fmt: skip
            accepted += detector.query(keyframe, SECOND_PASS_ODOMETER + 5.0 * j)
            detector.add(keyframe, SECOND_PASS_ODOMETER + 5.0 * j)
        assert len(accepted) == closed
        assert all(c.match_keyframe == _stored_at(40.0) for c in accepted)


@pytest.mark.parametrize(("consistent_distance", "accepted"), [(MATCHING.consistent_distance, 0), (4.0, 9)])
def test_consecutive_relocalisations_must_agree(passes: TwoPasses, consistent_distance: float, accepted: int) -> None:
    # Every other keyframe fits 3 m further along the street: each relocalises at the right place, but no two
    # consecutive ones agree on the transform (what a repeated pattern does). Each keyframe alone (query_radius 0):
    # two keyframes 3 m apart in the odometry's frame of one pass are no drive's. Runs with no gap: a run allowed
    # to go on past a keyframe joins every other one (test_a_run_goes_on_past_a_keyframe_that_sees_nothing).
    update = {"consistent_distance": consistent_distance, "query_radius": 0.0, "run_gap": 0}
    config = MATCHING.model_copy(update=update)
    detector = LoopClosureDetector(KEYFRAMES, config)
    passes.first_pass(detector)
    drift = passes.yaw_pose(DRIFT_YAW, DRIFT)
    shifted = passes.yaw_pose(0.0, (3.0, 0.0, 0.0)) @ drift
    xs = np.arange(30.0, 71.0, 5.0)
    closures, _ = _second_pass(passes, detector, xs, drifts=[drift if j % 2 else shifted for j in range(len(xs))])
    assert sum(len(c) for c in closures) == accepted


@pytest.mark.parametrize(
    ("offset", "gate"),
    [((0.5, 6.0, 0.0), "max_place_offset"), ((0.5, 0.8, 7.0), "max_vertical_offset")],
    ids=["beside", "above"],
)
def test_a_fit_that_puts_the_robot_elsewhere_is_rejected(make_street, make_keyframe, make_yaw_pose, offset, gate):
    # The second pass drives 6 m beside the first (a parallel lane) or 7 m above it (a bridge), seeing the same
    # objects: the fit is right, and says the robot is not at a stored place.
    for limit, expected in [(getattr(MATCHING, gate), 0), (8.0, 7)]:
        passes = TwoPasses(make_street, make_keyframe, make_yaw_pose)
        detector = LoopClosureDetector(KEYFRAMES, MATCHING.model_copy(update={gate: limit}))
        passes.first_pass(detector)
        closures, _ = _second_pass(passes, detector, np.arange(30.0, 61.0, 5.0), offset=offset)
        assert sum(len(c) for c in closures) == expected


@pytest.mark.parametrize(("turn_deg", "bound_deg", "accepted"), [(20.0, None, 7), (60.0, None, 0), (60.0, 90.0, 7)])
def test_a_fit_turned_more_than_the_odometry_can_drift_is_rejected(
    passes: TwoPasses, turn_deg: float, bound_deg: float | None, accepted: int
) -> None:
    # The second pass's world is turned about the street by `turn_deg`: the fit finds the turn. 20° is a heading
    # drift the odometry can build up over the 300-400 m since the first pass; 60° is not (the default bound there
    # is 30° + 3°/100 m, about 40°): a layout that fits turned so far is another place, or the same one flipped.
    config = MATCHING if bound_deg is None else MATCHING.model_copy(update={"max_yaw_drift_deg": bound_deg})
    detector = LoopClosureDetector(KEYFRAMES, config)
    passes.first_pass(detector)
    xs = np.arange(30.0, 61.0, 5.0)
    drifts = [_turned_about(np.array([45.0, 0.0, 0.0]), np.radians(turn_deg))] * len(xs)
    closures, _ = _second_pass(passes, detector, xs, drifts=drifts)
    assert sum(len(c) for c in closures) == accepted
    if accepted:
        assert all(c.match_keyframe == _stored_at(x) for c, x in zip(sum(closures, []), xs, strict=True))


def test_a_third_visit_is_accepted_like_the_second(passes: TwoPasses) -> None:
    detector = LoopClosureDetector(KEYFRAMES, MATCHING)
    passes.first_pass(detector)
    xs = np.arange(0.0, 101.0, 5.0)
    second, _ = _second_pass(passes, detector, xs, drifts=[passes.yaw_pose(np.radians(2), (3, -3, 0))] * len(xs))
    assert sum(map(len, second)) == len(xs)
    third_drift = [passes.yaw_pose(np.radians(-2), (-3, 3, 0))] * len(xs)
    third, _ = _second_pass(passes, detector, xs, drifts=third_drift, start=SECOND_PASS_ODOMETER + 400.0)
    assert sum(map(len, third)) == len(xs)


def test_scores_against_every_stored_keyframe_peak_at_the_same_place(passes: TwoPasses) -> None:
    detector = LoopClosureDetector(KEYFRAMES, MATCHING)
    passes.first_pass(detector)
    query = passes.keyframe(passes.second_pass_pose(50.0, yaw=np.pi), passes.yaw_pose(DRIFT_YAW, DRIFT), 1000)
    spectral, verified = detector.scores(query)
    assert spectral.shape == verified.shape == (len(FIRST_PASS),)
    same_place = _stored_at(50.0)
    assert int(np.argmax(spectral)) == int(np.argmax(verified)) == same_place
    assert (spectral >= 0).all() and (verified <= spectral + 1e-9).all()
    far = np.abs(FIRST_PASS - 50.0) > 2 * REACH  # no object in common: never verified
    assert (verified[far] == 0).all() and verified[same_place] > 0


# -------------------------------------------------------------------------------------------------------- pipeline


def _judged(closures, truth_positions: np.ndarray):
    """Precision and recall against the truth, the way the evaluation judges a run (horizontal by default)."""
    evaluation = EvaluationConfig()
    criteria = LoopCriteria(evaluation.loop_max_distance, evaluation.loop_min_frame_gap)
    positions = truth_positions[:, :2] if evaluation.loop_distance == "horizontal" else truth_positions
    return evaluate_closures(closures, positions, criteria)


def _run_route(name: str, seed: int, folder: Path):
    write_dataset(folder, simulate_route(name, SimulatorConfig(seed=seed, detection_profile="ideal")))
    dataset = read_dataset(folder)
    return dataset, run(dataset.frames(), NeoSLAMConfig(), total=len(dataset), progress=False)


@pytest.mark.slow
def test_the_block_route_closes_loops_with_full_precision(tmp_path: Path) -> None:
    dataset, result = _run_route("block", 11, tmp_path / "block")
    assert len(result.loop_closures) >= 5
    assert _judged(result.loop_closures, dataset.ground_truth.positions).precision == 1.0
    keyframe_ids = [c.query_keyframe for c in result.loop_closures]
    assert len(set(keyframe_ids)) == len(keyframe_ids)  # each keyframe closes at most one loop


def _detected_closures(dataset, matching: MatchingConfig = MATCHING) -> tuple[list, list]:
    """Keyframes and the closures the loop detector accepts, with the keyframes and the detector driven the way
    the pipeline drives them (odometry poses, odometer of planar motion), but without the rest of the pipeline."""
    builder, detector = KeyframeBuilder(KEYFRAMES), LoopClosureDetector(KEYFRAMES, matching)
    closures, previous = [], None
    for frame in dataset.frames():
        horizontal, _, vertical = planar_motion(
            frame.odometry_pose if previous is None else previous, frame.odometry_pose
        )
        previous = frame.odometry_pose
        keyframe = builder.add(
            frame.index, frame.odometry_pose, frame.observations, float(np.hypot(horizontal, vertical))
        )
        if keyframe is not None:
            closures += detector.query(keyframe, builder.odometer_m)
            detector.add(keyframe, builder.odometer_m)
    return detector.index.keyframes, closures


@pytest.mark.slow
@pytest.mark.parametrize("evidence", ["keyframe", "run"])
def test_the_town_route_is_not_fooled_by_its_repeated_layout(tmp_path: Path, evidence: str) -> None:
    write_dataset(tmp_path / "town", simulate_route("town", SimulatorConfig(seed=0, detection_profile="ideal")))
    dataset = read_dataset(tmp_path / "town")
    keyframes, closures = _detected_closures(dataset, MATCHING.model_copy(update={"evidence": evidence}))
    repeat = ROUTES["town"].repeats[0]
    xy = dataset.ground_truth.positions[:, :2]

    def near(start, heading) -> np.ndarray:
        offset = xy - np.asarray(start)
        along = offset @ [np.cos(heading), np.sin(heading)]
        across = offset @ [-np.sin(heading), np.cos(heading)]
        return (along > -20.0) & (along < repeat.length + 20.0) & (np.abs(across) < 20.0)

    source, target = near(repeat.source_start, repeat.source_heading), near(repeat.target_start, repeat.target_heading)
    # The trap is real: keyframes of the target stretch do verify against keyframes of the source stretch.
    on_source = [k for k in keyframes if source[k.frame_index]]
    on_target = [k for k in keyframes if target[k.frame_index]]
    assert len(on_source) > 10 and len(on_target) > 10
    assert any(match_keyframes(q, s, MATCHING, KEYFRAMES.e_max).verified for q in on_target[::3] for s in on_source)
    # Loops are closed elsewhere, all of them right, and none joins the two stretches.
    assert len(closures) >= 20
    assert _judged(closures, dataset.ground_truth.positions).precision == 1.0
    for c in closures:
        q, m = c.query_frame, c.match_frame
        assert not (source[q] and target[m]) and not (target[q] and source[m]), (q, m)


# ------------------------------------------------------------------------------------------- ambiguity and windows


def _stored_twice(passes: TwoPasses, matching: MatchingConfig) -> tuple[LoopClosureDetector, Keyframe]:
    """The street stored, then stored again 2 km away in the odometry's world (a copy: a repeated layout); and a
    revisit of the first."""
    detector = LoopClosureDetector(KEYFRAMES, matching)
    passes.first_pass(detector)
    copy = passes.yaw_pose(0.0, (2000.0, 0.0, 0.0))
    for i, x in enumerate(FIRST_PASS):
        keyframe = passes.keyframe(passes.yaw_pose(0.0, (x, 0.0, CAMERA_HEIGHT)), copy, frame=500 + 10 * i)
        detector.add(keyframe, 200.0 + 5.0 * i)
    return detector, passes.keyframe(passes.second_pass_pose(50.0), passes.yaw_pose(DRIFT_YAW, DRIFT), 1000)


def test_a_layout_stored_at_two_places_relocalises_nowhere(passes: TwoPasses) -> None:
    """Every stored keyframe a candidate and no drift prior to tell the two copies apart: a revisit verifies at
    both with the same evidence, so it relocalises at neither; once a closure has joined the two (they are one
    place seen in two passes), it relocalises."""
    detector, query = _stored_twice(passes, MATCHING.model_copy(update={"search_radius": 1e5, "drift_radius": 1e5}))
    assert detector.relocalise(query, SECOND_PASS_ODOMETER) is None
    detector.joined.join(_stored_at(50.0), len(FIRST_PASS) + _stored_at(50.0))
    found = detector.relocalise(query, SECOND_PASS_ODOMETER)
    assert found is not None and found.closure.match_keyframe in (_stored_at(50.0), len(FIRST_PASS) + _stored_at(50.0))


def test_the_drift_prior_holds_with_the_search_radius_opened(passes: TwoPasses) -> None:
    """Retrieval opened to the whole map finds both copies, but the odometry cannot have drifted 2 km in 300 m of
    travel: the copy's fit costs its drift prior, and the revisit relocalises at the near place."""
    detector, query = _stored_twice(passes, MATCHING.model_copy(update={"search_radius": 1e5}))
    found = detector.relocalise(query, SECOND_PASS_ODOMETER)
    assert found is not None and found.closure.match_keyframe == _stored_at(50.0)


def test_the_query_window_holds_what_one_sparse_keyframe_misses(passes: TwoPasses) -> None:
    """Two consecutive second-pass keyframes that each see only three of the street's objects (a sparse detector),
    three others each: alone neither can be matched (4 needed); the second, with the first in its query window,
    relocalises. (The stored objects they do not see are no contradiction here: the contradiction check is tested
    on its own.)"""
    tolerant = MATCHING.model_copy(update={"max_contradictions": 1000, "contradiction_bits": 0.0})
    detector = LoopClosureDetector(KEYFRAMES, tolerant)
    passes.first_pass(detector)
    drift = passes.yaw_pose(DRIFT_YAW, DRIFT)
    full = [passes.keyframe(passes.second_pass_pose(x), drift, 1000 + j) for j, x in enumerate((48.0, 52.0))]
    sparse = []
    for keyframe, keep in zip(full, (slice(0, None, 4), slice(2, None, 4)), strict=True):
        index = np.arange(len(keyframe.labels))[keep][:3]
        sparse.append(
            Keyframe(keyframe.id, keyframe.frame_index, keyframe.pose, keyframe.centers[index],
                     tuple(keyframe.labels[i] for i in index), keyframe.patches[index])
        )  # fmt: skip
    alone = LoopClosureDetector(KEYFRAMES, tolerant.model_copy(update={"query_radius": 0.0}))
    alone.index = detector.index
    assert alone.relocalise(sparse[0], SECOND_PASS_ODOMETER) is None
    assert alone.relocalise(sparse[1], SECOND_PASS_ODOMETER + 4.0) is None
    assert detector.relocalise(sparse[0], SECOND_PASS_ODOMETER) is None
    found = detector.relocalise(sparse[1], SECOND_PASS_ODOMETER + 4.0)
    assert found is not None and found.closure.match_keyframe in (_stored_at(50.0), _stored_at(50.0) + 1)


def test_a_stored_place_leaves_out_its_members_from_the_last_metres(make_keyframe, make_yaw_pose) -> None:
    """A place is its candidate with the same-pass neighbours near it; a neighbour made within
    `exclude_recent_distance` of travel is the query's own street seen moments ago and is left out; the whole-map
    relocaliser of a later session has no recent keyframes."""
    detector = LoopClosureDetector(KEYFRAMES, MATCHING)
    stored = [
        replace(
            make_keyframe([[x + 10.0, 4.0, 0.0], [x + 14.0, -4.0, 0.0]], ["car", "car"], id=i, frame_index=i),
            pose=make_yaw_pose(0.0, (x, 0.0, 0.0)),
        )
        for i, x in enumerate((0.0, 5.0))
    ]
    for i, keyframe in enumerate(stored):
        detector.add(keyframe, 30.0 * i)
    travelled = 30.0 + MATCHING.exclude_recent_distance - 1.0  # the second keyframe is still recent
    place = detector._place(0, travelled)
    assert place.members == (0,) and len(place.keyframe.labels) == 2
    assert detector._place(0, travelled + 2.0).members == (0, 1)
    relocaliser = MapRelocaliser(KEYFRAMES, MATCHING, MapStoreConfig(), stored)
    assert relocaliser._place(0, 0.0).members == (0, 1)


def test_a_place_that_fails_on_objects_in_view_is_matched_again_around_the_fits_robot(passes: TwoPasses) -> None:
    # The place of the keyframe stored at x = 40 reaches 20 m either side; a fit that puts the revisit's robot at
    # x = 52.5 and finds five objects in view missing is tried again around the keyframe stored at x = 50.
    detector = LoopClosureDetector(KEYFRAMES, MATCHING)
    passes.first_pass(detector)
    place = detector.place(_stored_at(40.0), SECOND_PASS_ODOMETER)
    assert _stored_at(50.0) in place.members
    query = passes.keyframe(passes.second_pass_pose(52.0), np.eye(4), frame=2000)
    failed = KeyframeMatch(
        query.id, _stored_at(40.0), 5.0, np.zeros((0, 2), int), np.eye(4), 0.1, False, 0.0,
        contradicted_in_view=np.ones(MATCHING.max_contradictions + 1, dtype=bool),
    )  # fmt: skip
    assert detector._recentred(failed, place, _stored_at(40.0), query) == _stored_at(50.0)
    assert detector._recentred(failed, place, _stored_at(50.0), query) is None  # already centred there
    few = replace(failed, contradicted_in_view=np.ones(MATCHING.max_contradictions, dtype=bool))
    assert detector._recentred(few, place, _stored_at(40.0), query) is None  # failed for another reason
    out_of_view = replace(failed, contradicted_in_view=~failed.contradicted_in_view)
    assert detector._recentred(out_of_view, place, _stored_at(40.0), query) is None
    off = LoopClosureDetector(KEYFRAMES, MATCHING.model_copy(update={"recentre_places": False}))
    for keyframe in detector.index.keyframes:
        off.add(keyframe, detector.index.odometer(keyframe.id))
    assert off._recentred(failed, off.place(_stored_at(40.0), SECOND_PASS_ODOMETER), _stored_at(40.0), query) is None
