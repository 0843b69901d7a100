"""The map the loop query is timed on (benchmarks/_loop_speed.py): the drives laid again and again, each copy after
the first with its objects moved by a smooth field of its own, so that it is one consistent world but not a twin
of the drive it was laid from."""

from __future__ import annotations

import numpy as np
from benchmarks._loop_speed import FIELD_SHIFT_M, displaced, tiled

from neoslam.config import load_config
from neoslam.loop.matching import match_keyframes
from neoslam.types import Keyframe

SPACING_M = 5.0


def street_drive(keyframes: int = 8, seed: int = 0) -> list[Keyframe]:
    """Keyframes every 5 m along a street of parked objects, each holding the objects within 20 m of it."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(3.0, 7.0, 40))
    y = np.where(np.arange(40) % 2 == 0, 1.0, -1.0) * rng.uniform(4.0, 7.0, 40)
    objects = np.column_stack([x, y, np.full(40, 0.8)])
    drive = []
    for index in range(keyframes):
        pose = np.eye(4)
        pose[0, 3] = 40.0 + SPACING_M * index
        near = np.flatnonzero(np.abs(objects[:, 0] - pose[0, 3]) <= 20.0)
        drive.append(
            Keyframe(
                id=index,
                frame_index=10 * index,
                pose=pose,
                centers=objects[near] + rng.normal(0.0, 0.05, (len(near), 3)),
                labels=("car",) * len(near),
                patches=np.full((len(near), 16, 16), 128, np.uint8),
                covariances=np.tile(0.01 * np.eye(2), (len(near), 1, 1)),
            )
        )
    return drive


def test_a_copy_moves_its_objects_by_metres_and_neighbouring_estimates_alike() -> None:
    rng = np.random.default_rng(1)
    centres = np.column_stack([rng.uniform(-200, 200, (500, 2)), np.zeros(500)])
    moved = displaced(centres, copy=3)
    shift = np.linalg.norm(moved[:, :2] - centres[:, :2], axis=1)
    assert 0.5 * FIELD_SHIFT_M < np.sqrt(np.mean(shift**2)) < 1.5 * FIELD_SHIFT_M
    assert np.array_equal(moved[:, 2], centres[:, 2])
    # another estimate of each object, 30 cm off, moves within a few decimetres of it: far inside the matching's
    # e_max (1.5 m) and the radius within which a place's estimates are one object (2.5 m)
    nearby = centres + np.array([0.3, 0.0, 0.0])
    assert np.max(np.linalg.norm((displaced(nearby, 3) - nearby) - (moved - centres), axis=1)) < 0.25
    assert np.array_equal(displaced(centres, 3), moved)
    assert not np.allclose(displaced(centres, 4), moved)


def test_distinct_copies_are_not_twins_of_their_drive_and_repeated_ones_are() -> None:
    drive = street_drive()
    config = load_config(environ={})
    size = 4 * len(drive)  # the one drive laid four times
    for distinct in (False, True):
        laid = tiled([drive], size, distinct=distinct)
        assert [k.id for k, _ in laid] == list(range(size))
        assert np.allclose(laid[0][0].centers, drive[0].centers)  # the drive's first laying is the drive
        odometer = [reading for _, reading in laid]
        assert odometer == sorted(odometer)
        first, copy = laid[3][0], laid[3 + 2 * len(drive)][0]
        assert not np.allclose(first.pose, copy.pose)  # each copy in a world of its own
        match = match_keyframes(copy, first, config.matching, config.keyframes.e_max)
        assert match.verified != distinct
