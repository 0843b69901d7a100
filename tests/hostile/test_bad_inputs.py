"""Hostile input through the CLI: impossible motion, absurd values, broken binary and text files, configs
that validate but would crash, misleading messages, values accepted silently but wrong. Each case is one line
`neoslam: error: <file>[:<line>]: <problem>` on stderr and exit code 2 (or, where the input is fine, a clean run),
never a traceback, never a hang."""

from __future__ import annotations

import csv
import json
import os
import shutil
import tracemalloc
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from neoslam.datasets.kitti import read_grey_image
from neoslam.errors import InputError
from neoslam.inputs import count_lines, read_input_bytes
from neoslam.io.image_header import image_size, oversized
from neoslam.text import read_yaml

SMALL_FRAMES = 40  # a cut of the block route: enough to run end to end in a few seconds
BOM = b"\xef\xbb\xbf"
# KITTI 06's rectified projections (calib.txt), for a synthetic three-frame KITTI root.
P0 = "707.0912 0 601.8873 0 0 707.0912 183.1104 0 0 0 1 0"
P1 = "707.0912 0 601.8873 -379.8145 0 707.0912 183.1104 0 0 0 1 0"
KITTI_FRAMES = 3


def _ok(result) -> None:
    assert result.exit_code == 0, (result.output, result.exception)


# --- data made once per module ---


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as handle:
        return list(csv.reader(handle))


def _write_rows(path: Path, rows: list[list[str]]) -> None:
    with path.open("w", newline="") as handle:
        csv.writer(handle, lineterminator="\n").writerows(rows)


def _cut(source: Path, target: Path, frames: int) -> None:
    """The first `frames` frames of a simulated dataset folder, with their detections, patches and truth."""
    shutil.copytree(source, target)
    meta = yaml.safe_load((source / "dataset.yaml").read_text())
    meta["frames"] = frames
    (target / "dataset.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    _write_rows(target / "frames.csv", _rows(source / "frames.csv")[: frames + 1])
    detections = _rows(source / "detections.csv")
    keep = [k for k, row in enumerate(detections[1:]) if int(row[0]) < frames]
    _write_rows(target / "detections.csv", [detections[0]] + [detections[k + 1] for k in keep])
    np.save(target / "patches.npy", np.load(source / "patches.npy")[keep])
    truth = (source / "truth" / "poses_tum.txt").read_text().splitlines()[:frames]
    (target / "truth" / "poses_tum.txt").write_text("\n".join(truth) + "\n")
    _write_rows(target / "truth" / "detections.csv", _rows(source / "truth" / "detections.csv")[: len(keep) + 1])


@pytest.fixture(scope="module")
def small(cli, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`neoslam simulate --route block`, cut to SMALL_FRAMES frames."""
    root = tmp_path_factory.mktemp("hostile")
    _ok(cli.invoke("simulate", "--route", "block", "--out", root / "block", "-q"))
    _cut(root / "block", root / "small", SMALL_FRAMES)
    return root / "small"


@pytest.fixture
def dataset(small: Path, tmp_path: Path) -> Path:
    """A fresh copy of the small dataset to corrupt."""
    shutil.copytree(small, tmp_path / "data")
    return tmp_path / "data"


def _set_cell(path: Path, row: int, column: str, value: str) -> None:
    """Replace one cell of a CSV table; `row` counts data rows from 0 (file line row + 2)."""
    rows = _rows(path)
    rows[row + 1][rows[0].index(column)] = value
    _write_rows(path, rows)


def _kitti_pose_lines(steps: list[float]) -> str:
    """KITTI camera poses driving forward (camera z) by the given steps."""
    z = np.concatenate([[0.0], np.cumsum(steps)])
    return "".join(f"1 0 0 0 0 1 0 0 0 0 1 {v:.6f}\n" for v in z)


@pytest.fixture(scope="module")
def kitti_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A KITTI odometry root with sequence 06 of three synthetic frames (textured, so PNGs decode), its calib,
    times and ground truth."""
    root = tmp_path_factory.mktemp("kitti") / "root"
    folder = root / "sequences" / "06"
    rng = np.random.default_rng(0)
    for side in ("image_0", "image_1"):
        (folder / side).mkdir(parents=True)
        for i in range(KITTI_FRAMES):
            image = cv2.resize(rng.integers(0, 255, (37, 123), dtype=np.uint8), (1226, 370))
            cv2.imwrite(str(folder / side / f"{i:06d}.png"), image)
    (folder / "calib.txt").write_text(f"P0: {P0}\nP1: {P1}\n")
    (folder / "times.txt").write_text("".join(f"{0.1 * i:.6f}\n" for i in range(KITTI_FRAMES)))
    (root / "poses").mkdir()
    (root / "poses" / "06.txt").write_text(_kitti_pose_lines([1.0] * (KITTI_FRAMES - 1)))
    (root / "empty.jsonl").write_text("")
    return root


@pytest.fixture
def kitti(kitti_root: Path, tmp_path: Path) -> Path:
    """A fresh copy of the KITTI root to corrupt."""
    shutil.copytree(kitti_root, tmp_path / "kitti")
    return tmp_path / "kitti"


def kitti_odometry(root: Path) -> Path:
    """An odometry file of the sequence's length, apart from its ground truth."""
    (root / "odometry.txt").write_text(_kitti_pose_lines([1.0] * (KITTI_FRAMES - 1)))
    return root / "odometry.txt"


def _run_kitti(cli, root: Path, out: Path, detections: Path | None = None, odometry: Path | None = None):
    detections = detections or root / "empty.jsonl"
    odometry = odometry or root / "poses" / "06.txt"
    return cli.invoke(
        "run", root, "--sequence", "06", "--detections", detections, "--odometry", odometry, "--out", out, "-q"
    )


# --- item 6 and 7: impossible motion and absurd values are refused, per-frame work stays bounded ---


@pytest.mark.parametrize(
    ("column", "value", "expected"),
    [
        ("vx", "1e9", ["frames.csv:5", "speed 1e+09 m/s", "motion_limits.max_speed"]),
        ("vy", "1e300", ["frames.csv:5", "speed 1e+300 m/s", "motion_limits.max_speed"]),
        ("wz", "100", ["frames.csv:5", "rotation rate 100 rad/s", "motion_limits.max_turn_rate"]),
        ("wx", "-1e300", ["frames.csv:5", "rotation rate 1e+300", "motion_limits.max_turn_rate"]),
    ],
)
@pytest.mark.slow
def test_impossible_velocity_in_frames_csv_is_refused(cli, dataset: Path, column: str, value: str, expected: list[str]):
    _set_cell(dataset / "frames.csv", 3, column, value)
    cli.one_line_error(cli.invoke("run", dataset, "--out", dataset.parent / "o", "-q"), *expected)
    assert not (dataset.parent / "o").exists()


def test_a_timestamp_gap_of_1e7_s_is_refused(cli, dataset: Path):
    rows = _rows(dataset / "frames.csv")
    for row in rows[7:]:
        row[1] = f"{float(row[1]) + 1e7:.6f}"
    _write_rows(dataset / "frames.csv", rows)
    result = cli.invoke("run", dataset, "--out", dataset.parent / "o", "-q")
    cli.one_line_error(result, "frames.csv:8", "time step of 1e+07 s", "motion_limits.max_time_step")


def test_motion_limits_are_configurable(cli, dataset: Path, tmp_path: Path):
    (tmp_path / "slow.yaml").write_text("motion_limits:\n  max_speed: 1.0\n")
    result = cli.invoke("run", dataset, "--config", tmp_path / "slow.yaml", "--out", tmp_path / "o", "-q")
    cli.one_line_error(result, "frames.csv:", "motion_limits.max_speed (1 m/s)")


def test_the_largest_allowed_step_runs_quickly(cli, dataset: Path, tmp_path: Path):
    """With the limits at their largest (1000 m/s for a day), one frame jumps 8.6e7 m: ten million grid cells.
    The cells shift by that modulo the torus, so the run takes as long as any other (it hung before)."""
    limits = "motion_limits:\n  max_speed: 1000\n  max_time_step: 86400\n"
    (tmp_path / "loose.yaml").write_text(limits)
    rows = _rows(dataset / "frames.csv")
    rows[11][2] = "999"  # vx of frame 10
    for row in rows[11:]:
        row[1] = f"{float(row[1]) + 86399:.6f}"
    _write_rows(dataset / "frames.csv", rows)
    result = cli.invoke("run", dataset, "--config", tmp_path / "loose.yaml", "--out", tmp_path / "o", "-q")
    _ok(result)
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["timing"]["ms_per_frame_p95"] < 1000


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ("x 1e300", ["odometry.txt:3", "position of magnitude 1e+300 is beyond 1e+08"]),
        ("jump 50 m", ["odometry.txt:3", "50 m from the previous pose in 0.1 s", "motion_limits.max_speed"]),
        ("half turn", ["odometry.txt:3", "rotation rate 31.4159 rad/s", "motion_limits.max_turn_rate"]),
    ],
)
def test_impossible_motion_in_an_odometry_file_is_refused(cli, kitti: Path, change: str, expected: list[str]):
    lines = (kitti / "poses" / "06.txt").read_text().splitlines()
    values = lines[2].split()
    if change == "x 1e300":
        values[3] = "1e300"
    elif change == "jump 50 m":
        values[11] = "51"
    else:  # turned by pi about the camera's y axis (a yaw of the robot) within one frame
        values[0], values[10] = "-1", "-1"
    lines[2] = " ".join(values)
    (kitti / "odometry.txt").write_text("\n".join(lines) + "\n")
    result = _run_kitti(cli, kitti, kitti.parent / "o", odometry=kitti / "odometry.txt")
    cli.one_line_error(result, *expected)


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (["0 0 0 0 0 0 0 1", "0.1 1 0 0 0 0 0 1", "0.2 1e300 0 0 0 0 0 1"], ["traj.txt:3", "magnitude 1e+300"]),
        (["0 0 0 0 0 0 0 1", "0.1 1 0 0 0 0 0 1", "0.2 1e5 0 0 0 0 0 1"], ["traj.txt:3", "99999 m", "max_speed"]),
        (["0 0 0 0 0 0 0 1", "0.1 1 0 0 0 0 0 1", "1e7 2 0 0 0 0 0 1"], ["traj.txt:3", "1e+07 s", "max_time_step"]),
        (["0 0 0 0 0 0 0 1", "0.1 1 0 0 0 0 0 1", "0.2 2 0 0 0 0 1 0"], ["traj.txt:3", "rotation rate", "max_turn"]),
    ],
)
def test_impossible_motion_in_a_simulate_trajectory_is_refused(
    cli, tmp_path: Path, lines: list[str], expected: list[str]
):
    (tmp_path / "traj.txt").write_text("\n".join(lines) + "\n")
    result = cli.invoke("simulate", "--trajectory", tmp_path / "traj.txt", "--out", tmp_path / "o", "-q")
    cli.one_line_error(result, *expected)
    assert not (tmp_path / "o").exists()


# --- item 8: patches.npy that is not a .npy array of patches ---


def _npz_bytes(tmp_path: Path) -> bytes:
    np.savez(tmp_path / "archive.npz", patches=np.zeros((3, 16, 16), np.uint8))
    return (tmp_path / "archive.npz").read_bytes()


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        ("empty", ["patches.npy: empty file (0 bytes)"]),
        ("npz", ["patches.npy: is an .npz (zip) archive"]),
        ("text", ["patches.npy: not a .npy file"]),
        ("no side", ["patches.npy: expected (", "s >= 1", ", 0, 0)"]),
        ("truncated", ["patches.npy: truncated"]),
    ],
)
def test_broken_patches_file_is_one_line(cli, dataset: Path, tmp_path: Path, content: str, expected: list[str]):
    path = dataset / "patches.npy"
    count = len(np.load(path))
    if content == "empty":
        path.write_bytes(b"")
    elif content == "npz":
        path.write_bytes(_npz_bytes(tmp_path))
    elif content == "text":
        path.write_text("these are not patches\n")
    elif content == "no side":
        np.save(path, np.zeros((count, 0, 0), np.uint8))
    else:
        path.write_bytes(path.read_bytes()[:-100])
    line = cli.one_line_error(cli.invoke("run", dataset, "--out", tmp_path / "o", "-q"), *expected)
    assert "pickle" not in line


# --- item 9: text files that are not UTF-8 ---


def test_dataset_yaml_that_is_not_utf8_is_one_line(cli, dataset: Path, tmp_path: Path):
    path = dataset / "dataset.yaml"
    path.write_bytes(path.read_bytes().replace(b"name: block", b"name: bl\xffck"))
    result = cli.invoke("run", dataset, "--out", tmp_path / "o", "-q")
    cli.one_line_error(result, "dataset.yaml:3", "not UTF-8")


def test_config_file_that_is_not_utf8_is_one_line(cli, tmp_path: Path):
    (tmp_path / "latin1.yaml").write_bytes(b"matching:\n  min_inliers: 4  # r\xe9glage\n")
    cli.one_line_error(cli.invoke("dump-config", "--config", tmp_path / "latin1.yaml"), "latin1.yaml:2", "not UTF-8")


# --- item 10: evaluate ---


def _tum(path: Path, xs: list[float]) -> Path:
    path.write_text("".join(f"{0.1 * k:.1f} {x} {k % 3} 0 0 0 0 1\n" for k, x in enumerate(xs)))
    return path


@pytest.mark.parametrize("which", ["estimate", "truth"])
def test_evaluate_refuses_a_position_beyond_any_drive(cli, tmp_path: Path, which: str):
    """1e300 m squared overflows: such a file is refused by line, never given a metric of inf or null."""
    files = {name: _tum(tmp_path / f"{name}.txt", [float(k) for k in range(20)]) for name in ("estimate", "truth")}
    files[which] = _tum(tmp_path / f"{which}.txt", [1e300 * (k % 2) for k in range(20)])
    result = cli.invoke("evaluate", files["estimate"], files["truth"], "--json", tmp_path / "m.json")
    cli.one_line_error(result, f"{which}.txt:2", "position of magnitude 1e+300")
    assert not (tmp_path / "m.json").exists()


LOOP_HEADER = "query_frame,match_frame,query_keyframe,match_keyframe,score,matched_objects,tx,ty,tz,qx,qy,qz,qw\n"


@pytest.mark.parametrize(
    ("row", "expected"),
    [
        ("9000,3,8,1,10.0,5,0,0,0,0,0,0,1", ["loops.csv:2", "frame 9000 is beyond the 200 poses"]),
        ("150.5,3,8,1,10.0,5,0,0,0,0,0,0,1", ["loops.csv:2", "query_frame: 150.5 is not a non-negative integer"]),
        ("150,-3,8,1,10.0,5,0,0,0,0,0,0,1", ["loops.csv:2", "match_frame: -3 is not a non-negative integer"]),
        ("150,3,8,1,10.0,5,0,0,0,0,0,0,0", ["loops.csv:2", "zero quaternion"]),
    ],
)
def test_evaluate_loops_with_a_bad_row_is_one_line(cli, tmp_path: Path, row: str, expected: list[str]):
    truth = _tum(tmp_path / "truth.txt", [float(k) for k in range(200)])
    (tmp_path / "loops.csv").write_text(LOOP_HEADER + row + "\n")
    cli.one_line_error(cli.invoke("evaluate", truth, truth, "--loops", tmp_path / "loops.csv"), *expected)


def test_evaluate_sim3_against_a_stationary_truth_is_refused(cli, tmp_path: Path):
    truth = tmp_path / "still.txt"
    truth.write_text("".join(f"{0.1 * k:.1f} 5 5 5 0 0 0 1\n" for k in range(20)))
    estimate = _tum(tmp_path / "estimate.txt", [float(k) for k in range(20)])
    result = cli.invoke("evaluate", estimate, truth, "--align", "sim3")
    cli.one_line_error(result, "still.txt", "all at one place", "sim3")


# --- item 11: a detections line nested 100,000 deep ---


def test_deeply_nested_detections_line_is_one_line(cli, kitti: Path):
    nested = "[" * 100_000 + "]" * 100_000
    (kitti / "deep.jsonl").write_text('{"frame": 0, "detections": ' + nested + "}\n")
    result = _run_kitti(cli, kitti, kitti.parent / "o", detections=kitti / "deep.jsonl")
    cli.one_line_error(result, "deep.jsonl:1", "nested too deeply")


# --- item 12: config values that validate today but crash a run ---


@pytest.mark.parametrize(
    ("yaml_text", "field"),
    [
        ("grid_cells: {dims: [0, 36, 36]}", "grid_cells.dims.0"),
        ("grid_cells: {dims: [36, -1, 36]}", "grid_cells.dims.1"),
        ("grid_cells: {dims: [36, 36, 1]}", "grid_cells.dims.2"),
        ("head_direction: {cells: 1}", "head_direction.cells"),
        ("grid_cells: {excitation_size: 8}", "grid_cells.excitation_size"),
        ("head_direction: {inhibition_size: 1000000001}", "head_direction.inhibition_size"),
        ("grid_cells: {metres_per_cell: 1.0e-300}", "grid_cells.metres_per_cell"),
        ("grid_cells: {metres_per_cell: .inf}", "grid_cells.metres_per_cell"),
        ("keyframes: {spacing: .inf}", "keyframes.spacing"),
        ("object_vector: {hidden_units: 100000000}", "object_vector.hidden_units"),
        ("simulator: {seed: -1}", "simulator.seed"),
        ("simulator: {frame_period: 1.0e-12}", "simulator.frame_period"),
        ("experience_map: {correction_loops: 1000000000}", "experience_map.correction_loops"),
        ("matching: {search_radius: .inf}", "matching.search_radius"),
        ("experience_map: {similarity_threshold: .nan}", "experience_map.similarity_threshold"),
    ],
)
def test_config_values_out_of_range_name_the_field(cli, tmp_path: Path, yaml_text: str, field: str):
    (tmp_path / "c.yaml").write_text(yaml_text + "\n")
    cli.one_line_error(cli.invoke("dump-config", "--config", tmp_path / "c.yaml"), "c.yaml", f"{field}: ")


def test_inhibition_that_kills_the_attractor_is_one_line(cli, dataset: Path, tmp_path: Path):
    (tmp_path / "c.yaml").write_text("grid_cells: {global_inhibition: 0.5}\n")
    result = cli.invoke("run", dataset, "--config", tmp_path / "c.yaml", "--out", tmp_path / "o", "-q")
    cli.one_line_error(result, "grid_cells: the attractor activity vanished", "global_inhibition 0.5")
    assert not (tmp_path / "o").exists()


# --- item 13: messages that named the wrong thing or said too little ---


def test_invalid_camera_block_names_the_field(cli, dataset: Path, tmp_path: Path):
    path = dataset / "dataset.yaml"
    meta = yaml.safe_load(path.read_text())
    meta["camera"]["fx"] = -3
    path.write_text(yaml.safe_dump(meta, sort_keys=False))
    line = cli.one_line_error(cli.invoke("run", dataset, "--out", tmp_path / "o", "-q"), "dataset.yaml", "camera.fx")
    assert "greater than 0" in line and "validation error" not in line


def test_unknown_environment_section_names_the_whole_variable(cli):
    cli.one_line_error(cli.invoke("dump-config", env={"NEOSLAM_FOO__BAR": "1"}), "NEOSLAM_FOO__BAR")


def test_dataset_yaml_without_frames_blames_dataset_yaml(cli, dataset: Path, tmp_path: Path):
    path = dataset / "dataset.yaml"
    meta = yaml.safe_load(path.read_text())
    del meta["frames"]
    path.write_text(yaml.safe_dump(meta, sort_keys=False))
    line = cli.one_line_error(cli.invoke("run", dataset, "--out", tmp_path / "o", "-q"), "no 'frames' entry")
    assert line.startswith(f"neoslam: error: {dataset / 'dataset.yaml'}: ")


def test_ground_truth_one_pose_short_names_the_pose_file(cli, kitti: Path):
    path = kitti / "poses" / "06.txt"
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:-1]))
    result = _run_kitti(cli, kitti, kitti.parent / "o", odometry=kitti_odometry(kitti))
    cli.one_line_error(result, "poses/06.txt", f"{KITTI_FRAMES - 1} poses for the {KITTI_FRAMES} frames")


def test_detection_frame_beyond_the_sequence_names_its_line(cli, kitti: Path):
    lines = [json.dumps({"frame": i, "detections": []}) for i in (0, 1, 40)]
    (kitti / "far.jsonl").write_text("\n".join(lines) + "\n")
    result = _run_kitti(cli, kitti, kitti.parent / "o", detections=kitti / "far.jsonl")
    cli.one_line_error(result, "far.jsonl:3", "frame 40 is beyond the 3 frames")


@pytest.mark.parametrize(
    ("damage", "expected"),
    [("truncated", "truncated PNG (its closing IEND chunk is missing)"), ("corrupt", "not a readable image")],
)
def test_a_broken_png_is_one_line_without_libpng_output(
    cli, kitti: Path, capfd: pytest.CaptureFixture[str], damage: str, expected: str
):
    """libpng and OpenCV write their complaints to file descriptor 2 themselves (not through sys.stderr, which the
    runner captures): capfd sees what a user's terminal would."""
    image = kitti / "sequences" / "06" / "image_0" / "000001.png"
    data = bytearray(image.read_bytes())
    if damage == "truncated":
        data = data[:5000]
    else:
        data[len(data) // 2 : len(data) // 2 + 64] = bytes(64)  # a damaged IDAT chunk: its CRC fails
    image.write_bytes(bytes(data))
    capfd.readouterr()
    result = _run_kitti(cli, kitti, kitti.parent / "o")
    cli.one_line_error(result, f"{image}: {expected}")
    assert capfd.readouterr().err == ""


# --- item 14: accepted silently but wrong ---


@pytest.mark.parametrize(
    ("column", "value", "expected"),
    [
        ("score", "5", '"score" must be a number in [0, 1], got 5.0'),
        ("score", "-3", '"score" must be a number in [0, 1], got -3.0'),
        ("label", "", '"label" must be a non-empty string'),
        ("left_x2", "-1", '"left box" must have x1 < x2'),
        ("right_y1", "1e5", '"right box" must have x1 < x2 and y1 < y2'),
        ("z", "1e300", "beyond 10000 m"),
    ],
)
def test_detections_csv_refuses_what_the_json_reader_refuses(
    cli, dataset: Path, tmp_path: Path, column: str, value: str, expected: str
):
    _set_cell(dataset / "detections.csv", 2, column, value)
    cli.one_line_error(cli.invoke("run", dataset, "--out", tmp_path / "o", "-q"), "detections.csv:4", expected)


@pytest.mark.parametrize(
    ("detection", "expected"),
    [
        ({"label": "car", "score": 5, "box": [1, 2, 3, 4]}, '"score" must be a number in [0, 1], got 5'),
        ({"label": "", "score": 0.5, "box": [1, 2, 3, 4]}, '"label" must be a non-empty string'),
        ({"label": "car", "score": 0.5, "box": [3, 2, 1, 4]}, '"box" must have x1 < x2'),
    ],
)
def test_the_json_reader_refuses_the_same_values(cli, kitti: Path, detection: dict, expected: str):
    (kitti / "d.jsonl").write_text(json.dumps({"frame": 1, "detections": [detection]}) + "\n")
    cli.one_line_error(_run_kitti(cli, kitti, kitti.parent / "o", detections=kitti / "d.jsonl"), "d.jsonl:1", expected)


def test_two_p1_lines_in_calib_are_refused(cli, kitti: Path):
    path = kitti / "sequences" / "06" / "calib.txt"
    path.write_text(path.read_text() + f"P1: {P1.replace('-379.8145', '-400')}\n")
    cli.one_line_error(
        _run_kitti(cli, kitti, kitti.parent / "o"), "calib.txt:3", "a second P1 line (the first is line 2)"
    )


def _with_bom(path: Path) -> None:
    path.write_bytes(BOM + path.read_bytes())


def test_a_byte_order_mark_is_accepted_in_every_dataset_file(cli, dataset: Path, tmp_path: Path):
    for name in ("dataset.yaml", "frames.csv", "detections.csv", "truth/poses_tum.txt"):
        _with_bom(dataset / name)
    (tmp_path / "c.yaml").write_bytes(BOM + b"keyframes:\n  spacing: 5.0\n")
    _ok(cli.invoke("run", dataset, "--config", tmp_path / "c.yaml", "--out", tmp_path / "o", "-q"))


def test_a_byte_order_mark_is_accepted_in_every_kitti_file(cli, kitti: Path):
    folder = kitti / "sequences" / "06"
    for path in (folder / "calib.txt", folder / "times.txt", kitti / "poses" / "06.txt"):
        _with_bom(path)
    (kitti / "d.jsonl").write_bytes(BOM + json.dumps({"frame": 0, "detections": []}).encode() + b"\n")
    odometry = kitti_odometry(kitti)
    _with_bom(odometry)
    _ok(_run_kitti(cli, kitti, kitti.parent / "o", detections=kitti / "d.jsonl", odometry=odometry))


def test_a_trajectory_whose_file_name_is_not_utf8_makes_a_dataset_that_reads_back(cli, tmp_path: Path):
    """The dataset's name comes from the file name; its bytes that are not UTF-8 are written as \\xNN escapes, so
    dataset.yaml is text and `run` reads it."""
    trajectory = tmp_path / os.fsdecode(b"t\xff.txt")
    trajectory.write_text("".join(f"{0.1 * k:.1f} {1.0 * k} 0 0 0 0 0 1\n" for k in range(40)))
    cli.ok("simulate", "--trajectory", trajectory, "--out", tmp_path / "o", "-q")
    meta = read_yaml(tmp_path / "o" / "dataset.yaml")
    assert meta["name"] == "t\\xff" and meta["source"].endswith("t\\xff.txt")
    cli.ok("run", tmp_path / "o", "--out", tmp_path / "r", "-q")


def test_a_yaml_key_given_twice_is_refused_by_name(cli, dataset: Path, tmp_path: Path):
    config = tmp_path / "twice.yaml"
    config.write_text("keyframes:\n  spacing: 5.0\n  spacing: 7.5\n")
    result = cli.invoke("run", dataset, "--config", config, "--out", tmp_path / "r")
    cli.one_line_error(result, "twice.yaml:3", "duplicate key 'spacing' (first on line 2)")


def _png_claiming(width: int, height: int) -> bytes:
    """A PNG whose header claims width x height pixels (8-bit grey) with no image data to speak of."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return len(body).to_bytes(4, "big") + kind + body + zlib.crc32(kind + body).to_bytes(4, "big")

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([8, 0, 0, 0, 0])
    data = chunk(b"IDAT", zlib.compress(b"\0" * 64))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + data + chunk(b"IEND", b"")


def test_an_image_claiming_a_billion_pixels_is_refused_from_its_header(tmp_path: Path):
    path = tmp_path / "000000.png"
    path.write_bytes(_png_claiming(32000, 32000))
    with pytest.raises(InputError, match=r"32000x32000 pixels in its header, more than the 128 megapixels"):
        read_grey_image(path)


def test_the_size_of_a_jpeg_is_read_from_its_frame_header():
    ok, encoded = cv2.imencode(".jpg", np.zeros((48, 64), np.uint8))
    data = bytearray(encoded.tobytes())
    assert ok and image_size(bytes(data)) == (64, 48)
    frame = data.index(b"\xff\xc0")
    data[frame + 5 : frame + 9] = (40000).to_bytes(2, "big") + (50000).to_bytes(2, "big")
    assert image_size(bytes(data)) == (50000, 40000) and "50000x40000" in oversized(bytes(data))


def test_a_simulation_whose_patches_exceed_the_memory_budget_is_refused_before_it_starts(cli, tmp_path: Path):
    """256-pixel patches and 100 false positives a frame, both in range: 10 GiB of patches on the block route,
    refused from the configuration alone; NEOSLAM_MAX_MEMORY sets the budget, and a value that is no amount is one
    line."""
    env = {
        "NEOSLAM_SIMULATOR__DETECTION__PATCH_SIZE": "256",
        "NEOSLAM_SIMULATOR__DETECTION__FALSE_POSITIVES_PER_FRAME": "100",
        "NEOSLAM_MAX_MEMORY": "2G",
    }
    result = cli.invoke("simulate", "--route", "block", "--out", tmp_path / "o", env=env)
    cli.one_line_error(
        result, "816 frames x 100 false positives a frame x 256x256 patches", "2.0 GiB", "NEOSLAM_MAX_MEMORY"
    )
    assert not (tmp_path / "o").exists()
    result = cli.invoke(
        "simulate", "--route", "block", "--out", tmp_path / "o", env={**env, "NEOSLAM_MAX_MEMORY": "lots"}
    )
    cli.one_line_error(result, "NEOSLAM_MAX_MEMORY: 'lots' is not an amount of memory")


def test_trajectories_whose_evaluation_exceeds_the_memory_budget_are_refused_before_they_are_read(cli, tmp_path: Path):
    """`evaluate` counts the lines of both files a block at a time and refuses, before it reads them, a pair whose
    evaluation would exceed the budget (BYTES_PER_LINE, measured by benchmarks/evaluation.py); the JSON it was to
    write is not made. Within the budget the same pair is evaluated."""
    lines = "".join(f"{0.1 * k:.1f} {k} 0 0 0 0 0 1\n" for k in range(2000))
    estimate, truth = tmp_path / "estimate.txt", tmp_path / "truth.txt"
    estimate.write_text(lines)
    truth.write_text(lines)
    out = tmp_path / "metrics.json"
    result = cli.invoke("evaluate", estimate, truth, "--json", out, env={"NEOSLAM_MAX_MEMORY": "1M"})
    cli.one_line_error(result, "evaluate: estimate.txt and truth.txt (4,000 lines)", "1.0 MiB", "NEOSLAM_MAX_MEMORY")
    assert not out.exists()
    assert cli.invoke("evaluate", estimate, truth, env={"NEOSLAM_MAX_MEMORY": "1G"}).exit_code == 0


def test_lines_are_counted_without_reading_the_file_whole_and_a_read_is_sized_by_the_file(tmp_path: Path):
    path = tmp_path / "t.txt"
    for text, lines in (("", 0), ("a", 1), ("a\n", 1), ("a\nb", 2), ("a\n" * 3_000_000, 3_000_000)):
        path.write_text(text)
        assert count_lines(path) == lines
    with pytest.raises(InputError, match="holds at most 100"):
        count_lines(path, limit=100)
    path.write_text("x")
    tracemalloc.start()
    try:
        assert read_input_bytes(path) == b"x"  # not a buffer of the 256 MiB a text file may have
        assert tracemalloc.get_traced_memory()[1] < 2**20
    finally:
        tracemalloc.stop()


def test_a_detections_video_needs_camera_images(cli, dataset: Path, tmp_path: Path) -> None:
    """The default scenario and a simulated dataset hold detections, no images: one line each, nothing written."""
    result = cli.invoke("run", "--out", tmp_path / "a", "--detections-video", "-q")
    cli.one_line_error(result, "--detections-video draws camera images", "not the default scenario")
    result = cli.invoke("run", dataset, "--out", tmp_path / "b", "--detections-video", "-q")
    cli.one_line_error(result, "--detections-video draws camera images", "holds simulated detections, no images")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
