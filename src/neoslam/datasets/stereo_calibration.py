"""Stereo calibration files, read into the cameras and the pose a `StereoRectifier` needs. Three formats, recognised
by their content:

- **NeoSLAM's own** (plain YAML with a `rectified` field; docs/own_camera.md documents it field by field):
  `image_size`, `rectified`, `left` and `right` (`fx`, `fy`, `cx`, `cy`, `distortion_model`, `distortion`), then
  `right_camera_pose` (`rotation`, `translation`: the right camera in the left camera's optical frame) for a raw
  pair or `baseline` for a rectified one; optional `frame_rate`.
- **OpenCV's stereo calibration** (`%YAML:1.0`, as OpenCV's stereo_calib sample writes it): `M1 D1 M2 D2 R T`
  (R, T take a point from the left camera's frame to the right's; T in metres), and the image size where present
  (`image_width` and `image_height`, or `image_size` / `imageSize`).
- **ORB-SLAM3's settings**: the `File.version: "1.0"` style (`Camera.type` PinHole, KannalaBrandt8 or Rectified;
  `Camera1.*`, `Camera2.*`, `Stereo.T_c1_c2` or `Stereo.b`, `Camera.width`, `Camera.height`, `Camera.fps`) and the
  older style (`Camera.fx ... Camera.bf` of a rectified pair, or `LEFT.K/D/R/P` and `RIGHT.*` of a raw one).

Every problem is one `InputError` naming the file and the field.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.datasets.opencv_yaml import OpenCVYaml, is_opencv_yaml
from neoslam.errors import InputError
from neoslam.geometry import invert_pose, is_rotation_matrix, make_pose
from neoslam.inputs import MAX_CONFIG_BYTES
from neoslam.perception.rectification import (
    EQUIDISTANT_LENGTH,
    PLUMB_BOB_LENGTHS,
    ROTATION_TOLERANCE,
    RawCamera,
    StereoRectifier,
)
from neoslam.text import read_text, read_yaml

__all__ = ["StereoCalibration", "read_stereo_calibration", "intrinsic_matrix", "MODEL_NAMES"]

# NeoSLAM's (and EuRoC's) names of the distortion models -> the rectifier's
MODEL_NAMES = {"radial-tangential": "plumb_bob", "equidistant": "equidistant", "none": "none"}
CAMERA_FIELDS = ("fx", "fy", "cx", "cy", "distortion_model", "distortion")
TOP_FIELDS = ("image_size", "rectified", "left", "right", "right_camera_pose", "baseline", "frame_rate")
POSE_FIELDS = ("rotation", "translation")
OPENCV_SIZE_VECTORS = ("image_size", "imageSize")
ORB_PINHOLE = ("k1", "k2", "p1", "p2")
ORB_FISHEYE = ("k1", "k2", "k3", "k4")
FORMATS = (
    "NeoSLAM's (a `rectified` field), OpenCV's stereo calibration (M1 D1 M2 D2 R T) or ORB-SLAM3's settings "
    "(Camera1.fx or Camera.fx)"
)


@dataclass(frozen=True)
class StereoCalibration:
    """A stereo calibration as read: the two cameras and either the pose between them (`T_right_left`, OpenCV's R
    and T) or each camera's rectification R and projection P (`projections`); `frame_rate` (Hz) when the file gives
    one. `pose_field` names the field the rectification's errors come from."""

    path: Path
    format: str
    left: RawCamera
    right: RawCamera
    T_right_left: np.ndarray | None
    projections: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
    frame_rate: float | None
    pose_field: str

    def rectifier(self, alpha: float = 0.0) -> StereoRectifier:
        """The rectifier of this calibration; a calibration that cannot be rectified is one line naming its field."""
        try:
            if self.projections is not None:
                return StereoRectifier.from_projections(self.left, self.right, *self.projections)
            assert self.T_right_left is not None
            return StereoRectifier.from_extrinsics(self.left, self.right, self.T_right_left, alpha)
        except ValueError as error:
            raise InputError(self.path, f"{self.pose_field}: {error}") from None


def intrinsic_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def raw_camera(path: Path, field: str, K: np.ndarray, D: np.ndarray, model: str, size: tuple[int, int]) -> RawCamera:
    """A camera, its problems named by `field` (the camera's key in the file)."""
    try:
        return RawCamera(K, D, model, size)  # type: ignore[arg-type]
    except ValueError as error:
        raise InputError(path, f"{field}: {error}") from None


def read_stereo_calibration(path: Path, image_size: tuple[int, int]) -> StereoCalibration:
    """The calibration in the file at `path`, whose format is recognised from its content. `image_size` (width,
    height) is the images' size: a file's size must equal it, and a file without one takes it."""
    text = read_text(path, "calibration file not found", MAX_CONFIG_BYTES)
    if is_opencv_yaml(text):
        return _from_opencv_yaml(OpenCVYaml(path, text), image_size)
    document = read_yaml(path, "calibration file not found")
    if isinstance(document, dict) and "rectified" in document:
        return _NeoSLAMFile(path, document).calibration(image_size)
    if isinstance(document, dict) and {"M1", "Camera.fx", "Camera1.fx"} & set(document):
        return _from_opencv_yaml(OpenCVYaml(path, text), image_size)  # OpenCV's keys without OpenCV's header
    raise InputError(path, f"not a stereo calibration NeoSLAM reads: {FORMATS}")


def _check_size(path: Path, field: str, size: tuple[int, int], image_size: tuple[int, int]) -> None:
    if size != image_size:
        given, actual = (f"{w}x{h}" for w, h in (size, image_size))
        raise InputError(path, f"{field}: {given}, but the images are {actual}")


def _shifted_pair(baseline: float) -> np.ndarray:
    """T_right_left of a rectified pair: the right camera `baseline` along the left's x axis."""
    return make_pose(np.eye(3), np.array([-baseline, 0.0, 0.0]))


# --- NeoSLAM's own format ---


class _NeoSLAMFile:
    """NeoSLAM's calibration format (plain YAML), field by field."""

    def __init__(self, path: Path, document: dict[str, Any]) -> None:
        self.path = path
        self.document = document
        self._known(document, TOP_FIELDS, "")

    def calibration(self, image_size: tuple[int, int]) -> StereoCalibration:
        size = self._size()
        _check_size(self.path, "image_size", size, image_size)
        rectified = self._value("rectified")
        if not isinstance(rectified, bool):
            raise self._error("rectified", "must be true or false")
        frame_rate = self._number("frame_rate", positive=True) if "frame_rate" in self.document else None
        left = self._camera("left", size, rectified)
        if rectified:
            if "right_camera_pose" in self.document:
                raise self._error("right_camera_pose", "a rectified pair takes a baseline, not the right camera's pose")
            if "right" in self.document:
                right = self._camera("right", size, rectified)
                if not np.array_equal(right.K, left.K):
                    raise self._error("right", "a rectified pair has one fx, fy, cx, cy: the right's differ")
            pose, pose_field = _shifted_pair(self._number("baseline", positive=True)), "baseline"
            return StereoCalibration(self.path, "neoslam", left, left, pose, None, frame_rate, pose_field)
        if "baseline" in self.document:
            raise self._error("baseline", "a raw pair (rectified: false) takes right_camera_pose, not a baseline")
        right = self._camera("right", size, rectified)
        pose = invert_pose(self._pose())  # the file gives the right camera's pose; the rectifier takes its inverse
        return StereoCalibration(self.path, "neoslam", left, right, pose, None, frame_rate, "right_camera_pose")

    def _size(self) -> tuple[int, int]:
        value = self._value("image_size")
        if not (isinstance(value, list) and len(value) == 2 and all(_is_count(side) for side in value)):
            raise self._error("image_size", "must be [width, height], two positive whole numbers of px")
        return value[0], value[1]

    def _camera(self, side: str, size: tuple[int, int], rectified: bool) -> RawCamera:
        fields = self._value(side)
        if not isinstance(fields, dict):
            raise self._error(side, "must be a mapping of fx, fy, cx, cy (and the distortion)")
        self._known(fields, CAMERA_FIELDS, f"{side}.")
        fx, fy, cx, cy = (self._number(f"{side}.{name}", positive=name in ("fx", "fy")) for name in CAMERA_FIELDS[:4])
        model_name = fields.get("distortion_model", "none")
        if model_name not in MODEL_NAMES:
            known = ", ".join(MODEL_NAMES)
            raise self._error(f"{side}.distortion_model", f"must be one of {known}, not {model_name!r}")
        model = MODEL_NAMES[model_name]
        if rectified and model != "none":
            raise self._error(f"{side}.distortion_model", "a rectified pair has no distortion: none")
        lengths = {"plumb_bob": PLUMB_BOB_LENGTHS[1:], "equidistant": (EQUIDISTANT_LENGTH,)}.get(model, (0,))
        if model == "none" and "distortion" in fields:
            raise self._error(f"{side}.distortion", "given without a distortion_model")
        distortion = self._numbers(f"{side}.distortion", lengths) if model != "none" else np.zeros(0)
        return raw_camera(self.path, side, intrinsic_matrix(fx, fy, cx, cy), distortion, model, size)

    def _pose(self) -> np.ndarray:
        fields = self._value("right_camera_pose")
        if not isinstance(fields, dict):
            raise self._error("right_camera_pose", "must be a mapping of rotation and translation")
        self._known(fields, POSE_FIELDS, "right_camera_pose.")
        rows = self._value("right_camera_pose.rotation")
        if not (isinstance(rows, list) and len(rows) == 3 and all(isinstance(row, list) for row in rows)):
            raise self._error("right_camera_pose.rotation", "must be three rows of three numbers")
        field = "right_camera_pose.rotation"
        rotation = np.array([self._numbers(f"{field} row {i + 1}", (3,), row) for i, row in enumerate(rows)])
        _check_rotation(self.path, field, rotation)
        return make_pose(rotation, self._numbers("right_camera_pose.translation", (3,)))

    def _value(self, field: str) -> Any:
        value: Any = self.document
        for part in field.split("."):
            if not isinstance(value, dict) or part not in value:
                raise self._error(field, "missing")
            value = value[part]
        return value

    def _number(self, field: str, positive: bool = False) -> float:
        value = self._value(field)
        if not _is_number(value):
            raise self._error(field, f"must be a number, not {_shown(value)}")
        if not np.isfinite(value):
            raise self._error(field, f"must be finite, not {value}")
        if positive and not value > 0:
            raise self._error(field, f"must be positive, not {value}")
        return float(value)

    def _numbers(self, field: str, lengths: tuple[int, ...], value: Any = None) -> np.ndarray:
        value = self._value(field) if value is None else value
        if not isinstance(value, list) or not all(_is_number(item) for item in value):
            raise self._error(field, "must be a list of numbers")
        if len(value) not in lengths:
            counts = " or ".join(str(n) for n in lengths)
            raise self._error(field, f"has {len(value)} numbers, {counts} expected")
        numbers = np.array(value, dtype=np.float64)
        if not np.isfinite(numbers).all():
            raise self._error(field, "holds a value that is not finite")
        return numbers

    def _known(self, fields: Mapping[Any, Any], known: tuple[str, ...], prefix: str) -> None:
        unknown = next((key for key in fields if key not in known), None)
        if unknown is not None:
            raise self._error(f"{prefix}{unknown}", f"unknown field (known: {', '.join(known)})")

    def _error(self, field: str, problem: str) -> InputError:
        return InputError(self.path, f"{field}: {problem}")


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _is_count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f"a {type(value).__name__}"


# --- OpenCV's and ORB-SLAM3's files (cv2.FileStorage YAML) ---


def _from_opencv_yaml(storage: OpenCVYaml, image_size: tuple[int, int]) -> StereoCalibration:
    if "M1" in storage:
        return _opencv_stereo(storage, image_size)
    if "Camera1.fx" in storage or "File.version" in storage:
        return _orbslam3(storage, image_size)
    if "Camera.fx" in storage or "LEFT.K" in storage:
        return _orbslam_old(storage, image_size)
    raise InputError(storage.path, f"not a stereo calibration NeoSLAM reads: {FORMATS}")


def _opencv_size(storage: OpenCVYaml, image_size: tuple[int, int]) -> tuple[int, int]:
    """The image size the file gives (checked against the images), else the images'."""
    if "image_width" in storage or "image_height" in storage:
        size = (_count(storage, "image_width"), _count(storage, "image_height"))
        _check_size(storage.path, "image_width, image_height", size, image_size)
    for key in OPENCV_SIZE_VECTORS:
        if key in storage:
            width, height = storage.vector(key, (2,))
            if not (width == int(width) > 0 and height == int(height) > 0):
                raise InputError(storage.path, f"{key}: must be two positive whole numbers (width, height)")
            _check_size(storage.path, key, (int(width), int(height)), image_size)
    return image_size


def _count(storage: OpenCVYaml, key: str) -> int:
    value = storage.integer(key)
    if value <= 0:
        raise InputError(storage.path, f"{key}: must be positive, not {value}")
    return value


def _opencv_stereo(storage: OpenCVYaml, image_size: tuple[int, int]) -> StereoCalibration:
    size = _opencv_size(storage, image_size)
    cameras = []
    for matrix_key, distortion_key in (("M1", "D1"), ("M2", "D2")):
        K = storage.matrix(matrix_key, (3, 3))
        D = storage.vector(distortion_key, PLUMB_BOB_LENGTHS[1:])
        cameras.append(raw_camera(storage.path, f"{matrix_key}, {distortion_key}", K, D, "plumb_bob", size))
    rotation = storage.matrix("R", (3, 3))
    _check_rotation(storage.path, "R", rotation)
    pose = make_pose(rotation, storage.vector("T", (3,)))
    return StereoCalibration(storage.path, "opencv", cameras[0], cameras[1], pose, None, None, "R, T")


def _orb_intrinsics(storage: OpenCVYaml, prefix: str) -> np.ndarray:
    return intrinsic_matrix(*(storage.number(f"{prefix}.{name}") for name in ("fx", "fy", "cx", "cy")))


def _orb_distortion(storage: OpenCVYaml, prefix: str, names: tuple[str, ...]) -> np.ndarray:
    """k1 k2 p1 p2 [k3] (pinhole, all optional together) or k1..k4 (fisheye, required)."""
    if names == ORB_PINHOLE and f"{prefix}.k1" not in storage:
        return np.zeros(0)
    if names == ORB_PINHOLE and f"{prefix}.k3" in storage:
        names = (*names, "k3")
    return np.array([storage.number(f"{prefix}.{name}") for name in names])


def _orb_size(storage: OpenCVYaml, prefix: str, image_size: tuple[int, int], required: bool) -> tuple[int, int]:
    keys = (f"{prefix}.width", f"{prefix}.height")
    if required or any(key in storage for key in keys):
        size = (_count(storage, keys[0]), _count(storage, keys[1]))
        _check_size(storage.path, ", ".join(keys), size, image_size)
    return image_size


def _orbslam3(storage: OpenCVYaml, image_size: tuple[int, int]) -> StereoCalibration:
    """ORB-SLAM3's settings of version 1.0."""
    size = _orb_size(storage, "Camera", image_size, required=True)
    kind = storage.string("Camera.type")
    frame_rate = _frame_rate(storage)
    if kind == "Rectified":
        left = raw_camera(storage.path, "Camera1", _orb_intrinsics(storage, "Camera1"), np.zeros(0), "none", size)
        pose = _shifted_pair(storage.number("Stereo.b"))
        return StereoCalibration(storage.path, "orbslam3", left, left, pose, None, frame_rate, "Stereo.b")
    models = {"PinHole": ("plumb_bob", ORB_PINHOLE), "KannalaBrandt8": ("equidistant", ORB_FISHEYE)}
    if kind not in models:
        raise InputError(storage.path, f"Camera.type: must be PinHole, KannalaBrandt8 or Rectified, not {kind!r}")
    model, names = models[kind]
    left, right = (
        raw_camera(
            storage.path, prefix, _orb_intrinsics(storage, prefix), _orb_distortion(storage, prefix, names), model, size
        )
        for prefix in ("Camera1", "Camera2")
    )
    pose = invert_pose(_rigid(storage, "Stereo.T_c1_c2"))  # the pose of camera 2 in camera 1's frame
    return StereoCalibration(storage.path, "orbslam3", left, right, pose, None, frame_rate, "Stereo.T_c1_c2")


def _orbslam_old(storage: OpenCVYaml, image_size: tuple[int, int]) -> StereoCalibration:
    """ORB-SLAM2's and the first ORB-SLAM3's settings: a rectified pair (Camera.*, Camera.bf) or LEFT/RIGHT K D R P."""
    size = _orb_size(storage, "Camera", image_size, required=False)
    frame_rate = _frame_rate(storage)
    if "LEFT.K" in storage or "RIGHT.K" in storage:
        cameras, rotations, projections = [], [], []
        for side in ("LEFT", "RIGHT"):
            _orb_size(storage, side, image_size, required=False)
            K, D = storage.matrix(f"{side}.K", (3, 3)), storage.vector(f"{side}.D", PLUMB_BOB_LENGTHS[1:])
            cameras.append(raw_camera(storage.path, f"{side}.K, {side}.D", K, D, "plumb_bob", size))
            rotations.append(storage.matrix(f"{side}.R", (3, 3)))
            projections.append(storage.matrix(f"{side}.P", (3, 4)))
        matrices = (rotations[0], rotations[1], projections[0], projections[1])
        return StereoCalibration(
            storage.path, "orbslam2", cameras[0], cameras[1], None, matrices, frame_rate, "LEFT.R/P, RIGHT.R/P"
        )
    K = _orb_intrinsics(storage, "Camera")
    if _orb_distortion(storage, "Camera", ORB_PINHOLE).any():
        raise InputError(
            storage.path, "Camera.k1: a pair without LEFT/RIGHT rectification must be rectified (no distortion)"
        )
    left = raw_camera(storage.path, "Camera", K, np.zeros(0), "none", size)
    baseline = storage.number("Camera.bf") / K[0, 0]
    return StereoCalibration(
        storage.path, "orbslam2", left, left, _shifted_pair(baseline), None, frame_rate, "Camera.bf"
    )


def _frame_rate(storage: OpenCVYaml) -> float | None:
    if "Camera.fps" not in storage:
        return None
    rate = storage.number("Camera.fps")
    if rate <= 0:
        raise InputError(storage.path, f"Camera.fps: must be positive, not {rate:g}")
    return rate


def _rigid(storage: OpenCVYaml, key: str) -> np.ndarray:
    """A 4x4 rigid transform: a rotation, a translation and the last row 0 0 0 1."""
    pose = storage.matrix(key, (4, 4))
    if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(storage.path, f"{key}: its last row must be 0 0 0 1")
    _check_rotation(storage.path, key, pose[:3, :3])
    return pose


def _check_rotation(path: Path, field: str, rotation: np.ndarray) -> None:
    if not is_rotation_matrix(rotation, ROTATION_TOLERANCE):
        raise InputError(path, f"{field}: not a rotation matrix (orthonormal, determinant +1)")
