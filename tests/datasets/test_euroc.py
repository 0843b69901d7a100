"""The EuRoC / ASL reader: recordings written here (small images, cameras of known calibration, a ground truth of
known motion), and the real raw frames of EuRoC V1_01_easy (euroc_v101_micro), whose rectified rows line up."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.euroc import is_euroc, read_euroc
from neoslam.errors import InputError
from neoslam.geometry import ROBOT_FROM_CAMERA, invert_pose, make_pose

WIDTH, HEIGHT, FRAMES = 64, 48, 6
START_NS = 1_403_715_273_262_142_976  # V1_01_easy's first image
PERIOD_NS = 50_000_000  # 20 Hz
BASELINE = 0.11
# a camera looking along the body's x axis (REP-103 body: x forward), 10 cm ahead of the body's origin
CAM0_IN_BODY = make_pose(ROBOT_FROM_CAMERA, np.array([0.1, 0.0, 0.0]))
CAM1_IN_BODY = CAM0_IN_BODY @ make_pose(np.eye(3), np.array([BASELINE, 0.0, 0.0]))
PERCEPTION = NeoSLAMConfig().perception
ORB_FEATURES, MAX_HAMMING, MAX_DISPARITY = 1500, 40, 120  # the stereo matches the vertical disparity is measured on


def _sensor_yaml(pose: np.ndarray, changes: dict[str, str]) -> str:
    """A camera's sensor.yaml: fx = fy = 40 px at the image centre, no distortion, `changes` replacing fields."""
    fields = {
        "sensor_type": "camera",
        "T_BS": "\n  cols: 4\n  rows: 4\n  data: [" + ", ".join(repr(float(v)) for v in pose.ravel()) + "]",
        "rate_hz": "20",
        "resolution": f"[{WIDTH}, {HEIGHT}]",
        "camera_model": "pinhole",
        "intrinsics": "[40.0, 40.0, 32.0, 24.0] #fu, fv, cu, cv",
        "distortion_model": "radial-tangential",
        "distortion_coefficients": "[0.0, 0.0, 0.0, 0.0]",
    }
    fields.update(changes)
    return "%YAML:1.0\n# General sensor definitions.\n" + "".join(
        f"{k}: {v}\n" for k, v in fields.items() if v != "DROP"
    )


def make_euroc(
    root: Path,
    frames: int = FRAMES,
    cam1_offsets_ns: dict[int, int] | None = None,
    extra_cam1: int = 0,
    sensor: dict[str, str] | None = None,
) -> Path:
    """A recording of `frames` stereo pairs at 20 Hz of rectified cameras (fx 40 px, baseline 0.11 m); cam1's
    frame i is `cam1_offsets_ns[i]` late, and `extra_cam1` more cam1 rows follow (listed, without images)."""
    mav0 = root / "mav0"
    rng = np.random.default_rng(3)
    for camera, pose in (("cam0", CAM0_IN_BODY), ("cam1", CAM1_IN_BODY)):
        (mav0 / camera / "data").mkdir(parents=True)
        changes = sensor if camera == "cam1" and sensor else {}
        text = _sensor_yaml(pose, changes)
        (mav0 / camera / "sensor.yaml").write_text(text)
        rows = ["#timestamp [ns],filename"]
        count = frames + (extra_cam1 if camera == "cam1" else 0)
        for index in range(count):
            offset = (cam1_offsets_ns or {}).get(index, 0) if camera == "cam1" else 0
            stamp = START_NS + index * PERIOD_NS + offset
            rows.append(f"{stamp},{stamp}.png")
            if index < frames:
                image = rng.integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8)
                cv2.imwrite(str(mav0 / camera / "data" / f"{stamp}.png"), image)
        (mav0 / camera / "data.csv").write_text("\r\n".join(rows) + "\r\n")  # EuRoC's files end lines so
    return root


def write_ground_truth(root: Path, body_poses, start_ns: int, end_ns: int, period_ns: int = 5_000_000) -> None:
    """EuRoC's state_groundtruth_estimate0/data.csv: `body_poses(t_s)` sampled at 200 Hz."""
    folder = root / "mav0" / "state_groundtruth_estimate0"
    folder.mkdir(parents=True)
    lines = ["#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], ..."]
    for stamp in range(start_ns, end_ns + 1, period_ns):
        pose = body_poses((stamp - START_NS) / 1e9)
        x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
        values = [*pose[:3, 3], w, x, y, z] + [0.0] * 9  # velocities and biases, unread
        lines.append(f"{stamp}," + ",".join(f"{v:.12f}" for v in values))
    (folder / "data.csv").write_text("\n".join(lines) + "\n")


def _flying(t: float) -> np.ndarray:
    """The body 1 m/s along the world's x axis while turning left at 0.2 rad/s."""
    return make_pose(Rotation.from_euler("z", 0.2 * t).as_matrix(), np.array([t, 0.5 * t, 2.0]))


def test_reads_a_recording(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "V1_01_easy")
    for given in (root, root / "mav0"):
        assert is_euroc(given)
        sequence = read_euroc(given, PERCEPTION)
        assert sequence.name == "euroc-V1_01_easy" and len(sequence) == FRAMES
        assert sequence.rectifier.identity  # aligned cameras without distortion: no warp
        assert sequence.camera.baseline == pytest.approx(BASELINE, rel=1e-12) and sequence.camera.fx == 40.0
        np.testing.assert_allclose(sequence.timestamps - sequence.timestamps[0], np.arange(FRAMES) * 0.05, atol=1e-6)
        assert sequence.timestamps[0] == pytest.approx(START_NS / 1e9)
        assert sequence.ground_truth is None
    left, right = sequence.stereo_pair(2)
    stamp = START_NS + 2 * PERIOD_NS
    np.testing.assert_array_equal(left, cv2.imread(str(root / f"mav0/cam0/data/{stamp}.png"), cv2.IMREAD_GRAYSCALE))
    np.testing.assert_array_equal(right, cv2.imread(str(root / f"mav0/cam1/data/{stamp}.png"), cv2.IMREAD_GRAYSCALE))
    np.testing.assert_array_equal(sequence.left_image(2), left)
    assert not is_euroc(tmp_path) and not is_euroc(root / "mav0" / "cam0")


def test_pairs_by_stamp_and_leaves_out_images_outside_the_other_cameras_recording(tmp_path: Path) -> None:
    """cam1 a microsecond late pairs; cam1 rows after cam0's last image are left out (euroc_v101_micro has four)."""
    root = make_euroc(tmp_path / "rec", cam1_offsets_ns={1: 1000, 3: 250_000}, extra_cam1=4)
    sequence = read_euroc(root, PERCEPTION)
    assert len(sequence) == FRAMES
    assert sequence.right_images[1].name == f"{START_NS + PERIOD_NS + 1000}.png"
    np.testing.assert_allclose(sequence.timestamps - START_NS / 1e9, np.arange(FRAMES) * 0.05, atol=1e-6)


def test_an_unpaired_image_inside_the_recording_is_refused_unless_skipped(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "rec", cam1_offsets_ns={2: 20_000_000})  # 20 ms late: no partner
    with pytest.raises(InputError, match="no cam1 image within 1 ms") as caught:
        read_euroc(root, PERCEPTION)
    assert caught.value.path == root / "mav0" / "cam0" / "data.csv" and caught.value.line == 4
    skipping = PERCEPTION.model_copy(update={"euroc": PERCEPTION.euroc.model_copy(update={"skip_unpaired": True})})
    assert len(read_euroc(root, skipping)) == FRAMES - 1


def test_ground_truth_becomes_robot_poses_at_the_image_stamps(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "rec")
    end = START_NS + (FRAMES - 1) * PERIOD_NS
    write_ground_truth(root, _flying, START_NS - 2_500_000, end + 7_500_000)  # samples 2.5 ms off the images
    sequence = read_euroc(root, PERCEPTION)
    truth = sequence.ground_truth
    assert truth is not None and len(truth) == FRAMES
    np.testing.assert_array_equal(truth.timestamps, sequence.timestamps)
    # the robot frame (REP-103 axes at the left camera) is the body frame moved 0.1 m forward
    robot_in_body = make_pose(np.eye(3), np.array([0.1, 0.0, 0.0]))
    times = (sequence.timestamps * 1e9 - START_NS).round() / 1e9
    world = np.array([_flying(t) @ robot_in_body for t in times])
    expected = invert_pose(world[0]) @ world
    np.testing.assert_allclose(truth.poses, expected, atol=1e-6)
    assert truth.poses[-1][0, 3] > 0.2  # it flew forward


def test_ground_truth_is_of_the_rectified_left_camera(tmp_path: Path) -> None:
    """With the right camera turned and off the left's x axis, the rectified left camera is turned from the raw
    one so that the baseline lies along its x axis: a body flying from the left camera's centre towards the right
    camera's moves the robot to its right (-y in REP-103), and nowhere else."""
    right_in_left = make_pose(
        Rotation.from_euler("y", 0.5, degrees=True).as_matrix(), np.array([BASELINE, 0.002, -0.001])
    )
    right_in_body = CAM0_IN_BODY @ right_in_left
    data = ", ".join(repr(float(v)) for v in right_in_body.ravel())
    root = make_euroc(tmp_path / "rec", sensor={"T_BS": f"\n  cols: 4\n  rows: 4\n  data: [{data}]"})
    along = CAM0_IN_BODY[:3, :3] @ right_in_left[:3, 3] / np.linalg.norm(right_in_left[:3, 3])  # in the body frame

    def flying(t: float) -> np.ndarray:
        return make_pose(np.eye(3), 0.5 * t * along)  # 0.5 m/s towards the right camera

    write_ground_truth(root, flying, START_NS, START_NS + FRAMES * PERIOD_NS)
    sequence = read_euroc(root, PERCEPTION)
    assert not sequence.rectifier.identity
    times = sequence.timestamps - sequence.timestamps[0]
    np.testing.assert_allclose(sequence.ground_truth.positions, np.outer(times, [0.0, -0.5, 0.0]), atol=1e-6)
    np.testing.assert_allclose(sequence.ground_truth.poses[:, :3, :3], np.tile(np.eye(3), (FRAMES, 1, 1)), atol=1e-9)


def test_ground_truth_that_does_not_cover_every_frame_is_not_used(tmp_path: Path) -> None:
    end = START_NS + (FRAMES - 1) * PERIOD_NS
    late = make_euroc(tmp_path / "late")
    write_ground_truth(late, _flying, START_NS + PERIOD_NS, end)  # starts after the first image
    assert read_euroc(late, PERCEPTION).ground_truth is None
    gappy = make_euroc(tmp_path / "gappy")
    write_ground_truth(gappy, _flying, START_NS, end, period_ns=100_000_000)  # 10 Hz: frames 50 ms from a sample
    assert read_euroc(gappy, PERCEPTION).ground_truth is None


@pytest.mark.parametrize(
    ("change", "where", "problem"),
    [
        ({"intrinsics": "[40.0, 40.0, 32.0]"}, "cam1/sensor.yaml", "intrinsics: has 3 numbers, 4 expected"),
        ({"intrinsics": "[40.0, -40.0, 32.0, 24.0]"}, "cam1/sensor.yaml", "intrinsics: K has a non-positive focal"),
        ({"distortion_model": "omni"}, "cam1/sensor.yaml", "distortion_model: must be one of"),
        ({"distortion_coefficients": "[0.1, .nan, 0, 0]"}, "cam1/sensor.yaml", "distortion_coefficients: holds a"),
        ({"resolution": "[64]"}, "cam1/sensor.yaml", "resolution: has 1 numbers, 2 expected"),
        ({"resolution": "[64.5, 48]"}, "cam1/sensor.yaml", "resolution: must be two whole numbers"),
        ({"resolution": "[32, 24]"}, "cam1/sensor.yaml", "T_BS (with cam0's): the left image size"),
        ({"T_BS": "DROP"}, "cam1/sensor.yaml", "T_BS: missing"),
        ({"camera_model": "omni"}, "cam1/sensor.yaml", "camera_model: only pinhole cameras are read"),
        (
            {"T_BS": "\n  cols: 4\n  rows: 4\n  data: [1, 0, 0, -0.1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"},
            "cam1/sensor.yaml",
            "T_BS (with cam0's): ",
        ),
    ],
)
def test_a_bad_camera_calibration_is_one_line_naming_the_field(
    tmp_path: Path, change, where: str, problem: str
) -> None:
    root = make_euroc(tmp_path / "rec", sensor=change)
    with pytest.raises(InputError) as caught:
        read_euroc(root, PERCEPTION)
    assert caught.value.path == root / "mav0" / where
    assert problem in caught.value.problem and "\n" not in str(caught.value), caught.value


def test_bad_image_lists_and_files_name_the_file_and_line(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "rec")
    listing = root / "mav0" / "cam0" / "data.csv"
    original = listing.read_text()
    for text, problem, line in (
        (original.replace(f"{START_NS},", "12x4,", 1), "is not a timestamp in ns", 2),
        (original.replace(f"{START_NS}.png", "../../etc/passwd", 1), "is not an image file name", 2),
        ("#timestamp [ns],filename\n", "lists no images", None),
        (original + f"{START_NS},{START_NS}.png\n", "timestamps must increase", FRAMES + 2),
    ):
        listing.write_text(text)
        with pytest.raises(InputError, match=problem) as caught:
            read_euroc(root, PERCEPTION)
        assert caught.value.path == listing and caught.value.line == line
    listing.write_text(original)
    image = root / "mav0" / "cam1" / "data" / f"{START_NS + PERIOD_NS}.png"
    image.unlink()
    with pytest.raises(InputError, match="image listed in cam1/data.csv not found") as caught:
        read_euroc(root, PERCEPTION)
    assert caught.value.path == image
    cv2.imwrite(str(image), np.zeros((HEIGHT, WIDTH + 2), np.uint8))
    sequence = read_euroc(root, PERCEPTION)
    with pytest.raises(InputError, match="image is 66x48, the calibration's is 64x48"):
        sequence.stereo_pair(1)


def test_a_bad_ground_truth_names_its_line(tmp_path: Path) -> None:
    root = make_euroc(tmp_path / "rec")
    write_ground_truth(root, _flying, START_NS, START_NS + FRAMES * PERIOD_NS)
    path = root / "mav0" / "state_groundtruth_estimate0" / "data.csv"
    lines = path.read_text().splitlines()
    for line, problem in (("1,2,3", "3 columns, at least 8 expected"), (lines[1], "must be a whole number above")):
        path.write_text("\n".join([*lines[:3], line, *lines[3:]]) + "\n")
        with pytest.raises(InputError, match=problem) as caught:
            read_euroc(root, PERCEPTION)
        assert caught.value.path == path and caught.value.line == 4
    bad = lines[3].split(",")
    bad[4] = "2.0"  # q_w: not a unit quaternion
    path.write_text("\n".join([*lines[:3], ",".join(bad), *lines[4:]]) + "\n")
    with pytest.raises(InputError, match="quaternion is not of unit length"):
        read_euroc(root, PERCEPTION)


# --- the real raw frames of EuRoC V1_01_easy ---


def _vertical_disparity(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """|dy| of the cross-checked ORB matches between a left and a right image, px: matches of at most
    MAX_HAMMING bits whose disparity (x_left - x_right) is 0-MAX_DISPARITY px, as a stereo pair's are."""
    orb = cv2.ORB_create(ORB_FEATURES)
    keys_left, descriptors_left = orb.detectAndCompute(left, None)
    keys_right, descriptors_right = orb.detectAndCompute(right, None)
    matches = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(descriptors_left, descriptors_right)
    found = np.array(
        [(*keys_left[m.queryIdx].pt, *keys_right[m.trainIdx].pt) for m in matches if m.distance <= MAX_HAMMING]
    )
    disparity = found[:, 0] - found[:, 2]
    return np.abs(found[:, 1] - found[:, 3])[(disparity >= 0) & (disparity <= MAX_DISPARITY)]


@pytest.fixture(scope="module")
def micro(shared_data: Path) -> Path:
    return shared_data / "euroc_v101_micro"


@pytest.mark.slow  # real images, ORB on three pairs
def test_the_real_recording_is_read_and_rectified(micro: Path) -> None:
    sequence = read_euroc(micro, PERCEPTION)
    assert sequence.name == "euroc-euroc_v101_micro" and len(sequence) == 95  # cam1 lists 4 more, without images
    assert not sequence.rectifier.identity
    camera = sequence.camera
    assert (camera.width, camera.height) == (752, 480)
    assert camera.baseline == pytest.approx(0.110, abs=0.001)  # EuRoC's stereo baseline, 11 cm
    assert 420 < camera.fx < 460 and camera.fx == camera.fy
    np.testing.assert_allclose(np.diff(sequence.timestamps), 0.05, atol=1e-4)
    raw, rectified = [], []
    for index in (0, 47, 94):
        left, right = (
            cv2.imread(str(p[index]), cv2.IMREAD_GRAYSCALE) for p in (sequence.left_images, sequence.right_images)
        )
        raw.append(_vertical_disparity(left, right))
        rectified.append(_vertical_disparity(*sequence.stereo_pair(index)))
    raw_dy, rectified_dy = np.concatenate(raw), np.concatenate(rectified)
    assert len(rectified_dy) > 500 and len(raw_dy) > 500
    # measured: raw median 12 px, 0.5 % of matches within 1 px of a row; rectified median 0 px, 76 % within 1 px
    # (most of the rest are wrong matches on the repeated patterns of the room: the checkerboard, the mats)
    assert np.median(rectified_dy) < 1.0 and np.mean(rectified_dy <= 1.0) > 0.6  # the rows line up
    assert np.median(raw_dy) > 5.0 and np.mean(raw_dy <= 1.0) < 0.05  # they did not before


@pytest.mark.slow
def test_neoslam_runs_on_the_real_recording(cli, micro: Path, shared_data: Path, tmp_path: Path) -> None:
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(shared_data / "models/yolox_nano_coco/yolox_nano.onnx")}
    result = cli.ok("run", micro / "mav0", "--out", tmp_path / "out", "-q", env=env)
    assert "frames" in result.stdout
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["dataset"] == "euroc-euroc_v101_micro" and metrics["frames"] == 95
    assert "ate_rmse_m" not in metrics  # these frames come without ground truth
    odometry = (tmp_path / "out" / "odometry_tum.txt").read_text().splitlines()
    assert len(odometry) == 95 and odometry[0].startswith("1403715273.262143")
