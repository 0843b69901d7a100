"""Reading and writing TUM / KITTI trajectory files, on real files in tmp_path and the shared KITTI data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.errors import InputError
from neoslam.geometry import make_pose, quaternion_from_pose
from neoslam.io.trajectory_files import (
    KITTI_FRAME_PERIOD,
    read_kitti,
    read_times,
    read_trajectory,
    read_tum,
    write_kitti,
    write_times,
    write_tum,
)
from neoslam.types import Trajectory

IDENTITY_KITTI = "1 0 0 0 0 1 0 0 0 0 1 0"
IDENTITY_TUM_TAIL = "0 0 0 0 0 0 1"


def _random_trajectory(n: int = 50, seed: int = 3) -> Trajectory:
    rng = np.random.default_rng(seed)
    rotations = Rotation.random(n, random_state=seed).as_matrix()
    poses = np.stack([make_pose(r, t) for r, t in zip(rotations, rng.uniform(-20, 20, (n, 3)), strict=True)])
    return Trajectory(np.cumsum(rng.uniform(0.05, 0.2, n)), poses)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _error(call, *args) -> InputError:
    with pytest.raises(InputError) as info:
        call(*args)
    return info.value


def _assert_names(error: InputError, path: Path, line: int | None) -> None:
    assert error.path == path
    assert path.name in str(error)
    assert error.line == line
    if line is not None:
        assert f"{path.name}:{line}:" in str(error)


# --- reading well-formed files ------------------------------------------------------------------------------


def test_read_tum_skips_comments_and_blank_lines_and_accepts_commas(tmp_path):
    second = "1.5,1,2,3, 0,0,0.7071068,0.7071068"
    text = f"# timestamp x y z qx qy qz qw\n\n0.0 {IDENTITY_TUM_TAIL}\n  \n{second}\n"
    trajectory = read_tum(_write(tmp_path, "a.tum", text))
    np.testing.assert_array_equal(trajectory.timestamps, [0.0, 1.5])
    np.testing.assert_allclose(trajectory.poses[0], np.eye(4))
    np.testing.assert_allclose(trajectory.positions[1], [1, 2, 3])
    # 90 degrees about z, used as is (no frame change for TUM)
    np.testing.assert_allclose(trajectory.poses[1, :3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-7)


def test_read_tum_normalises_slightly_off_quaternions(tmp_path):
    trajectory = read_tum(_write(tmp_path, "a.tum", "0 0 0 0 0 0 0 1.005\n"))
    np.testing.assert_allclose(trajectory.poses[0], np.eye(4), atol=1e-12)


def test_read_kitti_converts_camera_to_robot_frame(tmp_path):
    # camera moved 2 m along its z (forward) and 1 m along its x (right): robot x forward, y left
    path = _write(tmp_path, "a.txt", f"{IDENTITY_KITTI}\n1 0 0 1 0 1 0 0 0 0 1 2\n")
    trajectory = read_kitti(path)
    np.testing.assert_allclose(trajectory.positions[1], [2.0, -1.0, 0.0])
    np.testing.assert_allclose(trajectory.timestamps, [0.0, KITTI_FRAME_PERIOD])


def test_read_kitti_uses_times_file(tmp_path):
    path = _write(tmp_path, "a.txt", f"{IDENTITY_KITTI}\n{IDENTITY_KITTI}\n")
    times = _write(tmp_path, "times.txt", "1.000000e-01\n2.5e-01\n")
    np.testing.assert_array_equal(read_kitti(path, times).timestamps, [0.1, 0.25])


def test_read_trajectory_auto_detects_both_formats(tmp_path):
    tum = _write(tmp_path, "a.tum", f"# header\n0 1 2 3 0 0 0 1\n1 {IDENTITY_TUM_TAIL}\n")
    kitti = _write(tmp_path, "a.txt", f"{IDENTITY_KITTI}\n")
    np.testing.assert_allclose(read_trajectory(tum, "auto").positions[0], [1, 2, 3])
    assert len(read_trajectory(kitti, "auto")) == 1
    assert len(read_trajectory(tum, "tum")) == 2
    assert len(read_trajectory(kitti, "kitti")) == 1


# --- one test per kind of bad input -------------------------------------------------------------------------


@pytest.mark.parametrize("reader", [read_tum, read_kitti, read_times])
def test_missing_file(tmp_path, reader):
    path = tmp_path / "nope.txt"
    error = _error(reader, path)
    _assert_names(error, path, None)
    assert "not found" in error.problem


@pytest.mark.parametrize("reader", [read_tum, read_kitti, read_times])
@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n   \n"])
def test_empty_file(tmp_path, reader, text):
    path = _write(tmp_path, "empty.txt", text)
    error = _error(reader, path)
    _assert_names(error, path, None)
    assert "no data lines" in error.problem


def test_wrong_column_count_tum(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n1 0 0 0 0 0 1\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 2)
    assert error.problem == "7 columns found, 8 expected"


def test_wrong_column_count_kitti(tmp_path):
    path = _write(tmp_path, "a.txt", f"# c\n{IDENTITY_KITTI} 5\n")
    error = _error(read_kitti, path)
    _assert_names(error, path, 2)
    assert error.problem == "13 columns found, 12 expected"


def test_value_that_is_not_a_number(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n1 0 0 1.2.3 0 0 0 1\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 2)
    assert error.problem == "not a number: '1.2.3'"


def test_empty_field_between_commas_is_not_a_number(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n1,,0,0,0,0,0,1\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 2)
    assert error.problem == "not a number: ''"


@pytest.mark.parametrize("token", ["nan", "inf", "-Infinity", "NaN"])
def test_nan_or_inf(tmp_path, token):
    path = _write(tmp_path, "a.txt", f"{IDENTITY_KITTI}\n{IDENTITY_KITTI}\n1 0 0 {token} 0 1 0 0 0 0 1 0\n")
    error = _error(read_kitti, path)
    _assert_names(error, path, 3)
    assert error.problem == f"value is not finite: {token!r}"


def test_non_orthonormal_rotation_kitti(tmp_path):
    scaled = f"{np.sqrt(1.2):.12f} 0 0 0 0 1 0 0 0 0 1 0"
    path = _write(tmp_path, "a.txt", f"{IDENTITY_KITTI}\n{scaled}\n")
    error = _error(read_kitti, path)
    _assert_names(error, path, 2)
    assert error.problem == "rotation is not orthonormal (|RR^T - I| = 0.2)"


def test_reflection_is_not_a_rotation_kitti(tmp_path):
    path = _write(tmp_path, "a.txt", "-1 0 0 0 0 1 0 0 0 0 1 0\n")
    error = _error(read_kitti, path)
    _assert_names(error, path, 1)
    assert "reflection" in error.problem


def test_non_unit_quaternion_tum(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n1 0 0 0 0 0 0 0.73\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 2)
    assert error.problem == "non-unit quaternion (norm 0.73)"


def test_zero_quaternion_tum(tmp_path):
    path = _write(tmp_path, "a.tum", "0 0 0 0 0 0 0 0\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 1)
    assert error.problem == "zero quaternion"


@pytest.mark.parametrize(("second", "third", "word"), [("1.0", "0.5", "goes back from"), ("1.0", "1.0", "repeats")])
def test_timestamps_not_increasing_tum(tmp_path, second, third, word):
    lines = [f"{t} {IDENTITY_TUM_TAIL}" for t in ("0.0", second, third)]
    path = _write(tmp_path, "a.tum", "\n".join(lines) + "\n")
    error = _error(read_tum, path)
    _assert_names(error, path, 3)
    assert error.problem == f"timestamp {float(third)} {word} {float(second)} at line 2"


@pytest.mark.parametrize(
    ("text", "problem"), [("0\n0.2\n0.1\n", "0.1 goes back from 0.2"), ("0\n0\n", "0.0 repeats 0.0")]
)
def test_timestamps_not_increasing_times_file(tmp_path, text, problem):
    path = _write(tmp_path, "times.txt", text)
    error = _error(read_times, path)
    line = text.count("\n")
    _assert_names(error, path, line)
    assert error.problem == f"timestamp {problem} at line {line - 1}"


@pytest.mark.parametrize("n_times", [1, 3])
def test_times_file_with_wrong_number_of_lines(tmp_path, n_times):
    poses = _write(tmp_path, "05.txt", f"{IDENTITY_KITTI}\n{IDENTITY_KITTI}\n")
    times = _write(tmp_path, "times.txt", "".join(f"{0.1 * i}\n" for i in range(n_times)))
    error = _error(read_kitti, poses, times)
    _assert_names(error, times, None)
    assert error.problem == f"{n_times} timestamps for the 2 poses of 05.txt"


def test_bad_times_file_is_named_not_the_pose_file(tmp_path):
    poses = _write(tmp_path, "05.txt", f"{IDENTITY_KITTI}\n")
    times = _write(tmp_path, "times.txt", "zero\n")
    _assert_names(_error(read_kitti, poses, times), times, 1)


def test_unknown_format(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n")
    error = _error(read_trajectory, path, "csv")
    _assert_names(error, path, None)
    assert "unknown trajectory format 'csv'" in error.problem


def test_auto_format_with_unexpected_column_count(tmp_path):
    path = _write(tmp_path, "a.txt", "# x y z\n\n1 2 3\n")
    error = _error(read_trajectory, path, "auto")
    _assert_names(error, path, 3)
    assert error.problem == "cannot tell the format: 3 columns found (8 for TUM, 12 for KITTI)"


def test_times_file_given_for_a_tum_file(tmp_path):
    path = _write(tmp_path, "a.tum", f"0 {IDENTITY_TUM_TAIL}\n")
    times = _write(tmp_path, "times.txt", "0\n")
    _assert_names(_error(read_trajectory, path, "auto", times), times, None)


# --- writers and round trips --------------------------------------------------------------------------------


def test_writers_produce_deterministic_text(tmp_path):
    pose = make_pose(np.eye(3), [1.0, -2.0, 0.5])
    trajectory = Trajectory(np.array([0.25]), pose[None])
    write_tum(tmp_path / "a.tum", trajectory)
    write_kitti(tmp_path / "a.txt", trajectory)
    write_times(tmp_path / "times.txt", trajectory.timestamps)
    expected_tum = "0.250000 1.000000000 -2.000000000 0.500000000 " + " ".join(["0.000000000"] * 3) + " 1.000000000\n"
    assert (tmp_path / "a.tum").read_text() == expected_tum
    # robot (1, -2, 0.5) is camera (x right = 2, y down = -0.5, z forward = 1)
    kitti = [float(v) for v in (tmp_path / "a.txt").read_text().split()]
    np.testing.assert_array_equal(kitti, [1, 0, 0, 2, 0, 1, 0, -0.5, 0, 0, 1, 1])
    assert "1.000000000e+00" in (tmp_path / "a.txt").read_text()
    assert (tmp_path / "times.txt").read_text() == "0.250000000\n"


def test_tum_round_trip(tmp_path):
    trajectory = _random_trajectory()
    write_tum(tmp_path / "a.tum", trajectory)
    again = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(again.poses, trajectory.poses, atol=1e-8)
    np.testing.assert_allclose(again.timestamps, trajectory.timestamps, atol=1e-6)


def test_kitti_round_trip_with_times(tmp_path):
    trajectory = _random_trajectory()
    write_kitti(tmp_path / "a.txt", trajectory)
    write_times(tmp_path / "times.txt", trajectory.timestamps)
    again = read_kitti(tmp_path / "a.txt", tmp_path / "times.txt")
    np.testing.assert_allclose(again.poses, trajectory.poses, atol=1e-8)
    np.testing.assert_allclose(again.timestamps, trajectory.timestamps, atol=1e-9)


def test_real_kitti_05(kitti_poses, tmp_path):
    trajectory = read_kitti(kitti_poses("05"))
    assert len(trajectory) == 2761
    np.testing.assert_allclose(trajectory.poses[0], np.eye(4), atol=1e-9)
    np.testing.assert_allclose(trajectory.timestamps[-1], 2760 * KITTI_FRAME_PERIOD)
    # the car drives forward: after 1 s it is ~5.5 m along robot +x and hardly moved sideways or up
    start = trajectory.positions[10]
    assert start[0] > 5.0
    assert abs(start[1]) < 0.1 * start[0] and abs(start[2]) < 0.1 * start[0]
    # the published values have 7 significant digits, so writing with 10 and reading back is exact
    write_kitti(tmp_path / "05.txt", trajectory)
    np.testing.assert_allclose(read_kitti(tmp_path / "05.txt").poses, trajectory.poses, rtol=0, atol=1e-8)


def test_real_kitti_times_00(shared_data, kitti_poses):
    times_path = shared_data / "kitti" / "times" / "00.txt"
    times = read_times(times_path)
    assert times.shape == (4541,)
    assert np.all(np.diff(times) > 0)
    assert np.diff(times).mean() == pytest.approx(KITTI_FRAME_PERIOD, abs=1e-4)
    trajectory = read_trajectory(kitti_poses("00"), "auto", times_path)
    np.testing.assert_array_equal(trajectory.timestamps, times)


def test_evo_reads_write_tum_output_identically(tmp_path):
    from evo.tools import file_interface

    trajectory = _random_trajectory()
    write_tum(tmp_path / "a.tum", trajectory)
    evo_trajectory = file_interface.read_tum_trajectory_file(str(tmp_path / "a.tum"))
    np.testing.assert_allclose(evo_trajectory.timestamps, trajectory.timestamps, atol=1e-6)
    np.testing.assert_allclose(evo_trajectory.positions_xyz, trajectory.positions, atol=1e-8)
    evo_xyzw = np.roll(evo_trajectory.orientations_quat_wxyz, -1, axis=1)  # evo keeps w first
    np.testing.assert_allclose(evo_xyzw, quaternion_from_pose(trajectory.poses), atol=1e-8)
    np.testing.assert_allclose(evo_trajectory.poses_se3, trajectory.poses, atol=1e-8)
