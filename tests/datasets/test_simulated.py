"""The simulated dataset folder: write, read back, read without truth/, and one precise error per bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from neoslam.config import SimulatorConfig
from neoslam.datasets.simulated import (
    FORMAT,
    VERSION,
    is_simulated_dataset,
    read_dataset,
    simulated_observations,
    write_dataset,
)
from neoslam.errors import InputError
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import SimulatedRecording, simulate

FRAMES = 200


@pytest.fixture(scope="module")
def recording() -> SimulatedRecording:
    config = SimulatorConfig()
    truth = drive_route(ROUTES["block"], config.frame_period, config.camera.height_above_ground)
    return simulate(truth.subset(np.arange(FRAMES)), config, name="cut", source="route:block[:200]")


@pytest.fixture(scope="module")
def written(recording: SimulatedRecording, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("written") / "dataset"
    write_dataset(folder, recording)
    return folder


@pytest.fixture
def dataset(written: Path, tmp_path: Path) -> Path:
    """A fresh copy of the written dataset that a test may break."""
    return Path(shutil.copytree(written, tmp_path / "dataset"))


def _edit_line(path: Path, line: int, old: str, new: str) -> None:
    """Replace the first `old` by `new` in the 1-based `line` of a text file."""
    lines = path.read_text().splitlines(keepends=True)
    assert old in lines[line - 1], (old, lines[line - 1])
    lines[line - 1] = lines[line - 1].replace(old, new, 1)
    path.write_text("".join(lines))


def _set_field(path: Path, line: int, column: int, value: str) -> None:
    lines = path.read_text().splitlines(keepends=True)
    fields = lines[line - 1].rstrip("\n").split(",")
    fields[column] = value
    lines[line - 1] = ",".join(fields) + "\n"
    path.write_text("".join(lines))


def _error(folder: Path) -> InputError:
    with pytest.raises(InputError) as caught:
        read_dataset(folder)
    return caught.value


def test_layout(written: Path) -> None:
    files = sorted(str(p.relative_to(written)) for p in written.rglob("*") if p.is_file())
    assert files == [
        "dataset.yaml",
        "detections.csv",
        "frames.csv",
        "patches.npy",
        "truth/detections.csv",
        "truth/objects.csv",
        "truth/poses_tum.txt",
    ]
    assert is_simulated_dataset(written)
    assert not is_simulated_dataset(written / "truth")


def test_read_back(written: Path, recording: SimulatedRecording) -> None:
    dataset = read_dataset(written)
    assert len(dataset) == FRAMES and dataset.name == "cut"
    assert dataset.camera == recording.config.camera
    np.testing.assert_allclose(dataset.timestamps, recording.truth.timestamps, atol=1e-6)
    np.testing.assert_allclose(dataset.linear_velocity, recording.linear_velocity, atol=1e-8)
    np.testing.assert_allclose(dataset.angular_velocity, recording.angular_velocity, atol=1e-8)
    assert [len(o) for o in dataset.observations] == [len(d) for d in recording.detections]
    for observations, detections in zip(dataset.observations, recording.detections, strict=True):
        for observation, detection in zip(observations, detections, strict=True):
            assert observation.label == detection.label
            assert observation.score == pytest.approx(detection.score, abs=5e-5)
            np.testing.assert_allclose(observation.center_camera, detection.center_camera, atol=5e-5)
            np.testing.assert_allclose(observation.box_left, detection.box_left, atol=5e-3)
            np.testing.assert_allclose(observation.box_right, detection.box_right, atol=5e-3)
            np.testing.assert_array_equal(observation.patch, detection.patch)
    assert dataset.ground_truth is not None
    np.testing.assert_allclose(dataset.ground_truth.poses, recording.truth.poses, atol=1e-6)


def test_detections_in_memory_become_the_observations_the_reader_gives(written: Path, recording) -> None:
    """A simulation run frame by frame (a robot in closed loop) gives its SLAM the observations a dataset folder
    would: the same values, rounded as written, the same classes left out."""
    classes = ("car", "person")
    read = read_dataset(written, classes=classes)
    for observations, detections in zip(read.observations, recording.detections, strict=True):
        in_memory = simulated_observations(detections, classes)
        assert len(in_memory) == len(observations)
        for mine, theirs in zip(in_memory, observations, strict=True):
            assert mine.label == theirs.label and mine.score == theirs.score
            for field in ("box_left", "box_right", "center_camera", "patch"):
                np.testing.assert_array_equal(getattr(mine, field), getattr(theirs, field))
    assert sum(map(len, recording.detections)) > sum(map(len, read.observations)) > 0


def test_frames_are_what_the_slam_path_sees(written: Path) -> None:
    dataset = read_dataset(written)
    frames = list(dataset.frames())
    assert [f.index for f in frames] == list(range(FRAMES))
    np.testing.assert_array_equal(frames[0].odometry_pose, np.eye(4))  # odometry starts at identity
    np.testing.assert_allclose(np.stack([f.odometry_pose for f in frames]), dataset.odometry().poses)
    assert all(isinstance(f.observations, tuple) for f in frames)


def test_without_truth_the_frames_are_identical(dataset: Path, written: Path) -> None:
    shutil.rmtree(dataset / "truth")
    without = read_dataset(dataset)
    assert without.ground_truth is None
    with_truth = read_dataset(written)
    for a, b in zip(without.frames(), with_truth.frames(), strict=True):
        assert (a.index, a.timestamp) == (b.index, b.timestamp)
        np.testing.assert_array_equal(a.odometry_pose, b.odometry_pose)
        np.testing.assert_array_equal(a.linear_velocity, b.linear_velocity)
        np.testing.assert_array_equal(a.angular_velocity, b.angular_velocity)
        assert len(a.observations) == len(b.observations)
        for o, p in zip(a.observations, b.observations, strict=True):
            assert (o.label, o.score) == (p.label, p.score)
            for field in ("box_left", "box_right", "center_camera", "patch"):
                np.testing.assert_array_equal(getattr(o, field), getattr(p, field))


def test_the_slam_inputs_hold_no_object_identities(written: Path) -> None:
    header = (written / "detections.csv").read_text().splitlines()[0]
    assert "object" not in header and "id" not in header.split(",")
    assert "object_id" in (written / "truth" / "detections.csv").read_text().splitlines()[0]


def test_missing_folder(tmp_path: Path) -> None:
    error = _error(tmp_path / "absent")
    assert error.path == tmp_path / "absent"


def test_missing_dataset_yaml(dataset: Path) -> None:
    (dataset / "dataset.yaml").unlink()
    assert _error(dataset).path == dataset / "dataset.yaml"


@pytest.mark.parametrize(
    ("old", "new", "problem"),
    [
        (f"format: {FORMAT}", "format: something-else", "format"),
        (f"version: {VERSION}", f"version: {VERSION + 1}", "version"),
        ("fx: 707.0912", "fx: -1.0", "camera"),
    ],
)
def test_wrong_format_version_or_camera(dataset: Path, old: str, new: str, problem: str) -> None:
    path = dataset / "dataset.yaml"
    path.write_text(path.read_text().replace(old, new, 1))
    error = _error(dataset)
    assert error.path == path
    assert problem in error.problem


def test_dataset_yaml_that_is_not_yaml(dataset: Path) -> None:
    (dataset / "dataset.yaml").write_text("format: [\n")
    assert _error(dataset).path == dataset / "dataset.yaml"


def test_dataset_yaml_without_name(dataset: Path) -> None:
    path = dataset / "dataset.yaml"
    path.write_text("".join(line for line in path.read_text().splitlines(True) if not line.startswith("name:")))
    assert read_dataset(dataset).name == dataset.name  # the folder names the dataset


def test_frame_count_differs_from_dataset_yaml(dataset: Path) -> None:
    path = dataset / "dataset.yaml"
    path.write_text(path.read_text().replace(f"frames: {FRAMES}", f"frames: {FRAMES + 1}", 1))
    error = _error(dataset)
    assert error.path == dataset / "frames.csv"
    assert str(FRAMES + 1) in error.problem


@pytest.mark.parametrize(
    ("line", "column", "value", "problem"),
    [
        (5, 2, "fast", "not a number"),
        (7, 6, "nan", "not finite"),
        (9, 1, "", "not a number"),
        (12, 1, "0.2", "does not increase"),  # timestamps going back
        (12, 0, "3", "out of order"),
    ],
)
def test_bad_frames_csv(dataset: Path, line: int, column: int, value: str, problem: str) -> None:
    path = dataset / "frames.csv"
    _set_field(path, line, column, value)
    error = _error(dataset)
    assert (error.path, error.line) == (path, line)
    assert problem in error.problem
    assert f"{path}:{line}:" in str(error)


def test_frames_csv_wrong_column_count(dataset: Path) -> None:
    path = dataset / "frames.csv"
    _edit_line(path, 4, "\n", ",0.0\n")
    error = _error(dataset)
    assert (error.path, error.line) == (path, 4)
    assert "9 columns" in error.problem


def test_frames_csv_wrong_header(dataset: Path) -> None:
    path = dataset / "frames.csv"
    _edit_line(path, 1, "vx", "speed")
    error = _error(dataset)
    assert (error.path, error.line) == (path, 1)


def test_frames_csv_missing(dataset: Path) -> None:
    (dataset / "frames.csv").unlink()
    assert _error(dataset).path == dataset / "frames.csv"


def test_frames_csv_that_is_not_text(dataset: Path) -> None:
    (dataset / "frames.csv").write_bytes(b"\xff\xfe\x00garbage\n")
    assert _error(dataset).path == dataset / "frames.csv"


@pytest.mark.parametrize(
    ("value", "problem"), [(str(FRAMES), "not one of"), ("-1", "not one of"), ("1.5", "not one of")]
)
def test_detection_of_a_frame_that_does_not_exist(dataset: Path, value: str, problem: str) -> None:
    path = dataset / "detections.csv"
    _set_field(path, 3, 0, value)
    error = _error(dataset)
    assert (error.path, error.line) == (path, 3)
    assert problem in error.problem


def test_detection_behind_the_camera(dataset: Path) -> None:
    path = dataset / "detections.csv"
    _set_field(path, 6, 13, "-4.0")  # z
    error = _error(dataset)
    assert (error.path, error.line) == (path, 6)


def test_detection_with_a_nan(dataset: Path) -> None:
    path = dataset / "detections.csv"
    _set_field(path, 8, 2, "nan")  # score
    error = _error(dataset)
    assert (error.path, error.line) == (path, 8)


@pytest.mark.parametrize("change", [-1, 1])
def test_patches_of_the_wrong_count(dataset: Path, change: int) -> None:
    path = dataset / "patches.npy"
    patches = np.load(path)
    patches = patches[:-1] if change < 0 else np.concatenate([patches, patches[:1]])
    np.save(path, patches)
    error = _error(dataset)
    assert error.path == path
    assert str(len(patches) - change) in error.problem


def test_patches_of_the_wrong_type(dataset: Path) -> None:
    path = dataset / "patches.npy"
    np.save(path, np.load(path).astype(np.float32))
    assert _error(dataset).path == path


def test_patches_not_an_array(dataset: Path) -> None:
    path = dataset / "patches.npy"
    path.write_bytes(b"hello")
    assert _error(dataset).path == path


def test_truth_of_the_wrong_length(dataset: Path) -> None:
    path = dataset / "truth" / "poses_tum.txt"
    path.write_text("".join(path.read_text().splitlines(True)[:-1]))
    assert _error(dataset).path == path


def _with_name(dataset: Path, name: str) -> Path:
    """dataset.yaml with its `name:` line replaced by `name: <name>` (YAML text, written last)."""
    path = dataset / "dataset.yaml"
    lines = [line for line in path.read_text().splitlines(True) if not line.startswith("name:")]
    path.write_text("".join(lines) + f"name: {name}\n")
    return path


def test_dataset_name_that_is_a_number(dataset: Path) -> None:
    _with_name(dataset, "5")
    assert read_dataset(dataset).name == "5"


@pytest.mark.parametrize(
    "name",
    [
        "{a: 1}",
        "x" * 300,
        # An alias chain: 2 KB of YAML that expands to gigabytes once written into metrics.json.
        "&a [lol, lol, lol]\nb: &b [*a, *a, *a]\nc: [*b, *b, *b]",
    ],
)
def test_dataset_name_that_is_no_name(dataset: Path, name: str) -> None:
    path = _with_name(dataset, name)
    error = _error(dataset)
    assert error.path == path
    assert "name must be a string" in error.problem
