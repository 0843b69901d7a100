"""A folder of a stereo camera's own images with a calibration file: pairing, frame times and errors on folders
written here; and the real frames of kitti_06_51 copied into such a folder, with their calibration written in every
format NeoSLAM reads, run to the same bytes as the KITTI run of the same frames."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.kitti import KittiSequence, read_calibration, read_kitti_sequence
from neoslam.datasets.stereo_folder import is_stereo_folder, read_stereo_folder
from neoslam.errors import InputError

WIDTH, HEIGHT, FX, BASELINE = 64, 48, 50.0, 0.5
PERCEPTION = NeoSLAMConfig().perception


def _calibration(frame_rate: float | None = None, size: tuple[int, int] = (WIDTH, HEIGHT)) -> str:
    rate = f"frame_rate: {frame_rate}\n" if frame_rate is not None else ""
    return (
        f"image_size: [{size[0]}, {size[1]}]\nrectified: true\nbaseline: {BASELINE}\n{rate}"
        f"left:\n  fx: {FX}\n  fy: {FX}\n  cx: {WIDTH / 2}\n  cy: {HEIGHT / 2}\n"
    )


def make_folder(root: Path, names: list[str], calibration: str | None = None, times: str | None = None) -> Path:
    """left/ and right/ images of the given names (random grey pixels), a calibration.yaml, a times.txt."""
    rng = np.random.default_rng(5)
    for side in ("left", "right"):
        (root / side).mkdir(parents=True)
        for name in names:
            cv2.imwrite(str(root / side / name), rng.integers(0, 256, (HEIGHT, WIDTH), dtype=np.uint8))
    (root / "calibration.yaml").write_text(calibration if calibration is not None else _calibration(10.0))
    if times is not None:
        (root / "times.txt").write_text(times)
    return root


def test_pairs_images_by_name_in_numeric_order(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "rig", ["10.png", "9.png", "100.png"])
    assert is_stereo_folder(folder) and not is_stereo_folder(tmp_path)
    sequence = read_stereo_folder(folder, PERCEPTION)
    assert sequence.name == "stereo-rig" and len(sequence) == 3
    assert [p.name for p in sequence.left_images] == ["9.png", "10.png", "100.png"]
    assert [p.name for p in sequence.right_images] == ["9.png", "10.png", "100.png"]
    np.testing.assert_allclose(sequence.timestamps, [0.0, 0.1, 0.2])  # frame numbers: the calibration's 10 Hz
    assert sequence.rectifier.identity and sequence.camera.baseline == BASELINE and sequence.camera.fx == FX
    left, right = sequence.stereo_pair(1)
    np.testing.assert_array_equal(left, cv2.imread(str(folder / "left" / "10.png"), cv2.IMREAD_GRAYSCALE))
    np.testing.assert_array_equal(right, cv2.imread(str(folder / "right" / "10.png"), cv2.IMREAD_GRAYSCALE))


def test_names_that_are_not_numbers_sort_alphabetically(tmp_path: Path) -> None:
    sequence = read_stereo_folder(make_folder(tmp_path / "rig", ["b.jpg", "a.png", "c.JPEG"]), PERCEPTION)
    assert [p.name for p in sequence.left_images] == ["a.png", "b.jpg", "c.JPEG"]


@pytest.mark.parametrize(
    ("names", "times", "rate", "expected"),
    [
        (["000000.png", "000001.png"], "0.0\n0.1037\n", None, [0.0, 0.1037]),  # times.txt first
        (["000000.png", "000001.png"], "0.0\n0.1037\n", 20.0, [0.0, 0.1037]),
        (["1403715273262142976.png", "1403715273312143104.png"], None, 20.0, [1403715273.262143, 1403715273.312143]),
        (["12.5.png", "12.55.png", "13.png"], None, None, [12.5, 12.55, 13.0]),  # seconds
        (["000000.png", "000001.png", "000002.png"], None, 20.0, [0.0, 0.05, 0.1]),  # frame numbers: the rate
        (["left_a.png", "left_b.png"], None, 4.0, [0.0, 0.25]),
    ],
)
def test_frame_times(tmp_path: Path, names: list[str], times, rate, expected: list[float]) -> None:
    folder = make_folder(tmp_path / "rig", names, _calibration(rate), times)
    np.testing.assert_allclose(read_stereo_folder(folder, PERCEPTION).timestamps, expected, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    ("names", "times", "rate", "where", "problem"),
    [
        (["000000.png", "000001.png"], None, None, ".", "frame times unknown: add times.txt"),
        (["a.png", "b.png"], None, None, ".", "give the frame rate in calibration.yaml"),
        (["1.5.png", "1.50.png"], None, None, "left/1.50.png", "the same time as 1.5.png"),
        (["0.png", "1.png"], "0.0\n", None, "times.txt", "1 times for the 2 image pairs"),
        (["0.png", "1.png"], "0.5\n0.1\n", None, "times.txt", "goes back"),
    ],
)
def test_unknown_or_bad_frame_times(tmp_path: Path, names, times, rate, where: str, problem: str) -> None:
    folder = make_folder(tmp_path / "rig", names, _calibration(rate), times)
    with pytest.raises(InputError, match=problem) as caught:
        read_stereo_folder(folder, PERCEPTION)
    assert caught.value.path == (folder / where if where != "." else folder)


def test_an_image_without_its_partner_is_refused(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "rig", ["0.png", "1.png", "2.png"])
    (folder / "right" / "1.png").rename(folder / "right" / "1.jpg")
    with pytest.raises(InputError, match=r"no right image of the same name \(1 left images have none\)") as caught:
        read_stereo_folder(folder, PERCEPTION)
    assert caught.value.path == folder / "left" / "1.png"
    (folder / "left" / "1.png").unlink()
    with pytest.raises(InputError, match="no left image of the same name") as caught:
        read_stereo_folder(folder, PERCEPTION)
    assert caught.value.path == folder / "right" / "1.jpg"


def test_no_images(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "rig", [])
    (folder / "left" / "notes.txt").write_text("not an image")
    with pytest.raises(InputError, match=r"no images \(.png, .jpg, .jpeg\)"):
        read_stereo_folder(folder, PERCEPTION)


def test_the_calibration_file_is_found_or_given(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "rig", ["0.png", "1.png"])
    elsewhere = tmp_path / "rig.yaml"
    (folder / "calibration.yaml").rename(elsewhere)
    with pytest.raises(InputError, match="calibration file not found") as caught:
        read_stereo_folder(folder, PERCEPTION)
    assert caught.value.path == folder / "calibration.yaml"
    assert read_stereo_folder(folder, PERCEPTION, elsewhere).camera.fx == FX


def test_images_of_another_size_than_the_calibration(tmp_path: Path) -> None:
    folder = make_folder(tmp_path / "rig", ["0.png", "1.png"], _calibration(10.0, (WIDTH * 2, HEIGHT)))
    with pytest.raises(InputError, match=r"image_size: 128x48, but the images are 64x48") as caught:
        read_stereo_folder(folder, PERCEPTION)
    assert caught.value.path == folder / "calibration.yaml"
    folder = make_folder(tmp_path / "rig2", ["0.png", "1.png"])
    cv2.imwrite(str(folder / "right" / "1.png"), np.zeros((HEIGHT, WIDTH + 1), np.uint8))
    sequence = read_stereo_folder(folder, PERCEPTION)
    with pytest.raises(InputError, match="image is 65x48, the calibration's is 64x48") as caught:
        sequence.stereo_pair(1)
    assert caught.value.path == folder / "right" / "1.png"


@pytest.mark.slow  # the CLI's first start
def test_the_cli_refuses_a_bad_calibration_in_one_line(cli, tmp_path: Path) -> None:
    folder = make_folder(
        tmp_path / "rig", ["0.png", "1.png"], _calibration(10.0).replace("baseline: 0.5", "baseline: -0.5")
    )
    result = cli.invoke("run", folder, "--out", tmp_path / "out", "-q")
    cli.one_line_error(result, str(folder / "calibration.yaml"), "baseline: must be positive")
    assert not (tmp_path / "out").exists()
    result = cli.invoke("detect", folder, "--out", tmp_path / "d.jsonl", "-q", "--calibration", tmp_path / "none.yaml")
    cli.one_line_error(result, str(tmp_path / "none.yaml"), "calibration file not found")
    other = tmp_path / "not-a-folder"
    other.mkdir()
    result = cli.invoke("run", other, "--calibration", folder / "calibration.yaml", "--out", tmp_path / "o2", "-q")
    cli.one_line_error(result, "--calibration applies to a folder of left/ and right/ images only")
    result = cli.invoke("run", folder, "--sequence", "06", "--out", tmp_path / "o3", "-q")
    cli.one_line_error(result, "--sequence applies to KITTI roots")


# --- the real frames of KITTI 06 as a folder with a calibration, in every format ---

FRAMES = 30  # the first keyframes of the street come at frames 22 and 27
SAME_BYTES = (
    "objects.csv",
    "loop_closures.csv",
    "experience_map.g2o",
    "trajectory_kitti.txt",
    "odometry_kitti.txt",
    "trajectory_tum.txt",
    "odometry_tum.txt",
)


def _kitti_calibrations(sequence: KittiSequence) -> dict[str, str]:
    """KITTI 04-12's calibration, as exactly as calib.txt gives it, in each format."""
    left_projection, right_projection = read_calibration(sequence.root / "sequences" / sequence.sequence / "calib.txt")
    camera = sequence.camera
    fx, fy, cx, cy, b = (repr(float(v)) for v in (camera.fx, camera.fy, camera.cx, camera.cy, camera.baseline))
    width, height = camera.width, camera.height
    intrinsics = f"  fx: {fx}\n  fy: {fy}\n  cx: {cx}\n  cy: {cy}\n"

    def matrix(values: np.ndarray) -> str:
        data = ", ".join(repr(float(v)) for v in np.ravel(values))
        return f"!!opencv-matrix\n  rows: {values.shape[0]}\n  cols: {values.shape[1]}\n  dt: d\n  data: [{data}]"

    K = left_projection[:, :3]
    pinhole = "".join(
        f"Camera{i}.{k}: {v}\n" for i in (1, 2) for k, v in zip(("fx", "fy", "cx", "cy"), (fx, fy, cx, cy), strict=True)
    )
    zeros = "".join(f"Camera{i}.{k}: 0.0\n" for i in (1, 2) for k in ("k1", "k2", "p1", "p2"))
    shifted = np.eye(4)
    shifted[0, 3] = camera.baseline
    left_right = "".join(
        f"{side}.height: {height}\n{side}.width: {width}\n{side}.D: {matrix(np.zeros((1, 5)))}\n{side}.K: {matrix(K)}\n"
        f"{side}.R: {matrix(np.eye(3))}\n{side}.P: {matrix(projection)}\n"
        for side, projection in (("LEFT", left_projection), ("RIGHT", right_projection))
    )
    bf = repr(float(-(right_projection[0, 3] - left_projection[0, 3])))
    return {
        "neoslam": f"image_size: [{width}, {height}]\nrectified: true\nleft:\n{intrinsics}baseline: {b}\n",
        "neoslam-raw": f"image_size: [{width}, {height}]\nrectified: false\nleft:\n{intrinsics}right:\n{intrinsics}"
        f"right_camera_pose:\n  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  translation: [{b}, 0, 0]\n",
        "opencv": f"%YAML:1.0\n---\nM1: {matrix(K)}\nD1: {matrix(np.zeros((1, 5)))}\nM2: {matrix(K)}\n"
        f"D2: {matrix(np.zeros((1, 5)))}\nR: {matrix(np.eye(3))}\nT: {matrix(-shifted[:3, 3:])}\n"
        f"image_width: {width}\nimage_height: {height}\n",
        "orbslam3": f'%YAML:1.0\nFile.version: "1.0"\nCamera.type: "Rectified"\n{pinhole.split("Camera2")[0]}'
        f"Camera.width: {width}\nCamera.height: {height}\nCamera.fps: 10\nStereo.b: {b}\nStereo.ThDepth: 40.0\n",
        "orbslam3-pinhole": f'%YAML:1.0\nFile.version: "1.0"\nCamera.type: "PinHole"\n{pinhole}{zeros}'
        f"Camera.width: {width}\nCamera.height: {height}\nStereo.T_c1_c2: {matrix(shifted)}\n",
        "orbslam2": f"%YAML:1.0\nCamera.fx: {fx}\nCamera.fy: {fy}\nCamera.cx: {cx}\nCamera.cy: {cy}\nCamera.k1: 0.0\n"
        f"Camera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\nCamera.fps: 10.0\nCamera.bf: {bf}\nThDepth: 35\n",
        "orbslam2-left-right": f"%YAML:1.0\nCamera.fx: {fx}\nCamera.fy: {fy}\nCamera.cx: {cx}\nCamera.cy: {cy}\n"
        f"Camera.bf: {bf}\n{left_right}",
    }


def _image_folder(root: Path, sequence: KittiSequence, frames: int, calibration: str) -> Path:
    """The first frames of a KITTI sequence copied into left/ and right/, its times.txt, a calibration.yaml."""
    for side, images in (("left", sequence.left_images), ("right", sequence.right_images)):
        (root / side).mkdir(parents=True)
        for path in images[:frames]:
            shutil.copyfile(path, root / side / path.name)
    source = sequence.root / "sequences" / sequence.sequence / "times.txt"
    (root / "times.txt").write_text("".join(source.read_text().splitlines(True)[:frames]))
    (root / "calibration.yaml").write_text(calibration)
    return root


@pytest.fixture(scope="module")
def street(shared_data: Path) -> KittiSequence:
    return read_kitti_sequence(shared_data / "kitti_06_51", "06")


@pytest.fixture(scope="module")
def kitti_run(cli, street: KittiSequence, shared_data: Path, tmp_path_factory: pytest.TempPathFactory):
    """The KITTI layout of the first frames, its detections (neoslam detect) and its run with them."""
    root = tmp_path_factory.mktemp("kitti_folder")
    kitti = root / "kitti"
    folder = kitti / "sequences" / "06"
    for camera, images in (("image_0", street.left_images), ("image_1", street.right_images)):
        (folder / camera).mkdir(parents=True)
        for path in images[:FRAMES]:
            shutil.copyfile(path, folder / camera / path.name)
    shutil.copyfile(street.root / "sequences/06/calib.txt", folder / "calib.txt")
    (folder / "times.txt").write_text(
        "".join((street.root / "sequences/06/times.txt").read_text().splitlines(True)[:FRAMES])
    )
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(shared_data / "models/yolox_nano_coco/yolox_nano.onnx")}
    detections = root / "detections.jsonl"
    cli.ok("detect", kitti, "--sequence", "06", "--out", detections, "-q", env=env)
    cli.ok("run", kitti, "--sequence", "06", "--detections", detections, "--out", root / "out", "-q")
    return kitti, detections, root / "out", env


@pytest.mark.slow
@pytest.mark.parametrize(
    "form", ["neoslam", "neoslam-raw", "opencv", "orbslam3", "orbslam3-pinhole", "orbslam2", "orbslam2-left-right"]
)
def test_a_folder_of_kitti_frames_runs_as_the_kitti_sequence(cli, street, kitti_run, tmp_path: Path, form: str) -> None:
    _, detections, kitti_out, _ = kitti_run
    folder = _image_folder(tmp_path / "street", street, FRAMES, _kitti_calibrations(street)[form])
    cli.ok("run", folder, "--detections", detections, "--out", tmp_path / "out", "-q")
    for name in SAME_BYTES:
        assert (tmp_path / "out" / name).read_bytes() == (kitti_out / name).read_bytes(), name
    kitti, ours = (json.loads((out / "metrics.json").read_text()) for out in (kitti_out, tmp_path / "out"))
    assert ours["dataset"] == "stereo-street" and ours["frames"] == FRAMES
    for key in ("keyframes", "objects", "experience_map"):
        assert ours[key] == kitti[key], key
    assert kitti["objects"] > 0 and kitti["keyframes"] > 0  # there is something to compare


@pytest.mark.slow
def test_a_folder_of_kitti_frames_detects_and_runs_with_the_detector_as_kitti(
    cli, street, kitti_run, tmp_path: Path
) -> None:
    """The built-in detector sees the same left images (`neoslam detect`, and a whole run) from the folder, its
    calibration given with --calibration from elsewhere."""
    kitti, detections, _, env = kitti_run
    folder = _image_folder(tmp_path / "street", street, FRAMES, "")
    (folder / "calibration.yaml").unlink()
    calibration = tmp_path / "rig.yaml"
    calibration.write_text(_kitti_calibrations(street)["opencv"])
    cli.ok("detect", folder, "--calibration", calibration, "--out", tmp_path / "folder.jsonl", "-q", env=env)
    assert (tmp_path / "folder.jsonl").read_bytes() == detections.read_bytes()
    cli.ok("run", kitti, "--sequence", "06", "--out", tmp_path / "kitti_out", "-q", env=env)
    cli.ok("run", folder, "--calibration", calibration, "--out", tmp_path / "folder_out", "-q", env=env)
    for name in SAME_BYTES:
        assert (tmp_path / "folder_out" / name).read_bytes() == (tmp_path / "kitti_out" / name).read_bytes(), name
