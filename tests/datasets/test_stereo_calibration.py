"""Stereo calibration files: NeoSLAM's own format, OpenCV's stereo calibration and ORB-SLAM3's settings (both
styles), each written here by the test, read into the same cameras and rectification; every bad calibration is one
line naming the file and the field."""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from neoslam.datasets.stereo_calibration import read_stereo_calibration
from neoslam.errors import InputError, NeoSLAMError
from neoslam.geometry import invert_pose, make_pose

SIZE = (752, 480)
# EuRoC's cam0 and cam1 (sensor.yaml of V1_01_easy), as a real raw calibration to write in every format
LEFT = {"fx": 458.654, "fy": 457.296, "cx": 367.215, "cy": 248.375}
RIGHT = {"fx": 457.587, "fy": 456.134, "cx": 379.999, "cy": 255.238}
D_LEFT = [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
D_RIGHT = [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
# the right camera in the left camera's frame (inv(T_BS_cam0) @ T_BS_cam1 of EuRoC)
RIGHT_POSE = np.array(
    [
        [0.999997256, -0.002317136, -0.000343393, 0.110074138],
        [0.002312067, 0.999898049, -0.014090668, -0.000156612],
        [0.000376008, 0.014089836, 0.999900663, 0.000889383],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
RECTIFIED = {"fx": 707.0912, "fy": 707.0912, "cx": 601.8873, "cy": 183.1104}
KITTI_BASELINE = 379.8145 / 707.0912
KITTI_SIZE = (1226, 370)


def _orthonormal(pose: np.ndarray) -> np.ndarray:
    """The pose with its rotation made orthonormal to float precision (the file's 9 digits are not)."""
    u, _, vt = np.linalg.svd(pose[:3, :3])
    return make_pose(u @ vt, pose[:3, 3])


POSE = _orthonormal(RIGHT_POSE)


def _number(value: float) -> str:
    """YAML's spelling: repr's digits (read back to the last bit), .nan and .inf for the others."""
    value = float(value)
    if np.isnan(value):
        return ".nan"
    return repr(value) if np.isfinite(value) else ("-" if value < 0 else "") + ".inf"


def _numbers(values) -> str:
    return "[" + ", ".join(_number(v) for v in np.ravel(values)) + "]"


def _matrix(values: np.ndarray) -> str:
    rows, cols = values.shape
    return f"!!opencv-matrix\n  rows: {rows}\n  cols: {cols}\n  dt: d\n  data: {_numbers(values)}\n"


def _k(camera: dict[str, float]) -> np.ndarray:
    return np.array([[camera["fx"], 0, camera["cx"]], [0, camera["fy"], camera["cy"]], [0, 0, 1.0]])


def neoslam_raw(**changes: str) -> str:
    fields = {
        "image_size": "[752, 480]",
        "rectified": "false",
        "frame_rate": "20",
        "left": "\n".join(f"  {k}: {v!r}" for k, v in LEFT.items())
        + f"\n  distortion_model: radial-tangential\n  distortion: {_numbers(D_LEFT)}",
        "right": "\n".join(f"  {k}: {v!r}" for k, v in RIGHT.items())
        + f"\n  distortion_model: radial-tangential\n  distortion: {_numbers(D_RIGHT)}",
        "right_camera_pose": f"  rotation: [{', '.join(_numbers(row) for row in POSE[:3, :3])}]\n"
        f"  translation: {_numbers(POSE[:3, 3])}",
    }
    fields.update(changes)
    return "# a stereo rig\n" + "".join(
        f"{key}:\n{value}\n" if "\n" in value or value.startswith("  ") else f"{key}: {value}\n"
        for key, value in fields.items()
        if value != "DROP"
    )


def neoslam_rectified(**changes: str) -> str:
    fields = {
        "image_size": f"[{KITTI_SIZE[0]}, {KITTI_SIZE[1]}]",
        "rectified": "true",
        "left": "\n".join(f"  {k}: {v!r}" for k, v in RECTIFIED.items()),
        "baseline": repr(KITTI_BASELINE),
    }
    fields.update(changes)
    return "".join(
        f"{key}:\n{value}\n" if "\n" in value or value.startswith("  ") else f"{key}: {value}\n"
        for key, value in fields.items()
        if value != "DROP"
    )


def opencv_stereo(header: str = "%YAML:1.0", **changes: str) -> str:
    """As OpenCV's stereo_calib sample writes intrinsics.yml and extrinsics.yml, in one file."""
    T_right_left = invert_pose(POSE)
    fields = {
        "M1": _matrix(_k(LEFT)),
        "D1": _matrix(np.array([D_LEFT + [0.0]])),
        "M2": _matrix(_k(RIGHT)),
        "D2": _matrix(np.array([D_RIGHT + [0.0]])),
        "R": _matrix(T_right_left[:3, :3]),
        "T": _matrix(T_right_left[:3, 3:]),
        "image_width": "752",
        "image_height": "480",
    }
    fields.update(changes)
    return f"{header}\n---\n" + "".join(f"{k}: {v}\n" for k, v in fields.items() if v != "DROP")


def orbslam3(kind: str = "PinHole", **changes: str) -> str:
    """ORB-SLAM3's settings, File.version "1.0"."""
    fields = {"File.version": '"1.0"', "Camera.type": f'"{kind}"', "Camera.width": "752", "Camera.height": "480"}
    fields["Camera.fps"] = "20"
    for prefix, camera in (("Camera1", LEFT), ("Camera2", RIGHT)):
        fields.update({f"{prefix}.{k}": repr(v) for k, v in camera.items()})
    names = ("k1", "k2", "k3", "k4") if kind == "KannalaBrandt8" else ("k1", "k2", "p1", "p2")
    for prefix, coefficients in (("Camera1", D_LEFT), ("Camera2", D_RIGHT)):
        fields.update({f"{prefix}.{n}": repr(v) for n, v in zip(names, coefficients, strict=True)})
    fields["Stereo.T_c1_c2"] = _matrix(POSE).replace("dt: d", "dt: f")
    fields["Stereo.ThDepth"] = "60.0"
    fields.update(changes)
    return "%YAML:1.0\n\n" + "".join(f"{k}: {v}\n" for k, v in fields.items() if v != "DROP")


def orbslam3_rectified(**changes: str) -> str:
    fields = {"File.version": '"1.0"', "Camera.type": '"Rectified"'}
    fields.update({f"Camera1.{k}": repr(v) for k, v in RECTIFIED.items()})
    fields.update({"Camera.width": str(KITTI_SIZE[0]), "Camera.height": str(KITTI_SIZE[1]), "Camera.fps": "10"})
    fields["Stereo.b"] = repr(KITTI_BASELINE)
    fields.update(changes)
    return "%YAML:1.0\n" + "".join(f"{k}: {v}\n" for k, v in fields.items() if v != "DROP")


def orbslam_old_rectified(**changes: str) -> str:
    """ORB-SLAM2's KITTI settings: a rectified pair and Camera.bf (baseline x fx)."""
    fields = {f"Camera.{k}": repr(v) for k, v in RECTIFIED.items()}
    fields.update({"Camera.k1": "0.0", "Camera.k2": "0.0", "Camera.p1": "0.0", "Camera.p2": "0.0"})
    fields.update({"Camera.fps": "10.0", "Camera.bf": "379.8145", "Camera.RGB": "1", "ThDepth": "35"})
    fields.update(changes)
    return "%YAML:1.0\n" + "".join(f"{k}: {v}\n" for k, v in fields.items() if v != "DROP")


def rectification() -> tuple[np.ndarray, ...]:
    T_right_left = invert_pose(POSE)
    K1, K2 = _k(LEFT), _k(RIGHT)
    R1, R2, P1, P2, *_ = cv2.stereoRectify(
        K1, np.array(D_LEFT), K2, np.array(D_RIGHT), SIZE, T_right_left[:3, :3].copy(), T_right_left[:3, 3:].copy(),
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=0,
    )  # fmt: skip
    return R1, R2, P1, P2


def orbslam_old_raw(**changes: str) -> str:
    """ORB-SLAM2's EuRoC settings: LEFT and RIGHT K, D, R, P (the rectification, as a ROS CameraInfo holds it)."""
    R1, R2, P1, P2 = rectification()
    intrinsics = P1[[0, 1, 0, 1], [0, 1, 2, 2]]
    fields = {f"Camera.{k}": repr(float(v)) for k, v in zip(("fx", "fy", "cx", "cy"), intrinsics, strict=True)}
    fields.update({"Camera.width": "752", "Camera.height": "480", "Camera.bf": repr(-float(P2[0, 3]))})
    for side, K, D, R, P in (("LEFT", _k(LEFT), D_LEFT, R1, P1), ("RIGHT", _k(RIGHT), D_RIGHT, R2, P2)):
        fields.update({f"{side}.height": "480", f"{side}.width": "752"})
        fields[f"{side}.D"] = _matrix(np.array([D + [0.0]])).replace("data: ", "data:")  # ORB-SLAM2's own spelling
        fields.update({f"{side}.K": _matrix(K), f"{side}.R": _matrix(R), f"{side}.P": _matrix(P)})
    fields.update(changes)
    return "%YAML:1.0\n" + "".join(f"{k}: {v}\n" for k, v in fields.items() if v != "DROP")


def _read(tmp_path: Path, text: str, size: tuple[int, int] = SIZE, name: str = "calibration.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return read_stereo_calibration(path, size)


# --- every format, read ---


@pytest.mark.parametrize("writer", [neoslam_raw, opencv_stereo, orbslam3], ids=["neoslam", "opencv", "orbslam3"])
def test_one_raw_calibration_in_every_format_rectifies_alike(tmp_path: Path, writer) -> None:
    calibration = _read(tmp_path, writer())
    np.testing.assert_allclose(calibration.left.K, _k(LEFT))
    np.testing.assert_allclose(calibration.right.D[:4], D_RIGHT)
    np.testing.assert_allclose(calibration.T_right_left, invert_pose(POSE), atol=1e-9)
    rectifier = calibration.rectifier()
    assert not rectifier.identity
    R1, _, P1, P2 = rectification()
    camera = rectifier.camera
    np.testing.assert_allclose([camera.fx, camera.fy, camera.cx, camera.cy], P1[[0, 1, 0, 1], [0, 1, 2, 2]], rtol=1e-7)
    assert camera.baseline == pytest.approx(-P2[0, 3] / P2[0, 0], rel=1e-7)
    assert camera.baseline == pytest.approx(0.1101, abs=1e-3)
    np.testing.assert_allclose(rectifier.left_rotation, R1, atol=1e-7)


def test_the_opencv_files_of_opencv_itself_and_of_older_versions(tmp_path: Path) -> None:
    """cv2.FileStorage writes "%YAML 1.2" (OpenCV 5) where older versions wrote "%YAML:1.0"; a file without the
    image size takes the images'."""
    path = tmp_path / "stereo.yml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    T_right_left = invert_pose(POSE)
    for key, value in (("M1", _k(LEFT)), ("D1", np.array([D_LEFT])), ("M2", _k(RIGHT)), ("D2", np.array([D_RIGHT]))):
        storage.write(key, value)
    storage.write("R", T_right_left[:3, :3].copy())
    storage.write("T", T_right_left[:3, 3:].copy())
    storage.release()
    written = read_stereo_calibration(path, SIZE)
    by_hand = _read(tmp_path, opencv_stereo(image_width="DROP", image_height="DROP"))
    assert written.format == by_hand.format == "opencv"
    assert written.rectifier().camera == by_hand.rectifier().camera
    np.testing.assert_allclose(written.T_right_left, by_hand.T_right_left, atol=1e-15)
    assert written.left.size == SIZE


def test_orbslam3_fisheye_cameras(tmp_path: Path) -> None:
    calibration = _read(tmp_path, orbslam3("KannalaBrandt8"))
    assert calibration.left.model == calibration.right.model == "equidistant"
    np.testing.assert_allclose(calibration.left.D, D_LEFT)
    assert calibration.frame_rate == 20
    rectifier = calibration.rectifier()
    assert rectifier.camera.baseline == pytest.approx(np.linalg.norm(POSE[:3, 3]), rel=1e-6)


def test_orbslam_left_right_projections(tmp_path: Path) -> None:
    """The older style's LEFT/RIGHT K D R P rectify as a ROS CameraInfo does: the given R and P."""
    calibration = _read(tmp_path, orbslam_old_raw())
    assert calibration.projections is not None and calibration.format == "orbslam2"
    ours = calibration.rectifier().camera
    extrinsics = _read(tmp_path, neoslam_raw(), name="ours.yaml").rectifier().camera
    for field in ("fx", "fy", "cx", "cy", "baseline"):
        assert getattr(ours, field) == pytest.approx(getattr(extrinsics, field), rel=1e-7), field


@pytest.mark.parametrize(
    "writer",
    [neoslam_rectified, orbslam3_rectified, orbslam_old_rectified],
    ids=["neoslam", "orbslam3", "orbslam2"],
)
def test_a_rectified_pair_is_read_without_a_warp(tmp_path: Path, writer) -> None:
    """KITTI's calibration: the camera NeoSLAM reads from KITTI's calib.txt, to the last bit."""
    rectifier = _read(tmp_path, writer(), KITTI_SIZE).rectifier()
    assert rectifier.identity
    camera = rectifier.camera
    assert (camera.fx, camera.fy, camera.cx, camera.cy) == tuple(RECTIFIED.values())
    assert camera.baseline == KITTI_BASELINE
    assert (camera.width, camera.height) == KITTI_SIZE


def test_frame_rates(tmp_path: Path) -> None:
    assert _read(tmp_path, neoslam_raw()).frame_rate == 20
    assert _read(tmp_path, neoslam_raw(frame_rate="DROP")).frame_rate is None
    assert _read(tmp_path, orbslam_old_rectified(), KITTI_SIZE).frame_rate == 10
    assert _read(tmp_path, opencv_stereo()).frame_rate is None


def test_opencv_keys_in_plain_yaml(tmp_path: Path) -> None:
    """ORB-SLAM's keys in a file without OpenCV's header line are still ORB-SLAM's settings."""
    text = orbslam_old_rectified().removeprefix("%YAML:1.0\n")
    assert _read(tmp_path, text, KITTI_SIZE).rectifier().camera.baseline == KITTI_BASELINE


# --- every bad calibration: one line naming the file and the field ---

BAD = [
    ("neoslam", neoslam_raw(left="  fy: 457.296\n  cx: 367.2\n  cy: 248.3"), "left.fx: missing"),
    ("neoslam", neoslam_raw(left="  fx: abc\n  fy: 457.296\n  cx: 367.2\n  cy: 248.3"), "left.fx: must be a number"),
    ("neoslam", neoslam_raw(left="  fx: -458\n  fy: 457.296\n  cx: 367.2\n  cy: 248.3"), "left.fx: must be positive"),
    ("neoslam", neoslam_raw(left="  fx: .nan\n  fy: 457.296\n  cx: 367.2\n  cy: 248.3"), "left.fx: must be finite"),
    ("neoslam", neoslam_raw(left="  fx: true\n  fy: 457.296\n  cx: 367.2\n  cy: 248.3"), "left.fx: must be a number"),
    ("neoslam", neoslam_raw(left="  fx: 458\n  fxx: 1\n  fy: 457\n  cx: 367\n  cy: 248"), "left.fxx: unknown field"),
    ("neoslam", neoslam_raw(image_size="[752]"), "image_size: must be [width, height]"),
    ("neoslam", neoslam_raw(image_size="[640, 480]"), "image_size: 640x480, but the images are 752x480"),
    ("neoslam", neoslam_raw(rectified="yes"), "rectified: must be true or false"),
    ("neoslam", neoslam_raw(rectified="DROP"), "not a stereo calibration NeoSLAM reads"),
    ("neoslam", neoslam_raw(right="DROP"), "right: missing"),
    ("neoslam", neoslam_raw(frame_rate="0"), "frame_rate: must be positive"),
    (
        "neoslam",
        neoslam_raw(left="  fx: 458\n  fy: 457\n  cx: 367\n  cy: 248\n  distortion_model: radial-tangential\n"
                    "  distortion: [0.1, 0.2, 0.3]"),  # fmt: skip
        "left.distortion: has 3 numbers, 4 or 5 or 8 or 12 or 14 expected",
    ),
    (
        "neoslam",
        neoslam_raw(left="  fx: 458\n  fy: 457\n  cx: 367\n  cy: 248\n  distortion_model: fisheye\n  distortion: []"),
        "left.distortion_model: must be one of radial-tangential, equidistant, none",
    ),
    ("neoslam", neoslam_raw(right_camera_pose="  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]"),
     "right_camera_pose.translation: missing"),  # fmt: skip
    (
        "neoslam",
        neoslam_raw(right_camera_pose="  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 2]]\n  translation: [0.11, 0, 0]"),
        "right_camera_pose.rotation: not a rotation matrix",
    ),
    (
        "neoslam",
        neoslam_raw(right_camera_pose="  rotation: [[1, 0, 0], [0, 1, 0]]\n  translation: [0.11, 0, 0]"),
        "right_camera_pose.rotation: must be three rows of three numbers",
    ),
    (
        "neoslam",
        neoslam_raw(right_camera_pose="  rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n  translation: [-0.11, 0, 0]"),
        "right_camera_pose: the rectified baseline is not positive",
    ),
    ("neoslam", neoslam_raw(baseline="0.11"), "baseline: a raw pair (rectified: false) takes right_camera_pose"),
    ("neoslam-rectified", neoslam_rectified(baseline="0"), "baseline: must be positive"),
    ("neoslam-rectified", neoslam_rectified(baseline="-0.54"), "baseline: must be positive"),
    ("neoslam-rectified", neoslam_rectified(baseline="DROP"), "baseline: missing"),
    ("neoslam-rectified", neoslam_rectified(baseline="[0.5]"), "baseline: must be a number"),
    (
        "neoslam-rectified",
        neoslam_rectified(right="  fx: 700\n  fy: 707.0912\n  cx: 601.8873\n  cy: 183.1104"),
        "right: a rectified pair has one fx, fy, cx, cy",
    ),
    ("opencv", opencv_stereo(T="DROP"), "T: missing"),
    ("opencv", opencv_stereo(T=_matrix(np.array([[0.11, 0.0]]))), "T: has 2 numbers, 3 expected"),
    ("opencv", opencv_stereo(M1=_matrix(np.full((3, 3), np.nan))), "M1: holds a value that is not finite"),
    ("opencv", opencv_stereo(M1=_matrix(np.eye(2))), "M1: is 2x2, 3x3 expected"),
    ("opencv", opencv_stereo(M1="[1, 2, abc]"), "M1: holds a value that is not a number"),
    ("opencv", opencv_stereo(image_width="640"), "image_width, image_height: 640x480, but the images are 752x480"),
    ("opencv", opencv_stereo(image_width="752.5"), "image_width: must be a whole number"),
    ("opencv", opencv_stereo(R=_matrix(2 * np.eye(3))), "R: not a rotation matrix"),
    ("opencv", opencv_stereo(T=_matrix(np.array([[0.11], [0.0], [0.0]]))), "R, T: "),
    ("opencv", opencv_stereo(M1="'707'"), "M1: must be a list of numbers or an opencv-matrix"),
    ("orbslam3", orbslam3(**{"Camera.width": "640"}), "Camera.width, Camera.height: 640x480, but the images"),
    ("orbslam3", orbslam3(**{"Camera.height": "DROP"}), "Camera.height: missing"),
    ("orbslam3", orbslam3(**{"Camera.type": '"Omni"'}), "Camera.type: must be PinHole, KannalaBrandt8 or Rectified"),
    ("orbslam3", orbslam3(**{"Camera.type": "3"}), "Camera.type: must be a string"),
    ("orbslam3", orbslam3(**{"Camera2.fx": "DROP"}), "Camera2.fx: missing"),
    ("orbslam3", orbslam3(**{"Camera1.fy": "-1"}), "Camera1: K has a non-positive focal length"),
    ("orbslam3", orbslam3(**{"Stereo.T_c1_c2": _matrix(np.eye(3))}), "Stereo.T_c1_c2: is 3x3, 4x4 expected"),
    ("orbslam3", orbslam3(**{"Stereo.T_c1_c2": _matrix(2 * np.eye(4))}), "Stereo.T_c1_c2: its last row"),
    ("orbslam3", orbslam3(**{"Camera.fps": "-20"}), "Camera.fps: must be positive"),
    ("orbslam3", orbslam3("KannalaBrandt8", **{"Camera2.k4": "DROP"}), "Camera2.k4: missing"),
    ("orbslam3-rectified", orbslam3_rectified(**{"Stereo.b": "-0.5"}), "Stereo.b: the rectified baseline is not"),
    ("orbslam3-rectified", orbslam3_rectified(**{"Stereo.b": ".nan"}), "Stereo.b: must be finite"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.bf": "DROP"}), "Camera.bf: missing"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.bf": "0"}), "Camera.bf: the rectified baseline is not positive"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.fx": '"fast"'}), "Camera.fx: must be a number"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.k1": "0.1"}), "Camera.k1: a pair without LEFT/RIGHT rectification"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.width": "100"}), "Camera.height: missing"),
    ("orbslam2", orbslam_old_rectified(**{"Camera.width": "100", "Camera.height": "370"}), "Camera.width, Camera."),
    ("orbslam2-raw", orbslam_old_raw(**{"RIGHT.P": _matrix(np.eye(3))}), "RIGHT.P: is 3x3, 3x4 expected"),
    ("orbslam2-raw", orbslam_old_raw(**{"LEFT.width": "640"}), "LEFT.width, LEFT.height: 640x480"),
    ("unknown", "camera: {fx: 1}\n", "not a stereo calibration NeoSLAM reads"),
    ("unknown", "%YAML:1.0\nfoo: 1\n", "not a stereo calibration NeoSLAM reads"),
    ("unknown", "- a list\n", "not a stereo calibration NeoSLAM reads"),
    ("broken", "left: [1, 2\n", "not valid YAML"),
    ("broken", "%YAML:1.0\nM1: [1, 2\n", "not a valid OpenCV YAML file"),
    ("broken", "%YAML:1.0\nM1: 1\nM1: 2\n", "M1: given twice"),
    ("broken", "%YAML:1.0\n", "not a valid OpenCV YAML file"),
    ("broken", f"%YAML:1.0\nM1: {_matrix(np.eye(3)).replace('rows: 3', 'rows: 100000')}", "M1: is 100000x3"),
]  # fmt: skip


@pytest.mark.parametrize(("kind", "text", "expected"), BAD, ids=[f"{kind}-{i}" for i, (kind, *_) in enumerate(BAD)])
def test_a_bad_calibration_is_one_line_naming_its_field(tmp_path: Path, kind: str, text: str, expected: str) -> None:
    size = KITTI_SIZE if kind in ("neoslam-rectified", "orbslam3-rectified", "orbslam2") else SIZE
    path = tmp_path / "calibration.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        read_stereo_calibration(path, size).rectifier()
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}:"), message
    assert expected in message, message


def test_a_calibration_file_that_is_not_there_or_not_a_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="calibration file not found"):
        read_stereo_calibration(tmp_path / "missing.yaml", SIZE)
    with pytest.raises(InputError, match="is a folder"):
        read_stereo_calibration(tmp_path, SIZE)
    (tmp_path / "binary.yaml").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match="not a text file"):
        read_stereo_calibration(tmp_path / "binary.yaml", SIZE)


YAML_TEXT = st.text(
    alphabet="%YAML:1.0 !opencv-matrix\nrowscolsdtdata[]{},-.0123456789eMDRTCamera.fxbLEFT_P", max_size=300
)


@pytest.mark.slow
@settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)
@given(st.one_of(YAML_TEXT.map(str.encode), st.binary(max_size=300)))
def test_any_bytes_are_a_calibration_or_one_error(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "calibration.yaml"
        path.write_bytes(data)
        with contextlib.suppress(NeoSLAMError):
            read_stereo_calibration(path, SIZE).rectifier()


def test_the_documented_examples_are_read(tmp_path: Path) -> None:
    """docs/own_camera.md's two examples of NeoSLAM's format: a raw pair (EuRoC's cameras) and a rectified one."""
    page = (Path(__file__).resolve().parents[2] / "docs" / "own_camera.md").read_text()
    raw, rectified = re.findall(r"```yaml\n(image_size.*?|# my_rig.*?)```", page, flags=re.S)[:2]
    raw_pair = _read(tmp_path, raw).rectifier()
    expected = _read(tmp_path, neoslam_raw(), name="ours.yaml").rectifier().camera
    for field in ("fx", "fy", "cx", "cy", "baseline", "width", "height"):
        assert getattr(raw_pair.camera, field) == pytest.approx(getattr(expected, field), rel=1e-6), field
    assert _read(tmp_path, rectified, KITTI_SIZE, "kitti.yaml").rectifier().identity


def test_a_calibration_that_is_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "calibration.yaml"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="FIFO"):
        read_stereo_calibration(fifo, SIZE)
