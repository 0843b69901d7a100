"""Read and write trajectories as TUM and KITTI text files, with KITTI `times.txt` timestamps.

TUM files (`t x y z qx qy qz qw`) hold robot poses (REP-103) and are used as they are. KITTI files hold camera
poses (x right, y down, z forward) and go through `neoslam.geometry` on the way in and out. Every problem
with an input file is an `InputError` naming the file and, where there is one, the 1-based line.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from neoslam.errors import InputError, OutputError
from neoslam.geometry import camera_poses_to_robot, pose_from_quaternion, quaternion_from_pose, robot_poses_to_camera
from neoslam.text import read_text
from neoslam.types import Trajectory

__all__ = [
    "KITTI_FRAME_PERIOD",
    "MAX_POSITION_M",
    "MAX_TIMESTAMP_S",
    "QUATERNION_NORM_TOLERANCE",
    "ROTATION_TOLERANCE",
    "read_tum",
    "read_kitti",
    "read_times",
    "read_trajectory",
    "data_line_numbers",
    "write_tum",
    "write_kitti",
    "write_times",
]

# Mean frame step of KITTI's times files (0.1037 s in sequence 00, 0.1039 s in 06); used when a sequence
# comes without its times.txt, as sequence 05 does in the shared data.
KITTI_FRAME_PERIOD = 0.1037

# TUM files written with 4-6 decimals have quaternion norms within ~1e-4 of one, so rounding passes; a norm
# further off than 1e-2 means a wrong column order or a corrupt file, which normalising would hide.
QUATERNION_NORM_TOLERANCE = 1e-2

# max |R R^T - I| allowed in a KITTI rotation block. The published ground truth is orthonormal to 3e-7; 1e-3
# also admits float32 or hand-rounded estimates but rejects scaled, sheared or misread blocks.
ROTATION_TOLERANCE = 1e-3

# Largest position any trajectory holds, m (100,000 km: no drive goes further; beyond, squared errors overflow and
# a metric is meaningless) and largest timestamp, s (about 30,000 years: Unix or GPS seconds fit many times over).
MAX_POSITION_M = 1e8
MAX_TIMESTAMP_S = 1e12

# Commas with optional spaces, or runs of whitespace; "1,,2" yields an empty token, reported as not a number.
_SEPARATOR = re.compile(r"\s*,\s*|\s+")
_TOKEN_CHUNK = 2**22  # characters of lines whose tokens are counted at once
_TUM_COLUMNS = 8
_KITTI_COLUMNS = 12


def _data_lines(text: str, path: Path) -> Iterator[tuple[int, list[str]]]:
    """(line number, tokens) of every line that is neither blank nor a `#` comment, one at a time (a file of ten
    million lines is not held as ten million lists)."""
    found = False
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            found = True
            yield number, _SEPARATOR.split(stripped)
    if not found:
        raise InputError(path, "no data lines (the file is empty or only has comments)")


def data_line_numbers(path: str | Path) -> np.ndarray:
    """The 1-based line number of each pose (data line) of a trajectory or times file, to name a pose's line."""
    path = Path(path)
    text = read_text(path)
    rows = _plain_rows(text)
    if rows is not None:
        return np.arange(1, rows + 1)
    return np.fromiter((number for number, _ in _data_lines(text, path)), dtype=np.int64)


def _plain_rows(text: str) -> int | None:
    """The number of lines of a file of numbers only, one row a line, no blank or comment line (then line k is row
    k); None for any other file."""
    if not text or "#" in text or "," in text or "\n\n" in text or text.startswith("\n"):
        return None
    rows = text.count("\n") + (0 if text.endswith("\n") else 1)
    return rows


def _read_plain(text: str, columns: int) -> tuple[np.ndarray, np.ndarray] | None:
    """A plain file of numbers (`_plain_rows`) parsed at once in C: (n, columns) finite floats and line numbers; None
    when the file is not plain, a row has another count of values, or a value is not a finite number (the line by
    line reader then names the line)."""
    rows = _plain_rows(text)
    if rows is None:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # text that stops being numbers: a short array, or numpy's ValueError
        try:
            values = np.fromstring(text, sep=" ")
        except ValueError:
            return None
    if values.size != rows * columns or not np.isfinite(values).all():
        return None
    if not _every_line_has(text, columns):  # whole rows, not the right count of values reflowed
        return None
    return values.reshape(rows, columns), np.arange(1, rows + 1)


def _every_line_has(text: str, columns: int) -> bool:
    """Whether every line holds `columns` whitespace-separated tokens, counted over the bytes a chunk of lines at a
    time (the byte masks of a whole 256 MiB file would take gigabytes)."""
    start = 0
    while start < len(text):
        end = text.find("\n", start + _TOKEN_CHUNK)
        end = len(text) if end < 0 else end + 1
        if not np.all(_tokens_per_line(text[start:end]) == columns):
            return False
        start = end
    return True


def _tokens_per_line(text: str) -> np.ndarray:
    """The number of whitespace-separated tokens on each line, counted over the bytes at once."""
    data = np.frombuffer(text.encode("utf-8", "surrogateescape"), dtype=np.uint8)
    blank = (data == 32) | (data == 9) | (data == 13) | (data == 10)
    starts = np.flatnonzero(~blank & np.concatenate(([True], blank[:-1])))
    ends = np.flatnonzero(data == 10)
    if len(ends) == 0 or ends[-1] != len(data) - 1:
        ends = np.append(ends, len(data))
    return np.diff(np.searchsorted(starts, ends), prepend=0)


def _read_numbers(path: Path, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, columns) finite floats and the (n,) line number each row came from."""
    text = read_text(path)
    plain = _read_plain(text, columns)
    if plain is not None:
        return plain
    values: list[np.ndarray] = []
    numbers: list[int] = []
    for number, tokens in _data_lines(text, path):
        if len(tokens) != columns:
            raise InputError(path, f"{len(tokens)} columns found, {columns} expected", number)
        row = np.empty(columns)
        for j, token in enumerate(tokens):
            try:
                row[j] = float(token)
            except ValueError:
                raise InputError(path, f"not a number: {token!r}", number) from None
            if not np.isfinite(row[j]):
                raise InputError(path, f"value is not finite: {token!r}", number)
        values.append(row)
        numbers.append(number)
    return np.array(values), np.array(numbers)


def _check_magnitude(path: Path, values: np.ndarray, lines: np.ndarray, limit: float, what: str) -> None:
    """A value beyond `limit` in magnitude is a unit slip or a corrupt line, named with its line."""
    rows = np.flatnonzero((np.abs(values) > limit).reshape(len(values), -1).any(axis=1))
    if rows.size:
        i = rows[0]
        worst = np.abs(values[i]).max()
        raise InputError(path, f"{what} of magnitude {worst:.3g} is beyond {limit:g}", int(lines[i]))


def _check_increasing(path: Path, times: np.ndarray, lines: np.ndarray) -> None:
    step_back = np.flatnonzero(np.diff(times) <= 0)
    if step_back.size:
        i = step_back[0]
        verb = "repeats" if times[i + 1] == times[i] else "goes back from"
        problem = f"timestamp {times[i + 1]} {verb} {times[i]} at line {lines[i]}"
        raise InputError(path, problem, int(lines[i + 1]))


def read_times(path: str | Path) -> np.ndarray:
    """Strictly increasing timestamps in seconds, one per line (KITTI `times.txt`)."""
    path = Path(path)
    values, lines = _read_numbers(path, 1)
    _check_magnitude(path, values, lines, MAX_TIMESTAMP_S, "timestamp")
    _check_increasing(path, values[:, 0], lines)
    return values[:, 0]


def read_tum(path: str | Path) -> Trajectory:
    """Robot poses from a TUM file `t x y z qx qy qz qw`; quaternions are normalised."""
    path = Path(path)
    values, lines = _read_numbers(path, _TUM_COLUMNS)
    _check_magnitude(path, values[:, :1], lines, MAX_TIMESTAMP_S, "timestamp")
    _check_magnitude(path, values[:, 1:4], lines, MAX_POSITION_M, "position")
    _check_increasing(path, values[:, 0], lines)
    quaternions = values[:, 4:8]
    with np.errstate(over="ignore", invalid="ignore"):  # a huge component gives an infinite norm, refused below
        norms = np.linalg.norm(quaternions, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_NORM_TOLERANCE)
    if bad.size:
        i = bad[0]
        problem = "zero quaternion" if norms[i] == 0 else f"non-unit quaternion (norm {norms[i]:.3g})"
        raise InputError(path, problem, int(lines[i]))
    poses = pose_from_quaternion(values[:, 1:4], quaternions / norms[:, None])
    return Trajectory(values[:, 0].copy(), poses)


def read_kitti(
    path: str | Path, times_path: str | Path | None = None, frame_period: float = KITTI_FRAME_PERIOD
) -> Trajectory:
    """Robot poses from a KITTI pose file (camera poses, 12 floats a line).

    Timestamps come from `times_path` (KITTI `times.txt`) or, without one, are `index * frame_period`.
    """
    if not frame_period > 0:
        raise ValueError(f"frame_period must be positive, got {frame_period}")
    path = Path(path)
    values, lines = _read_numbers(path, _KITTI_COLUMNS)
    _check_magnitude(path, values[:, [3, 7, 11]], lines, MAX_POSITION_M, "position")
    camera_poses = np.tile(np.eye(4), (len(values), 1, 1))
    camera_poses[:, :3, :] = values.reshape(-1, 3, 4)
    rotations = camera_poses[:, :3, :3]
    with np.errstate(over="ignore", invalid="ignore"):  # a huge entry gives an infinite error, refused below
        errors = np.abs(rotations @ np.swapaxes(rotations, 1, 2) - np.eye(3)).max(axis=(1, 2))
        determinants = np.linalg.det(rotations)
    bad = np.flatnonzero((errors > ROTATION_TOLERANCE) | (determinants <= 0))
    if bad.size:
        i = bad[0]
        if errors[i] > ROTATION_TOLERANCE:
            problem = f"rotation is not orthonormal (|RR^T - I| = {errors[i]:.3g})"
        else:
            problem = f"rotation is a reflection (det = {determinants[i]:.3g})"
        raise InputError(path, problem, int(lines[i]))
    if times_path is None:
        timestamps = np.arange(len(values)) * frame_period
    else:
        timestamps = read_times(times_path)
        if len(timestamps) != len(values):
            problem = f"{len(timestamps)} timestamps for the {len(values)} poses of {path.name}"
            raise InputError(times_path, problem)
    return Trajectory(timestamps, camera_poses_to_robot(camera_poses))


def read_trajectory(
    path: str | Path, fmt: str, times_path: str | Path | None = None, frame_period: float = KITTI_FRAME_PERIOD
) -> Trajectory:
    """Read a trajectory as "tum", "kitti" or "auto" (8 columns: TUM, 12: KITTI, from the first data line)."""
    path = Path(path)
    if fmt not in ("tum", "kitti", "auto"):
        raise InputError(path, f"unknown trajectory format {fmt!r} (expected 'tum', 'kitti' or 'auto')")
    if fmt == "auto":
        number, tokens = next(_data_lines(read_text(path), path))
        formats = {_TUM_COLUMNS: "tum", _KITTI_COLUMNS: "kitti"}
        if len(tokens) not in formats:
            problem = f"cannot tell the format: {len(tokens)} columns found (8 for TUM, 12 for KITTI)"
            raise InputError(path, problem, number)
        fmt = formats[len(tokens)]
    if fmt == "kitti":
        return read_kitti(path, times_path, frame_period)
    if times_path is not None:
        # TUM lines carry their own timestamps; silently ignoring a times file would hide a mix-up.
        raise InputError(times_path, f"a times file is only used with KITTI poses, and {path.name} is TUM")
    return read_tum(path)


def _write_lines(path: str | Path, lines: list[str]) -> None:
    try:
        Path(path).write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"{path}: cannot be written ({exc.strerror})") from None


def write_tum(path: str | Path, trajectory: Trajectory) -> None:
    """TUM file `t x y z qx qy qz qw` of the robot poses; quaternions with w >= 0."""
    quaternions = quaternion_from_pose(trajectory.poses)
    rows = np.hstack([trajectory.positions, quaternions])
    lines = [
        f"{t:.6f} " + " ".join(f"{v:.9f}" for v in row) for t, row in zip(trajectory.timestamps, rows, strict=True)
    ]
    _write_lines(path, lines)


def write_kitti(path: str | Path, trajectory: Trajectory) -> None:
    """KITTI pose file (camera poses, 12 numbers a line); the timestamps are not written (see write_times)."""
    rows = robot_poses_to_camera(trajectory.poses)[:, :3, :].reshape(-1, 12)
    _write_lines(path, [" ".join(f"{v:.9e}" for v in row) for row in rows])


def write_times(path: str | Path, timestamps: np.ndarray) -> None:
    """KITTI-style times file, one timestamp in seconds per line."""
    # 9 decimals: exact for KITTI's 7-digit times and keeps sub-microsecond digits of Unix times.
    _write_lines(path, [f"{t:.9f}" for t in np.asarray(timestamps, dtype=float)])
