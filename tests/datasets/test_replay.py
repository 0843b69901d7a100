"""A replayed stereo sequence: order, photometric changes, ground truth, and the forward-back-forward drive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.replay import PhotometricChange, ReplayedSequence, forward_back_forward


@pytest.fixture(scope="module")
def mini(shared_data: Path):
    return read_kitti_sequence(shared_data / "kitti_mini", "06")


def test_forward_back_forward_order_and_truth(mini) -> None:
    change = PhotometricChange(gain=0.9)
    replay = forward_back_forward(mini, change)
    assert replay.order == tuple(range(12)) + tuple(range(10, -1, -1)) + tuple(range(1, 12))
    assert len(replay) == 34 and replay.changes[:23] == (None,) * 23 and set(replay.changes[23:]) == {change}
    assert np.all(np.diff(replay.timestamps) > 0)
    np.testing.assert_array_equal(replay.ground_truth.poses, mini.ground_truth.poses[list(replay.order)])
    assert replay.camera == mini.camera and replay.name == "kitti-06-forward-back-forward"


def test_unchanged_frames_are_the_base_images(mini) -> None:
    replay = forward_back_forward(mini, PhotometricChange(offset=10))
    for index in (0, 15):
        for ours, theirs in zip(replay.stereo_pair(index), mini.stereo_pair(replay.order[index]), strict=True):
            np.testing.assert_array_equal(ours, theirs)


def test_photometric_change_is_what_it_says_and_deterministic() -> None:
    image = np.full((40, 60), 100, np.uint8)
    assert np.all(PhotometricChange(gain=0.5, offset=20).apply(image, 0, 0) == 70)
    assert np.all(PhotometricChange(gain=3.0).apply(image, 0, 0) == 255)  # clipped
    noisy = PhotometricChange(noise_sigma=5, seed=1)
    assert 3 < np.std(noisy.apply(image, 0, 0).astype(float)) < 7
    np.testing.assert_array_equal(noisy.apply(image, 3, 1), noisy.apply(image, 3, 1))
    assert not np.array_equal(noisy.apply(image, 3, 0), noisy.apply(image, 3, 1))
    ramp = np.tile(np.arange(60, dtype=np.uint8) * 4, (40, 1))
    shifted = PhotometricChange(shift_x=2.0).apply(ramp, 0, 0)
    np.testing.assert_array_equal(shifted[:, 10:50], ramp[:, 8:48])


def test_replay_refuses_frames_outside_the_base(mini) -> None:
    with pytest.raises(ValueError, match="0..11"):
        ReplayedSequence(mini, (0, 12), (None, None))
    with pytest.raises(ValueError, match="changes"):
        ReplayedSequence(mini, (0, 1), (None,))
