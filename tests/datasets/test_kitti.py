"""The KITTI odometry reader: the real kitti_mini sequence, and every malformed layout giving one clear error."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam.datasets.kitti import is_kitti_root, read_calibration, read_kitti_sequence
from neoslam.errors import InputError

WIDTH, HEIGHT, FRAMES = 64, 32, 3
FX, BASELINE = 50.0, 0.5


def _calib_line(key: str, tx: float, cx: float = WIDTH / 2, cy: float = HEIGHT / 2) -> str:
    values = [FX, 0, cx, tx, 0, FX, cy, 0, 0, 0, 1, 0]
    return f"{key}: " + " ".join(f"{v:.6e}" for v in values)


def make_kitti_root(root: Path, frames: int = FRAMES, width: int = WIDTH, poses: bool = True) -> Path:
    """A small KITTI odometry root with sequence 00: textured images, calibration, times and poses."""
    folder = root / "sequences" / "00"
    rng = np.random.default_rng(0)
    for camera in ("image_0", "image_1"):
        (folder / camera).mkdir(parents=True)
        for i in range(frames):
            image = rng.integers(0, 255, (HEIGHT, width), dtype=np.uint8)
            cv2.imwrite(str(folder / camera / f"{i:06d}.png"), image)
    (folder / "calib.txt").write_text(f"{_calib_line('P0', 0.0)}\n{_calib_line('P1', -FX * BASELINE)}\n")
    (folder / "times.txt").write_text("".join(f"{0.1 * i:.6e}\n" for i in range(frames)))
    if poses:
        (root / "poses").mkdir()
        lines = [f"1 0 0 0 0 1 0 0 0 0 1 {0.5 * i}\n" for i in range(frames)]
        (root / "poses" / "00.txt").write_text("".join(lines))
    return root


@pytest.fixture
def kitti_root(tmp_path: Path) -> Path:
    return make_kitti_root(tmp_path / "kitti")


def test_reads_a_sequence(kitti_root: Path) -> None:
    sequence = read_kitti_sequence(kitti_root, "00")
    assert is_kitti_root(kitti_root)
    assert len(sequence) == FRAMES
    assert sequence.camera.fx == FX and sequence.camera.baseline == pytest.approx(BASELINE)
    assert (sequence.camera.width, sequence.camera.height) == (WIDTH, HEIGHT)
    left, right = sequence.stereo_pair(2)
    assert left.shape == right.shape == (HEIGHT, WIDTH) and left.dtype == np.uint8
    # KITTI camera z forward becomes robot x forward.
    np.testing.assert_allclose(sequence.ground_truth.positions[2], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sequence.timestamps, [0.0, 0.1, 0.2])


def test_poses_are_optional(tmp_path: Path) -> None:
    sequence = read_kitti_sequence(make_kitti_root(tmp_path, poses=False), "00")
    assert sequence.ground_truth is None


def test_reads_the_real_kitti_mini(shared_data: Path) -> None:
    sequence = read_kitti_sequence(shared_data / "kitti_mini", "06")
    assert len(sequence) == 12
    assert sequence.camera.fx == pytest.approx(707.0912)
    assert sequence.camera.baseline == pytest.approx(379.8145 / 707.0912)
    assert (sequence.camera.width, sequence.camera.height) == (1226, 370)
    assert len(sequence.ground_truth) == 12
    assert sequence.stereo_pair(11)[0].shape == (370, 1226)


def _error(root: Path, sequence: str = "00") -> InputError:
    with pytest.raises(InputError) as caught:
        read_kitti_sequence(root, sequence)
    return caught.value


def test_missing_sequence_lists_the_ones_there(kitti_root: Path) -> None:
    error = _error(kitti_root, "07")
    assert error.path == kitti_root / "sequences" / "07"
    assert "sequences here: 00" in str(error)


def test_missing_calibration(kitti_root: Path) -> None:
    (kitti_root / "sequences" / "00" / "calib.txt").unlink()
    assert "calibration file not found" in str(_error(kitti_root))


@pytest.mark.parametrize(
    ("text", "problem", "line"),
    [
        (_calib_line("P0", 0.0) + "\n", "no P1 line", None),
        ("P0: 1 2 3\n", "P0 has 3 numbers, 12 expected", 1),
        ("\n" + _calib_line("P0", 0.0).replace("5.000000e+01", "fifty", 1) + "\n", "not a number", 2),
        (_calib_line("P0", 0.0) + "\n" + _calib_line("P1", float("nan")) + "\n", "not finite", 2),
        (_calib_line("P0", 0.0) + "\n" + _calib_line("P1", FX * BASELINE) + "\n", "non-positive stereo baseline", None),
    ],
)
def test_malformed_calibration(kitti_root: Path, text: str, problem: str, line: int | None) -> None:
    path = kitti_root / "sequences" / "00" / "calib.txt"
    path.write_text(text)
    error = _error(kitti_root)
    assert error.path == path and problem in error.problem and error.line == line


def test_read_calibration_returns_both_projections(kitti_root: Path) -> None:
    left, right = read_calibration(kitti_root / "sequences" / "00" / "calib.txt")
    assert left.shape == right.shape == (3, 4)
    assert right[0, 3] == pytest.approx(-FX * BASELINE)


def test_missing_times(kitti_root: Path) -> None:
    (kitti_root / "sequences" / "00" / "times.txt").unlink()
    assert "times file not found" in str(_error(kitti_root))


def test_missing_frame_names_the_image(kitti_root: Path) -> None:
    missing = kitti_root / "sequences" / "00" / "image_1" / "000001.png"
    missing.unlink()
    error = _error(kitti_root)
    assert error.path == missing and "frame missing" in error.problem


def test_more_images_than_times(kitti_root: Path) -> None:
    (kitti_root / "sequences" / "00" / "times.txt").write_text("0\n0.1\n")
    assert "1 more images than the 2 lines of times.txt" in str(_error(kitti_root))


def test_missing_image_folder(kitti_root: Path) -> None:
    folder = kitti_root / "sequences" / "00" / "image_0"
    for image in folder.iterdir():
        image.unlink()
    folder.rmdir()
    error = _error(kitti_root)
    assert error.path == folder and "image folder not found" in error.problem


def test_image_size_that_disagrees_with_the_calibration(tmp_path: Path) -> None:
    root = make_kitti_root(tmp_path, width=2 * WIDTH)  # the calibration's principal point is at WIDTH / 2
    error = _error(root)
    assert error.path.name == "000000.png" and "does not match the calibration" in error.problem


def test_a_frame_of_another_size_is_named_when_read(kitti_root: Path) -> None:
    path = kitti_root / "sequences" / "00" / "image_1" / "000002.png"
    cv2.imwrite(str(path), np.zeros((HEIGHT, WIDTH + 2), np.uint8))
    sequence = read_kitti_sequence(kitti_root, "00")
    with pytest.raises(InputError) as caught:
        sequence.stereo_pair(2)
    assert caught.value.path == path and f"{WIDTH + 2}x{HEIGHT}" in caught.value.problem


def test_unreadable_image(kitti_root: Path) -> None:
    path = kitti_root / "sequences" / "00" / "image_0" / "000001.png"
    path.write_bytes(b"not a png")
    sequence = read_kitti_sequence(kitti_root, "00")
    with pytest.raises(InputError) as caught:
        sequence.stereo_pair(1)
    assert caught.value.path == path and "not a readable image" in caught.value.problem


def test_pose_count_must_match_the_times(kitti_root: Path) -> None:
    (kitti_root / "poses" / "00.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    error = _error(kitti_root)
    # The pose file is what is short (times.txt matched the images already): it is the file named.
    assert error.path == kitti_root / "poses" / "00.txt"
    assert "1 poses for the 3 frames of times.txt" in error.problem
