"""Stored places: neighbouring keyframes of one pass merged into one keyframe."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.geometry import make_pose
from neoslam.loop.index import StoredKeyframes
from neoslam.loop.places import PlaceCache, merge_keyframes
from neoslam.types import Keyframe


def _keyframe(id: int, x: float, centres, labels, spread: float = 0.1, provisional=None) -> Keyframe:
    centres = np.asarray(centres, dtype=float)
    n = len(centres)
    return Keyframe(
        id=id,
        frame_index=10 * id,
        pose=make_pose(np.eye(3), np.array([x, 0.0, 1.65])),
        centers=centres,
        labels=tuple(labels),
        patches=np.full((n, 16, 16), 100 + id, np.uint8),
        provisional=provisional,
        covariances=np.tile(np.eye(2) * spread, (n, 1, 1)),
    )


def test_the_same_object_in_two_keyframes_is_one_the_best_known_estimate() -> None:
    first = _keyframe(0, 0.0, [[5.0, 5.0, 0.0], [10.0, -5.0, 0.0]], ["car", "car"], spread=0.5)
    second = _keyframe(1, 5.0, [[5.8, 5.1, 0.0], [10.3, -5.0, 0.0], [20.0, 5.0, 0.0]], ["car", "truck", "car"], 0.2)
    merged = merge_keyframes([first, second], second, association_radius=2.5)
    # The cars at (5, 5) are one object, held at the second keyframe's (better known) estimate; the truck beside
    # the car at (10, -5) is another object (labels differ); the car at (20, 5) is new.
    assert merged.id == 1 and np.array_equal(merged.pose, second.pose)
    order = np.lexsort((merged.labels, merged.centers[:, 0]))
    np.testing.assert_allclose(merged.centers[order, :2], [[5.8, 5.1], [10.0, -5.0], [10.3, -5.0], [20.0, 5.0]])
    assert [merged.labels[i] for i in order] == ["car", "car", "truck", "car"]
    np.testing.assert_allclose(merged.covariances[order[0]], np.eye(2) * 0.2)
    assert merged.patches[order[0]].mean() == 101 and merged.patches[order[1]].mean() == 100


def test_a_merged_keyframe_was_seen_from_every_member_and_moves_with_its_objects() -> None:
    first = _keyframe(0, 0.0, [[5.0, 5.0, 0.0]], ["car"])
    second = _keyframe(1, 5.0, [[12.0, -5.0, 0.0]], ["car"])
    merged = merge_keyframes([first, second], second, association_radius=2.5)
    np.testing.assert_allclose(merged.views, [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    turn = make_pose(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.array([100.0, 0.0, 0.0]))
    moved = merged.moved(turn)  # a quarter turn, then 100 m along x
    np.testing.assert_allclose(moved.views, [[100.0, 0.0, np.pi / 2], [100.0, 5.0, np.pi / 2]], atol=1e-12)


def test_a_merged_object_is_provisional_only_when_every_estimate_is() -> None:
    first = _keyframe(0, 0.0, [[5.0, 5.0, 0.0], [15.0, 5.0, 0.0]], ["car", "car"], provisional=[True, True])
    second = _keyframe(1, 5.0, [[5.2, 5.0, 0.0], [15.2, 5.0, 0.0]], ["car", "car"], provisional=[False, True])
    merged = merge_keyframes([first, second], second, association_radius=2.5)
    order = np.argsort(merged.centers[:, 0])
    assert merged.provisional[order].tolist() == [False, True]


def _stored(xs) -> StoredKeyframes:
    stored = StoredKeyframes()
    for i, x in enumerate(xs):
        stored.append(_keyframe(i, x, [[x, 5.0, 0.0]], ["car"]))
    return stored


def test_a_place_is_the_keyframes_of_its_pass_within_the_radius() -> None:
    # A pass every 5 m from 0 to 50, then a second pass of the same street from 0 again: the stored order steps
    # back by 50 m between them.
    stored = _stored([*np.arange(0.0, 51.0, 5.0), *np.arange(0.0, 31.0, 5.0)])
    cache = PlaceCache(radius=12.0, association_radius=2.5)
    place = cache.place(stored, 4)  # x = 20 on the first pass
    assert place.members == (2, 3, 4, 5, 6)
    assert len(place.keyframe.labels) == 5 and place.keyframe.id == 4
    end = cache.place(stored, 10)  # x = 50, the last of the first pass: the second pass starts far from it
    assert end.members == (8, 9, 10)
    start = cache.place(stored, 11)  # x = 0 on the second pass: the first pass ended 50 m away
    assert start.members == (11, 12, 13)
    alone = PlaceCache(radius=0.0, association_radius=2.5).place(stored, 4)
    assert alone.members == (4,) and alone.keyframe is stored.at(4)


def test_a_place_is_kept_once_no_later_keyframe_can_join_it() -> None:
    stored = _stored(np.arange(0.0, 21.0, 5.0))
    cache = PlaceCache(radius=12.0, association_radius=2.5)
    last = cache.place(stored, 4)  # the newest keyframe: the next one may join it
    assert last.members == (2, 3, 4)
    stored.append(_keyframe(5, 25.0, [[25.0, 5.0, 0.0]], ["car"]))
    assert cache.place(stored, 4).members == (2, 3, 4, 5)
    inner = cache.place(stored, 2)
    assert cache.place(stored, 2) is inner  # made once


def test_the_cache_keeps_the_places_last_asked_for() -> None:
    stored = _stored(np.arange(0.0, 51.0, 5.0))
    cache = PlaceCache(radius=12.0, association_radius=2.5, capacity=3)
    first = cache.place(stored, 1)
    for slot in (2, 3):
        cache.place(stored, slot)
    assert cache.place(stored, 1) is first and len(cache) == 3  # asked for again: now the newest
    cache.place(stored, 4)  # one more: the least recently asked for (slot 2) goes
    assert len(cache) == 3 and cache.place(stored, 1) is first
    assert cache.place(stored, 2).members == (0, 1, 2, 3, 4)  # made again, the same place


def _merged_by_rows(keyframes: list[Keyframe], anchor: Keyframe, association_radius: float) -> Keyframe:
    """merge_keyframes as its docstring says it, object by object over rows of numpy: the reference."""
    centers = np.concatenate([k.centers for k in keyframes])
    labels = np.array([label for k in keyframes for label in k.labels])
    covariances = np.concatenate([k.covariances for k in keyframes])
    provisional = np.concatenate([k.provisional for k in keyframes])
    order = np.argsort(np.trace(covariances, axis1=1, axis2=2), kind="stable")
    distance = np.linalg.norm(centers[:, None, :2] - centers[None, :, :2], axis=2)
    distance[labels[:, None] != labels[None, :]] = np.inf
    standing, known, kept = np.zeros(len(labels), dtype=bool), ~provisional, []
    for i in order:
        near = np.where(standing, distance[i], np.inf)
        j = int(np.argmin(near))
        if near[j] <= association_radius:
            known[j] |= not provisional[i]
            continue
        standing[i] = True
        kept.append(int(i))
    keep = np.array(kept, dtype=int)
    patches = np.concatenate([k.patches for k in keyframes])[keep]
    return Keyframe(anchor.id, anchor.frame_index, anchor.pose, centers[keep], tuple(labels[keep].tolist()), patches,
                    ~known[keep], covariances[keep])  # fmt: skip


@pytest.mark.parametrize("seed", range(5))
def test_a_merge_is_the_object_by_object_one(seed: int) -> None:
    rng = np.random.default_rng(seed)
    keyframes = []
    for i in range(6):  # a crowded street: many objects of few labels within the association radius of others
        n = int(rng.integers(5, 15))
        centres = np.column_stack([rng.uniform(0, 30, n), rng.uniform(-6, 6, n), rng.uniform(0, 2, n)])
        labels = rng.choice(["car", "truck", "bicycle"], n).tolist()
        keyframes.append(_keyframe(i, 5.0 * i, centres, labels, spread=float(rng.uniform(0.05, 1.0)),
                                   provisional=rng.random(n) < 0.3))  # fmt: skip
    merged = merge_keyframes(keyframes, keyframes[2], association_radius=2.5)
    expected = _merged_by_rows(keyframes, keyframes[2], association_radius=2.5)
    assert merged.labels == expected.labels
    for field in ("centers", "patches", "provisional", "covariances", "distances", "pose"):
        assert np.array_equal(getattr(merged, field), getattr(expected, field))
