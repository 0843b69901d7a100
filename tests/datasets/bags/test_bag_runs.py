"""`neoslam run BAG` end to end: a ROS 1 bag and ROS 2 bags (sqlite3, mcap; Image and CompressedImage) written from
the first 20 real frames of kitti_06_51 give the trajectory, objects, closures and pose graph of the run on the same
frames in the KITTI layout (same pixels, same calibration); the odometry topic moves the robot as `--odometry` does;
`neoslam detect` reads bags too; and a bag that cannot be used is one line and exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from neoslam.io.trajectory_files import read_trajectory, write_tum

pytestmark = pytest.mark.slow  # every test here runs whole drives, real images or real bags

FRAMES = 30  # the first keyframes of the street come at frames 22 and 27
EPOCH_S = 1_317_384_000  # tests/datasets/bags/conftest.py: the bags' stamps are KITTI's times from this second on
SAME_BYTES = ("objects.csv", "loop_closures.csv", "experience_map.g2o", "trajectory_kitti.txt", "odometry_kitti.txt")


def _model_env(shared_data: Path) -> dict[str, str]:
    return {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(shared_data / "models/yolox_nano_coco/yolox_nano.onnx")}


@pytest.fixture(scope="module")
def runs(cli, street, stereo_bag, kitti_subset, shared_data: Path, tmp_path_factory: pytest.TempPathFactory):
    """The KITTI subset and the three bags of it, each run with the built-in detector and stereo odometry."""
    root = tmp_path_factory.mktemp("bag_runs")
    env = _model_env(shared_data)
    inputs = {
        "kitti": kitti_subset(root / "kitti", street, FRAMES),
        "ros1": stereo_bag(root / "drive.bag", street, FRAMES, "ros1"),
        "sqlite3": stereo_bag(root / "drive_sqlite3", street, FRAMES, "sqlite3", right_compressed=True),
        "mcap": stereo_bag(root / "drive_mcap", street, FRAMES, "mcap"),
    }
    outs = {name: root / f"out_{name}" for name in inputs}
    cli.ok("run", inputs["kitti"], "--sequence", "06", "--out", outs["kitti"], "-q", env=env)
    for name in ("ros1", "sqlite3", "mcap"):
        cli.ok("run", inputs[name], "--out", outs[name], "-q", env=env)
    return inputs, outs


def _assert_same_trajectory(kitti_file: Path, bag_file: Path) -> None:
    kitti, bag = (read_trajectory(path, "tum") for path in (kitti_file, bag_file))
    np.testing.assert_allclose(bag.poses, kitti.poses, rtol=0, atol=1e-9)
    np.testing.assert_allclose(bag.timestamps - EPOCH_S, kitti.timestamps, rtol=0, atol=2e-6)


@pytest.mark.parametrize("bag", ["ros1", "sqlite3", "mcap"])
def test_a_bag_runs_as_its_kitti_folder(runs, bag: str) -> None:
    _, outs = runs
    for name in ("trajectory_tum.txt", "odometry_tum.txt"):
        _assert_same_trajectory(outs["kitti"] / name, outs[bag] / name)
    for name in SAME_BYTES:
        assert (outs[bag] / name).read_bytes() == (outs["kitti"] / name).read_bytes(), name
    kitti, got = (json.loads((outs[name] / "metrics.json").read_text()) for name in ("kitti", bag))
    assert got["dataset"] == f"bag-{'drive' if bag == 'ros1' else f'drive_{bag}'}" and got["frames"] == FRAMES
    for key in ("keyframes", "objects", "experience_map"):
        assert got[key] == kitti[key], key
    assert kitti["objects"] > 0 and kitti["keyframes"] > 0  # there is something to compare
    assert "ate_rmse_m" not in got  # a bag carries no ground truth


def test_detect_reads_a_bag_as_its_kitti_folder(cli, runs, shared_data: Path, tmp_path: Path) -> None:
    inputs, _ = runs
    env = _model_env(shared_data)
    cli.ok("detect", inputs["kitti"], "--sequence", "06", "--out", tmp_path / "kitti.jsonl", "-q", env=env)
    result = cli.ok("detect", inputs["ros1"], "--out", tmp_path / "bag.jsonl", "-q", env=env)
    assert f"in {FRAMES} frames" in result.stdout
    assert (tmp_path / "bag.jsonl").read_text() == (tmp_path / "kitti.jsonl").read_text()


def test_the_odometry_topic_moves_the_robot_as_a_pose_file_does(
    cli, runs, street, stereo_bag, shared_data: Path, tmp_path: Path
) -> None:
    """The ground truth as a TUM file (--odometry) and, read back from it, as the bag's nav_msgs/Odometry topic."""
    inputs, _ = runs
    truth_file = tmp_path / "truth_tum.txt"
    write_tum(truth_file, street.ground_truth.subset(np.arange(FRAMES)))
    poses = read_trajectory(truth_file, "tum").poses  # as the file gives them, to the last bit
    bag = stereo_bag(tmp_path / "odom", street, FRAMES, "mcap", odometry=poses)
    bag_file = bag / "odom.mcap"  # a bare .mcap file is a bag too
    env = _model_env(shared_data)
    cli.ok("detect", inputs["kitti"], "--sequence", "06", "--out", tmp_path / "dets.jsonl", "-q", env=env)
    common = ("--detections", tmp_path / "dets.jsonl", "-q")
    cli.ok("run", inputs["kitti"], "--sequence", "06", "--odometry", truth_file, "--out", tmp_path / "k", *common)
    cli.ok("run", bag_file, "--odometry-topic", "/odom", "--out", tmp_path / "b", *common)
    _assert_same_trajectory(tmp_path / "k" / "odometry_tum.txt", tmp_path / "b" / "odometry_tum.txt")
    _assert_same_trajectory(tmp_path / "k" / "trajectory_tum.txt", tmp_path / "b" / "trajectory_tum.txt")
    assert (tmp_path / "b" / "objects.csv").read_text() == (tmp_path / "k" / "objects.csv").read_text()
    # perception.odometry.source: poses finds the bag's only odometry topic by itself
    env = {"NEOSLAM_PERCEPTION__ODOMETRY__SOURCE": "poses"}
    cli.ok("run", bag_file, "--out", tmp_path / "auto", *common, env=env)
    auto = (tmp_path / "auto" / "odometry_tum.txt").read_text()
    assert auto == (tmp_path / "b" / "odometry_tum.txt").read_text()


# --- what cannot be used: one line, exit code 2, no results folder ---


def _assert_one_line_error(result, expected: list[str]) -> None:
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    for text in expected:
        assert text in lines[0], lines[0]


def _tiny_bag(
    bag_writer,
    path: Path,
    encoding: str = "mono8",
    right_offset_ns: int = 0,
    fx: float = 50.0,
    odometry_x: list[float] | None = None,
) -> Path:
    """Three frames of 64x48 px with their CameraInfo (fx 50 px, baseline 0.5 m), and an /odom topic with the
    robot at `odometry_x` (m along x) if given."""
    pixels = np.zeros((48, 64), dtype=np.uint16 if encoding == "mono16" else np.uint8)
    projections = [np.array([[fx, 0, 32, offset * fx], [0, fx, 24, 0], [0, 0, 1, 0]]) for offset in (0.0, -0.5)]
    with bag_writer(path, "ros1") as bag:
        for index in range(3):
            if odometry_x is not None:
                pose = np.eye(4)
                pose[0, 3] = odometry_x[index]
                stamp = (1_600_000_000 + index) * 10**9
                bag.add("/odom", "nav_msgs/msg/Odometry", bag.odometry(stamp, pose), stamp)
            for side, projection, offset in zip(("left", "right"), projections, (0, right_offset_ns), strict=True):
                stamp = (1_600_000_000 + index) * 10**9 + offset
                bag.add(f"/{side}/image_raw", "sensor_msgs/msg/Image", bag.image(stamp, pixels, encoding), stamp)
                info = bag.camera_info(stamp, projection, 64, 48)
                bag.add(f"/{side}/camera_info", "sensor_msgs/msg/CameraInfo", info, stamp)
    return path


def _broken(kind: str, folder: Path, street, stereo_bag, bag_writer) -> Path:
    if kind == "mono16":
        return _tiny_bag(bag_writer, folder / "deep.bag", "mono16")
    if kind == "unpaired":
        return _tiny_bag(bag_writer, folder / "apart.bag", right_offset_ns=40_000_000)
    if kind == "absurd-calibration":
        return _tiny_bag(bag_writer, folder / "huge.bag", fx=1e300)
    if kind == "odometry-jump":
        return _tiny_bag(bag_writer, folder / "jump.bag", odometry_x=[0.0, 1.0, 500.0])  # 499 m in 1 s
    if kind == "corrupt":
        whole = stereo_bag(folder / "whole.bag", street, 2, "ros1")
        cut = folder / "corrupt.bag"
        cut.write_bytes(whole.read_bytes()[:5000])
        return cut
    if kind == "no-calibration":
        return stereo_bag(folder / "nocal", street, 2, "sqlite3", right_info=False)
    raise ValueError(kind)


@pytest.mark.parametrize(
    ("kind", "args", "expected"),
    [
        ("corrupt", [], ["corrupt.bag", "cannot be read as a ROS bag"]),
        ("mono16", [], ["deep.bag", "message 0 of /left/image_raw", "unsupported image encoding 'mono16'"]),
        ("unpaired", [], ["apart.bag", "no stereo pairs", "within 5 ms"]),
        ("no-calibration", [], ["nocal", "no CameraInfo topic beside /stereo/right/image_rect"]),
        ("no-calibration", ["--left-topic", "/nowhere"], ["--left-topic /nowhere", "/stereo/left/image_rect (Image)"]),
        ("corrupt", ["--sequence", "06"], ["--sequence applies to KITTI roots"]),
        ("absurd-calibration", [], ["huge.bag", "camera.fx"]),
        ("odometry-jump", ["--odometry-topic", "/odom"], ["jump.bag", "odometry topic /odom, frame 2", "max_speed"]),
    ],
)
def test_a_bag_that_cannot_be_used_is_one_line(
    cli, kind, args, expected, street, stereo_bag, bag_writer, tmp_path: Path
) -> None:
    bag = _broken(kind, tmp_path, street, stereo_bag, bag_writer)
    result = cli.invoke("run", bag, *args, "--out", tmp_path / "out", "-q")
    _assert_one_line_error(result, expected)
    assert not (tmp_path / "out").exists()


def test_topic_options_need_a_bag(cli, runs, tmp_path: Path) -> None:
    inputs, _ = runs
    result = cli.invoke("run", inputs["kitti"], "--sequence", "06", "--left-topic", "/a", "--out", tmp_path / "o")
    _assert_one_line_error(result, ["--left-topic, --right-topic and --odometry-topic apply to ROS bags only"])
