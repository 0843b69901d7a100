"""Loop-closure judgement on hand-built trajectories whose true and false closures are known exactly."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from neoslam.evaluation import LoopCriteria, evaluate_closures, judge_closures, true_revisits
from neoslam.types import LoopClosure

LEG_FRAMES = 200
RETURN_OFFSET_M = 1.0
# Frame 200 + k of the return leg sits at x = 199 - k, 1 m beside the outbound frames 199 - k +- 4 (within 5 m).
# The earliest of them, 195 - k, is 2k + 5 frames back: a true revisit from k = 48, i.e. frames 248 ... 399.
FIRST_REVISIT = 248
N_REVISITS = 2 * LEG_FRAMES - FIRST_REVISIT


def out_and_back() -> np.ndarray:
    """1 m per frame along x for 200 frames, then back along x with a 1 m lateral offset."""
    outbound = np.stack([np.arange(LEG_FRAMES), np.zeros(LEG_FRAMES), np.zeros(LEG_FRAMES)], axis=1)
    back = outbound[::-1] + [0.0, RETURN_OFFSET_M, 0.0]
    return np.concatenate([outbound, back]).astype(float)


def brute_force_revisits(positions: np.ndarray, criteria: LoopCriteria) -> np.ndarray:
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=-1)
    frame = np.arange(len(positions))
    earlier = frame[None, :] <= frame[:, None] - criteria.min_frame_gap
    return ((distance <= criteria.max_distance_m) & earlier).any(axis=1)


def test_true_revisits_of_the_out_and_back_path():
    revisits = true_revisits(out_and_back(), LoopCriteria())
    np.testing.assert_array_equal(np.flatnonzero(revisits), np.arange(FIRST_REVISIT, 2 * LEG_FRAMES))


def test_true_revisits_match_brute_force_on_a_random_walk():
    rng = np.random.default_rng(3)
    positions = np.cumsum(rng.normal(0, 1.0, (600, 3)) * [1, 1, 0.1], axis=0)
    criteria = LoopCriteria(max_distance_m=4.0, min_frame_gap=30)
    expected = brute_force_revisits(positions, criteria)
    assert 0 < expected.sum() < len(expected)
    np.testing.assert_array_equal(true_revisits(positions, criteria), expected)
    query = np.arange(0, 600, 7)
    np.testing.assert_array_equal(true_revisits(positions, criteria, query), expected[query])


def test_true_and_false_closures_set_precision_and_recall():
    positions = out_and_back()
    closures = [(300, 99, 0.9), (300, 97, 0.8), (350, 10, 0.5)]  # two true ones of one query frame, one false
    np.testing.assert_array_equal(judge_closures(closures, positions), [True, True, False])
    stats = evaluate_closures(closures, positions)
    assert (stats.accepted, stats.true_positive, stats.false_positive) == (3, 2, 1)
    assert stats.precision == pytest.approx(2 / 3)
    assert stats.recalled_frames == 1  # distinct query frames
    assert stats.revisit_frames == N_REVISITS
    assert stats.recall == pytest.approx(1 / N_REVISITS)
    p, r = 2 / 3, 1 / N_REVISITS
    assert stats.f1 == pytest.approx(2 * p * r / (p + r))


def test_loop_closure_records_are_accepted():
    positions = out_and_back()
    record = LoopClosure(320, 79, 3, 1, score=0.7, n_matches=6, relative_pose=np.eye(4))
    stats = evaluate_closures([record], positions)
    assert stats.true_positive == 1
    assert stats.precision == 1.0


def test_gap_rule_rejects_a_closure_too_few_frames_back():
    standing_still = np.zeros((200, 3))
    np.testing.assert_array_equal(
        judge_closures([(150, 100, 1.0), (150, 50, 1.0), (50, 150, 1.0)], standing_still), [False, True, False]
    )
    assert not true_revisits(standing_still)[99]
    assert true_revisits(standing_still)[100]


def test_distance_rule_uses_the_criteria():
    positions = out_and_back()
    strict = LoopCriteria(max_distance_m=0.5, min_frame_gap=100)
    assert judge_closures([(300, 99, 1.0)], positions, strict).tolist() == [False]
    assert not true_revisits(positions, strict).any()
    stats = evaluate_closures([(300, 99, 1.0)], positions, strict)
    assert math.isnan(stats.recall) and math.isnan(stats.f1_max) and stats.precision == 0.0


def test_threshold_sweep_gives_recall_at_full_precision():
    positions = out_and_back()
    closures = [(300, 99, 0.9), (310, 89, 0.8), (350, 10, 0.6), (320, 79, 0.5), (330, 69, 0.5)]
    stats = evaluate_closures(closures, positions)
    # thresholds 0.9: 1/1 true, 1 frame; 0.8: 2/2, 2 frames; 0.6: 2/3; 0.5: 4/5, 4 frames
    assert stats.recall_at_full_precision == pytest.approx(2 / N_REVISITS)
    f1 = [2 * p * r / (p + r) for p, r in [(1, 1), (1, 2), (2 / 3, 2), (4 / 5, 4)] for r in [r / N_REVISITS]]
    assert stats.f1_max == pytest.approx(max(f1))
    assert stats.recall == pytest.approx(4 / N_REVISITS)


def test_recall_counts_only_the_given_query_frames():
    positions = out_and_back()
    keyframes = np.arange(0, 2 * LEG_FRAMES, 10)
    closures = [(300, 99, 0.9), (305, 94, 0.9)]  # frame 305 is not a keyframe: precision only
    stats = evaluate_closures(closures, positions, query_frames=keyframes)
    assert stats.revisit_frames == len(range(250, 400, 10))
    assert stats.recalled_frames == 1
    assert stats.precision == 1.0


def test_no_closures_gives_nan_precision_and_zero_recall():
    stats = evaluate_closures([], out_and_back())
    assert stats.accepted == 0
    assert math.isnan(stats.precision) and math.isnan(stats.f1)
    assert stats.recall == 0.0
    assert stats.recall_at_full_precision == 0.0 and stats.f1_max == 0.0
    as_dict = stats.as_dict()
    assert as_dict["precision"] is None and as_dict["recall"] == 0.0
    json.dumps(as_dict, allow_nan=False)
