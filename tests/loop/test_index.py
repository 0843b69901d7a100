"""Candidate retrieval: the signature and which stored keyframes are eligible and ranked."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from neoslam.config import MatchingConfig
from neoslam.geometry import make_pose, transform_points
from neoslam.loop.index import INITIAL_CAPACITY, RANK_CHUNK, KeyframeIndex, _best_first, signature

CONFIG = MatchingConfig()
LABELS = ["car", "truck", "bicycle", "person"]


def _random_keyframe(make_keyframe, rng, count=12, position=(0.0, 0.0), id=0):
    centres = np.column_stack([rng.uniform(-20, 20, count), rng.uniform(-7, 7, count), rng.uniform(0, 1.5, count)])
    pose = make_pose(np.eye(3), [*position, 1.65])
    return make_keyframe(centres + [*position, 0.0], rng.choice(LABELS, count).tolist(), pose=pose, id=id)


@pytest.mark.parametrize("seed", range(4))
def test_signature_ignores_object_order_and_rigid_motion(make_keyframe, seed: int) -> None:
    rng = np.random.default_rng(seed)
    keyframe = _random_keyframe(make_keyframe, rng)
    reference = signature(keyframe)
    np.testing.assert_allclose(np.linalg.norm(reference), 1.0)
    order = rng.permutation(len(keyframe.labels))
    shuffled = make_keyframe(keyframe.centers[order], [keyframe.labels[i] for i in order])
    np.testing.assert_allclose(signature(shuffled), reference, atol=1e-12)
    motion = make_pose(Rotation.from_euler("zyx", [rng.uniform(-np.pi, np.pi), 0.1, -0.2]), rng.uniform(-500, 500, 3))
    moved = make_keyframe(transform_points(motion, keyframe.centers), keyframe.labels)
    np.testing.assert_allclose(signature(moved), reference, atol=1e-12)
    # It does see what is there: another class mix or another layout changes it.
    relabelled = make_keyframe(keyframe.centers, ["car"] * len(keyframe.labels))
    assert signature(relabelled) @ reference < 0.99
    spread = make_keyframe(keyframe.centers * 2, keyframe.labels)
    assert signature(spread) @ reference < 0.99


def _index_with(make_keyframe, rng, rows, config=CONFIG) -> KeyframeIndex:
    """An index of keyframes made at (position, odometer) rows."""
    index = KeyframeIndex(config)
    for i, (position, odometer) in enumerate(rows):
        index.add(_random_keyframe(make_keyframe, rng, position=position, id=i), odometer)
    return index


def test_recent_keyframes_are_not_eligible(make_keyframe) -> None:
    rng = np.random.default_rng(0)
    recent = CONFIG.exclude_recent_distance
    index = _index_with(
        make_keyframe, rng, [((0.0, 0.0), 100.0 - recent - 1), ((0.0, 0.0), 100.0 - recent), ((0, 0), 99.0)]
    )
    np.testing.assert_array_equal(index.eligible(np.zeros(3), 100.0), [0, 1])


def test_eligible_radius_grows_with_the_distance_travelled_since(make_keyframe) -> None:
    rng = np.random.default_rng(1)
    # Keyframes made at the origin after 0, 500 and 1000 m of travel; the query is made after 1100 m.
    index = _index_with(make_keyframe, rng, [((0.0, 0.0), 0.0), ((0.0, 0.0), 500.0), ((0.0, 0.0), 1000.0)])
    radius = [CONFIG.search_radius + CONFIG.search_radius_per_metre * t for t in (1100.0, 600.0, 100.0)]
    assert radius == pytest.approx([125.0, 75.0, 25.0])
    for distance, expected in [(24.0, [0, 1, 2]), (26.0, [0, 1]), (74.0, [0, 1]), (76.0, [0]), (126.0, [])]:
        position = np.array([distance * 0.6, distance * 0.8, 50.0])  # height does not count
        np.testing.assert_array_equal(index.eligible(position, 1100.0), expected)


def test_candidates_are_the_best_signatures_first(make_keyframe) -> None:
    rng = np.random.default_rng(2)
    config = CONFIG.model_copy(update={"candidates": 5, "retrieval": "signature"})
    query = _random_keyframe(make_keyframe, rng, count=14, id=99)
    index = KeyframeIndex(config)
    for i in range(12):  # more and more of the query's objects replaced by others, in a shuffled order
        replaced = int(rng.permutation(12)[0])
        centres = query.centers.copy()
        centres[:replaced] = rng.uniform(-30, 30, (replaced, 3))
        index.add(make_keyframe(centres, query.labels[:replaced][::-1] + query.labels[replaced:], id=i), 0.0)
    index.add(make_keyframe(query.centers, query.labels, id=12), 70.0)  # the best, but too recent
    eligible = index.eligible(query.pose[:3, 3], 100.0)
    assert len(eligible) == 12
    candidates = index.candidates(query, 100.0)
    similarity = np.array([signature(k) @ signature(query) for k in index.keyframes])
    assert len(candidates) == config.candidates
    assert 12 not in candidates
    assert (np.diff(similarity[candidates]) <= 0).all()
    assert similarity[candidates[-1]] >= np.sort(similarity[eligible])[-config.candidates]
    assert len(KeyframeIndex(CONFIG).candidates(query, 100.0)) == 0


def test_growing_past_the_initial_capacity_keeps_every_keyframe(make_keyframe) -> None:
    rng = np.random.default_rng(3)
    count = 2 * INITIAL_CAPACITY + 10
    rows = [((10.0 * i, -3.0 * i), 5.0 * i) for i in range(count)]
    index = _index_with(make_keyframe, rng, rows)
    assert len(index) == count == len(index.keyframes)
    every = np.arange(count)
    for i in [0, 1, INITIAL_CAPACITY - 1, INITIAL_CAPACITY, 2 * INITIAL_CAPACITY, count - 1]:
        # Position, odometer and signature of keyframe i all survived the copies.
        position = np.array([10.0 * i, -3.0 * i, 0.0])
        assert index.nearest(position, every) == i
        assert i in index.eligible(position, 5.0 * i + CONFIG.exclude_recent_distance)
        assert i not in index.eligible(position, 5.0 * i + CONFIG.exclude_recent_distance - 1)
        assert index.candidates(index.keyframes[i], 5.0 * i + 1e6)[0] == i


def test_stored_keyframes_are_named_by_id_when_ids_skip(make_keyframe) -> None:
    """Keyframes recognised as stored ones are not stored (lifelong mapping): the stored ids skip, and every answer
    of the index names keyframes by id, not by position."""
    rng = np.random.default_rng(4)
    ids = [0, 1, 2, 7, 8, 30, 31, 300]
    index = KeyframeIndex(CONFIG)
    for k, keyframe_id in enumerate(ids):
        index.add(_random_keyframe(make_keyframe, rng, position=(20.0 * k, 0.0), id=keyframe_id), 10.0 * k)
    assert len(index) == len(ids) and [k.id for k in index.keyframes] == ids
    assert 30 in index.keyframes and 3 not in index.keyframes and index.keyframes[30].id == 30
    now = 10.0 * len(ids) + CONFIG.exclude_recent_distance
    assert set(index.eligible(np.array([100.0, 0.0, 0.0]), now)) <= set(ids)
    assert index.nearest(np.array([101.0, 0.0, 0.0]), np.array(ids)) == 30  # stored fifth, at x = 100
    assert index.odometer(30) == 50.0
    for keyframe in index.keyframes:
        assert index.candidates(keyframe, 1e6)[0] == keyframe.id
    with pytest.raises(ValueError, match="ids must increase"):
        index.add(_random_keyframe(make_keyframe, rng, id=5), now)


def test_candidates_are_the_keyframes_sharing_most_triangles_first(make_keyframe) -> None:
    """The same keyframes as above ranked by retrieval triangles: fewer of the query's objects replaced, more of
    its triangles shared, a higher rank."""
    rng = np.random.default_rng(2)
    query = _random_keyframe(make_keyframe, rng, count=14, id=99)
    index = KeyframeIndex(CONFIG)
    replaced_counts = rng.permutation(np.arange(0, 12))
    for i, replaced in enumerate(replaced_counts):
        centres = query.centers.copy()
        centres[:replaced] = rng.uniform(-30, 30, (replaced, 3))
        index.add(make_keyframe(centres, query.labels, id=i), 0.0)
    ranked, shared = index.best_first(query, index.eligible(query.pose[:3, 3], 100.0))
    ranked = np.array(list(ranked))
    np.testing.assert_array_equal(ranked[:3], np.argsort(replaced_counts)[:3])
    assert shared[ranked[0]] > shared[ranked[-1]]
    assert index.nbytes > 0


@settings(max_examples=60, deadline=None)
@given(
    scores=st.lists(st.integers(0, 6), min_size=0, max_size=3 * RANK_CHUNK + 5),
    taken=st.integers(0, 3 * RANK_CHUNK + 5),
)
def test_best_first_is_a_stable_sort_however_far_it_is_read(scores: list[int], taken: int) -> None:
    """Sorting a chunk at a time gives the stable sort's order, ties (many here: few distinct scores) included,
    whether the iteration stops early or runs to the end."""
    ids = np.arange(100, 100 + len(scores))
    values = np.asarray(scores, dtype=float) / 3.0
    expected = ids[np.argsort(-values, kind="stable")].tolist()
    got = _best_first(ids, values)
    assert [next(got) for _ in range(min(taken, len(ids)))] == expected[:taken]
    assert list(_best_first(ids, values)) == expected
