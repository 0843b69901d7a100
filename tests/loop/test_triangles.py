"""Retrieval by object triangles: keys that survive viewpoint and noise, and an index that ranks the place first."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.geometry import make_pose, transform_points
from neoslam.loop.triangles import TriangleIndex, triangle_keys
from neoslam.types import Keyframe

LABELS = ("car", "car", "car", "car", "truck", "bicycle")
CODES = {"car": 1, "truck": 2, "bicycle": 3}


def _keyframe(centres, labels, pose=None, id=0) -> Keyframe:
    centres = np.asarray(centres, dtype=float)
    return Keyframe(
        id=id,
        frame_index=id,
        pose=np.eye(4) if pose is None else pose,
        centers=centres,
        labels=tuple(labels),
        patches=np.zeros((len(centres), 4, 4), np.uint8),
    )


def _street(rng, count=10, length=40.0):
    x = np.sort(rng.uniform(0, length, count))
    y = np.where(rng.random(count) < 0.5, 1.0, -1.0) * rng.uniform(4.0, 8.0, count)
    labels = [LABELS[i] for i in rng.integers(0, len(LABELS), count)]
    return np.column_stack([x, y, rng.uniform(0, 1.5, count)]), labels


def _keys(keyframe: Keyframe, spread: bool, side_bin=1.0) -> set[int]:
    codes = np.array([CODES[label] for label in keyframe.labels])
    return set(triangle_keys(keyframe, codes, side_bin, 12, 40.0, spread).tolist())


@pytest.mark.parametrize("seed", range(3))
def test_keys_ignore_object_order_and_rigid_motion(seed: int) -> None:
    rng = np.random.default_rng(seed)
    centres, labels = _street(rng)
    pose = make_pose(np.eye(3), np.array([centres[3, 0], 0.0, 1.65]))
    stored = _keyframe(centres, labels, pose)
    yaw = rng.uniform(-np.pi, np.pi)
    motion = make_pose(
        np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]), rng.uniform(-500, 500, 3)
    )
    order = rng.permutation(len(labels))
    moved = _keyframe(transform_points(motion, centres[order]), [labels[i] for i in order], motion @ pose)
    assert _keys(moved, spread=False) == _keys(stored, spread=False)


def test_a_query_finds_the_keys_of_its_place_through_noise_below_half_a_bin() -> None:
    rng = np.random.default_rng(4)
    centres, labels = _street(rng)
    stored = _keyframe(centres, labels)
    noisy = _keyframe(centres + np.column_stack([rng.uniform(-0.12, 0.12, (10, 2)), np.zeros(10)]), labels)
    # Each side moves by less than half a 1 m bin: every stored key is among the query's.
    assert _keys(stored, spread=False) <= _keys(noisy, spread=True)
    assert not _keys(stored, spread=False) <= _keys(noisy, spread=False)  # without spreading, some are lost


def test_the_place_is_ranked_first_among_streets_of_the_same_kind() -> None:
    rng = np.random.default_rng(5)
    index = TriangleIndex(side_bin=1.0, max_objects=12, max_side=40.0)
    streets = [_street(rng) for _ in range(300)]
    for i, (centres, labels) in enumerate(streets):
        index.add(_keyframe(centres, labels, id=i))
    assert len(index) == 300 and index.nbytes > 0
    hits = 0
    for target in range(0, 300, 15):
        centres, labels = streets[target]
        keep = rng.permutation(10)[:7]  # the revisit sees 7 of the 10 objects, with noise, and 2 others
        seen = centres[keep] + np.column_stack([rng.normal(0, 0.3, (7, 2)), np.zeros(7)])
        extra, extra_labels = _street(rng, count=2)
        query = _keyframe(np.vstack([seen, extra]), [labels[i] for i in keep] + extra_labels)
        scores, shared = index.scores(query)
        hits += int(np.argmax(scores) == target)
        assert shared[target] >= 4  # the seven objects seen again share their triangles
    assert hits >= 18  # of 20


def test_the_tail_scores_as_the_merged_keys_do() -> None:
    rng = np.random.default_rng(6)
    streets = [_street(rng) for _ in range(80)]
    query = _keyframe(*streets[40])
    merged = TriangleIndex(1.0, 12, 40.0)
    for i, street in enumerate(streets):
        merged.add(_keyframe(*street, id=i))
    merged._merge()  # everything sorted
    tail = TriangleIndex(1.0, 12, 40.0)
    for i, street in enumerate(streets):
        tail.add(_keyframe(*street, id=i))
    assert 0 < len(tail._tail_keys) < sum(len(_keys(_keyframe(*street), spread=False)) for street in streets)
    for from_tail, from_sorted in zip(tail.scores(query), merged.scores(query), strict=True):
        np.testing.assert_allclose(from_tail, from_sorted)


def test_an_empty_index_and_a_keyframe_of_two_objects_score_nothing() -> None:
    index = TriangleIndex(1.0, 12, 40.0)
    triangle = _keyframe([[0, 0, 0], [5, 0, 0], [0, 5, 0]], ["car"] * 3)
    assert [part.shape for part in index.scores(triangle)] == [(0,), (0,)]
    index.add(_keyframe([[0, 0, 0], [5, 0, 0]], ["car"] * 2))
    assert [part.tolist() for part in index.scores(triangle)] == [[0.0], [0.0]]


def test_a_keyframe_without_objects_is_stored_and_queried_with_no_keys() -> None:
    index = TriangleIndex(1.0, 12, 40.0)
    empty = _keyframe(np.zeros((0, 3)), [])
    index.add(empty)
    assert [part.tolist() for part in index.scores(empty)] == [[0.0], [0.0]]
