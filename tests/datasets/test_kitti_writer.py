"""A stereo sequence written as a KITTI root reads back as it was: images, calibration, times and poses."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from neoslam.datasets.kitti import read_calibration, read_kitti_sequence
from neoslam.datasets.kitti_writer import write_kitti_sequence
from neoslam.datasets.replay import PhotometricChange, ReplayedSequence

FRAMES = 4


@pytest.fixture(scope="module")
def street(shared_data: Path):
    """The first frames of kitti_06_51 (real KITTI 06 images, times and poses)."""
    root = shared_data / "kitti_06_51"
    if not (root / "sequences" / "06").is_dir():
        pytest.skip(f"kitti_06_51 not found under {shared_data}")
    whole = read_kitti_sequence(root, "06")
    return replace(
        whole,
        timestamps=whole.timestamps[:FRAMES],
        left_images=whole.left_images[:FRAMES],
        right_images=whole.right_images[:FRAMES],
        ground_truth=whole.ground_truth.subset(np.arange(FRAMES)),
    )


def _same_camera(a, b) -> None:
    for field in ("fx", "fy", "cx", "cy", "width", "height", "baseline"):
        assert getattr(a, field) == pytest.approx(getattr(b, field), rel=1e-12), field


def test_a_kitti_sequence_reads_back_as_it_was(street, tmp_path: Path) -> None:
    folder = write_kitti_sequence(tmp_path / "root", "07", street)
    assert folder == tmp_path / "root" / "sequences" / "07"
    back = read_kitti_sequence(tmp_path / "root", "07")
    assert len(back) == FRAMES
    for index in range(FRAMES):
        for ours, theirs in zip(back.stereo_pair(index), street.stereo_pair(index), strict=True):
            np.testing.assert_array_equal(ours, theirs)
    _same_camera(back.camera, street.camera)
    np.testing.assert_array_equal(back.timestamps, street.timestamps)
    np.testing.assert_allclose(back.ground_truth.poses, street.ground_truth.poses, atol=1e-8)
    original = read_calibration(street.root / "sequences" / "06" / "calib.txt")
    for ours, theirs in zip(read_calibration(folder / "calib.txt"), original, strict=True):
        np.testing.assert_allclose(ours, theirs, rtol=1e-12)
    keys = [line.split(":")[0] for line in (folder / "calib.txt").read_text().splitlines()]
    assert keys == ["P0", "P1", "P2", "P3"]


def test_a_replayed_sequence_reads_back_as_replayed(street, tmp_path: Path) -> None:
    change = PhotometricChange(gain=0.8, offset=15.0, noise_sigma=3.0, blur_sigma=0.7, shift_x=1.3, seed=2)
    order = (3, 2, 1, 0, 1, 2)
    replay = ReplayedSequence(street, order, (None,) * 3 + (change,) * 3, label="back-forward")
    write_kitti_sequence(tmp_path, "00", replay)
    back = read_kitti_sequence(tmp_path, "00")
    assert len(back) == len(order)
    for index in (0, 4):
        for ours, theirs in zip(back.stereo_pair(index), replay.stereo_pair(index), strict=True):
            np.testing.assert_array_equal(ours, theirs)
    _same_camera(back.camera, street.camera)
    np.testing.assert_allclose(back.timestamps, replay.timestamps, atol=1e-9)
    np.testing.assert_allclose(back.ground_truth.poses, street.ground_truth.poses[list(order)], atol=1e-8)


def test_no_ground_truth_no_pose_file_and_no_overwrite(street, tmp_path: Path) -> None:
    write_kitti_sequence(tmp_path, "01", replace(street, ground_truth=None))
    assert not (tmp_path / "poses").exists()
    assert read_kitti_sequence(tmp_path, "01").ground_truth is None
    with pytest.raises(FileExistsError):
        write_kitti_sequence(tmp_path, "01", street)
