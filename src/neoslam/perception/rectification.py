"""Stereo rectification: a raw stereo calibration becomes the rectified pair's `CameraConfig` and the maps that warp
raw images into it (OpenCV: `stereoRectify`, `initUndistortRectifyMap`, `remap`; `cv2.fisheye` for the equidistant
model).

The front end matches stereo points along image rows and triangulates with one focal length and a baseline, so it
needs a rectified pair: no lens distortion, both image planes in one plane, rows aligned. `StereoRectifier` gives
that pair from either

- `from_extrinsics`: each camera's intrinsics and distortion and the pose between them (`T_right_left`, which takes
  a point from the left camera's optical frame to the right's: OpenCV's R and T), as calibration tools write them;
- `from_projections`: each camera's intrinsics and distortion and its rectification rotation R and projection P, as
  a ROS `CameraInfo` carries them (image_proc's maps: from K, D, R, P).

A calibration of images that are a rectified pair already (no distortion, one intrinsic matrix, no rotation between
the cameras, the right camera on the left's x axis) gives `identity`: the images are passed on untouched, so a
rectified input gives the same bytes as through a reader of rectified images.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from pydantic import ValidationError

from neoslam.config import CameraConfig, describe_validation_error
from neoslam.geometry import is_rotation_matrix

__all__ = ["DistortionModel", "RawCamera", "StereoRectifier"]

DistortionModel = Literal["plumb_bob", "equidistant", "none"]
DISTORTION_MODELS: tuple[str, ...] = ("plumb_bob", "equidistant", "none")
# OpenCV's radial-tangential coefficients: k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tx ty]]]] (none: no distortion)
PLUMB_BOB_LENGTHS = (0, 4, 5, 8, 12, 14)
EQUIDISTANT_LENGTH = 4  # k1 k2 k3 k4 of the fisheye model
MAX_IMAGE_SIDE = 100_000  # CameraConfig's bound on width and height, px
# A rotation within this of the identity (per matrix element) and a translation within this share of its length of
# the x axis move no pixel of any real image by a measurable amount: such a pair is rectified already.
IDENTITY_TOLERANCE = 1e-9
# A given rotation whose R R^T is farther than this from the identity (per element) is not a rotation matrix.
ROTATION_TOLERANCE = 1e-6
# Two rectified cameras share their intrinsics in P; more than this relative difference is not a rectified pair.
SAME_INTRINSICS_RTOL = 1e-3
MAP_TYPE = cv2.CV_16SC2  # fixed-point maps: OpenCV's fastest remap, 1/32 px interpolation steps


@dataclass(frozen=True)
class RawCamera:
    """One camera as calibrated: intrinsic matrix `K` (3x3), distortion coefficients `D` (any length OpenCV takes
    for the model: plumb_bob 0, 4, 5, 8, 12 or 14; equidistant 4; none 0 or all zeros), the distortion `model`
    (plumb_bob: radial-tangential; equidistant: fisheye; none) and the image `size` (width, height) in px. Checked
    on construction: a `ValueError` names the problem."""

    K: np.ndarray
    D: np.ndarray
    model: DistortionModel
    size: tuple[int, int]

    def __post_init__(self) -> None:
        K = _finite_array(self.K, (3, 3), "K")
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(f"K has a non-positive focal length ({K[0, 0]:g}, {K[1, 1]:g})")
        if not np.array_equal(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
            raise ValueError("K is not an intrinsic matrix (its last row must be 0 0 1 and K[1, 0] zero)")
        if self.model not in DISTORTION_MODELS:
            raise ValueError(f"unknown distortion model {self.model!r} (known: {', '.join(DISTORTION_MODELS)})")
        D = _finite_array(np.asarray(self.D, dtype=np.float64).reshape(-1), None, "D")
        lengths = {"plumb_bob": PLUMB_BOB_LENGTHS, "equidistant": (EQUIDISTANT_LENGTH,)}.get(self.model)
        if lengths is None and D.any():
            raise ValueError("distortion model none has non-zero distortion coefficients")
        if lengths is not None and len(D) not in lengths:
            expected = ", ".join(str(n) for n in lengths)
            raise ValueError(f"{self.model} distortion takes {expected} coefficients, not {len(D)}")
        width, height = _size(self.size)
        for name, value in (("K", K), ("D", D)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "size", (width, height))

    @property
    def distorted(self) -> bool:
        return bool(self.D.any())


def _finite_array(values: object, shape: tuple[int, ...] | None, name: str) -> np.ndarray:
    try:
        array = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} is not an array of numbers") from None
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} has shape {array.shape}, {shape} expected")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} holds a value that is not finite")
    return array


def _size(size: object) -> tuple[int, int]:
    try:
        width, height = (int(side) for side in size)  # type: ignore[union-attr]
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"image size {size!r} is not two whole numbers (width, height)") from None
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE) or (width, height) != tuple(size):
        raise ValueError(f"image size {size!r} is not two whole numbers of px in 1..{MAX_IMAGE_SIDE}")
    return width, height


def _rotation(values: object, name: str) -> np.ndarray:
    rotation = _finite_array(values, (3, 3), name)
    if not is_rotation_matrix(rotation, ROTATION_TOLERANCE):
        raise ValueError(f"{name} is not a rotation matrix (orthonormal, determinant +1)")
    return rotation


def _is_identity(rotation: np.ndarray) -> bool:
    return bool(np.abs(rotation - np.eye(3)).max() <= IDENTITY_TOLERANCE)


def _camera(projection: np.ndarray, size: tuple[int, int], baseline: float) -> CameraConfig:
    """The rectified pair's calibration: intrinsics from the left projection (or intrinsic) matrix."""
    values = (projection[0, 0], projection[1, 1], projection[0, 2], projection[1, 2], baseline)
    if not np.isfinite(values).all():
        raise ValueError("the rectified calibration is not finite")
    if not baseline > 0:
        problem = f"the rectified baseline is not positive ({baseline:.4g} m)"
        raise ValueError(f"{problem}: the right camera must be to the right of the left one")
    fx, fy, cx, cy = (float(v) for v in projection[[0, 1, 0, 1], [0, 1, 2, 2]])
    try:
        return CameraConfig(fx=fx, fy=fy, cx=cx, cy=cy, width=size[0], height=size[1], baseline=float(baseline))
    except ValidationError as error:  # e.g. a focal length of 1e300 px
        raise ValueError(f"the rectified calibration gives camera.{describe_validation_error(error)}") from None


class StereoRectifier:
    """The rectified pair's calibration (`camera`) and the warp of raw images into it (`rectify`), with the maps
    precomputed. `identity`: the images need no warp and `rectify` returns them as given. `left_rotation` turns a
    vector from the raw left camera's optical frame into the rectified left camera's."""

    def __init__(
        self,
        camera: CameraConfig,
        size: tuple[int, int],
        maps: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None,
        left_rotation: np.ndarray,
    ) -> None:
        self.camera = camera
        self.size = size  # (width, height) of the raw images, which the rectified images keep
        self.left_rotation = left_rotation
        self._maps = maps

    @property
    def identity(self) -> bool:
        return self._maps is None

    @classmethod
    def from_extrinsics(
        cls, left: RawCamera, right: RawCamera, T_right_left: np.ndarray, alpha: float = 0.0
    ) -> StereoRectifier:
        """Rectify with `cv2.stereoRectify` (or `cv2.fisheye.stereoRectify`) from the pose between the cameras:
        `T_right_left` (4x4) takes a point from the left camera's optical frame to the right's (for a usual rig its
        translation is about (-baseline, 0, 0)). `alpha` in [0, 1]: 0 keeps only pixels that have a source in both
        raw images, 1 keeps every source pixel (the fisheye model's `balance`)."""
        fisheye = _pair_model(left, right)
        pose = _finite_array(T_right_left, (4, 4), "T_right_left")
        if not np.array_equal(pose[3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError("T_right_left's last row must be 0 0 0 1")
        rotation, translation = _rotation(pose[:3, :3], "T_right_left's rotation"), pose[:3, 3].copy()
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], not {alpha}")
        off_axis = np.abs(translation[1:]).max() <= IDENTITY_TOLERANCE * np.linalg.norm(translation)
        same = np.array_equal(left.K, right.K) and not left.distorted and not right.distorted
        if same and off_axis and _is_identity(rotation):
            return cls(_camera(left.K, left.size, -float(translation[0])), left.size, None, np.eye(3))
        if not np.linalg.norm(translation) > 0:
            raise ValueError("T_right_left has no translation: the two cameras are in one place")
        K1, D1, K2, D2, size = left.K, _coefficients(left), right.K, _coefficients(right), left.size
        if fisheye:
            flags = cv2.fisheye.CALIB_ZERO_DISPARITY
            R1, R2, P1, P2, _ = cv2.fisheye.stereoRectify(
                K1, D1, K2, D2, size, rotation, translation.reshape(3, 1), flags, balance=alpha, fov_scale=1.0
            )
        else:
            R1, R2, P1, P2, *_ = cv2.stereoRectify(
                K1, D1, K2, D2, size, rotation, translation.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha
            )
        return cls._warping(left, right, R1, R2, P1, P2)

    @classmethod
    def from_projections(
        cls,
        left: RawCamera,
        right: RawCamera,
        R_left: np.ndarray,
        R_right: np.ndarray,
        P_left: np.ndarray,
        P_right: np.ndarray,
    ) -> StereoRectifier:
        """Rectify as ROS's image_proc does from two CameraInfo messages: maps from K, D, R, P of each camera; the
        rectified intrinsics from P_left, the baseline from P_right[0, 3] = -fx * baseline (relative to
        P_left's)."""
        _pair_model(left, right)
        rotations = [_rotation(R, name) for R, name in ((R_left, "R_left"), (R_right, "R_right"))]
        projections = [_finite_array(P, (3, 4), name) for P, name in ((P_left, "P_left"), (P_right, "P_right"))]
        undistorted = not left.distorted and not right.distorted
        unrotated = all(_is_identity(R) for R in rotations)
        unprojected = all(np.array_equal(c.K, P[:, :3]) for c, P in zip((left, right), projections, strict=True))
        if undistorted and unrotated and unprojected and projections[1][1, 3] == 0:
            _check_shared_intrinsics(*projections)
            baseline = -(projections[1][0, 3] - projections[0][0, 3]) / projections[0][0, 0]
            return cls(_camera(projections[0], left.size, baseline), left.size, None, np.eye(3))
        return cls._warping(left, right, *rotations, *projections)

    @classmethod
    def _warping(
        cls, left: RawCamera, right: RawCamera, R1: np.ndarray, R2: np.ndarray, P1: np.ndarray, P2: np.ndarray
    ) -> StereoRectifier:
        """The rectifier of a computed (or given) rectification: camera from P1 and P2, maps from K, D, R, P."""
        if not (np.isfinite(P1).all() and np.isfinite(P2).all()):
            raise ValueError("the rectified calibration is not finite")
        _check_shared_intrinsics(P1, P2)
        if abs(P2[1, 3] - P1[1, 3]) > abs(P2[0, 3] - P1[0, 3]):
            raise ValueError("the right camera is above or below the left one: NeoSLAM needs a side-by-side pair")
        camera = _camera(P1, left.size, -(P2[0, 3] - P1[0, 3]) / P1[0, 0])
        maps = (_map(left, R1, P1), _map(right, R2, P2))
        return cls(camera, left.size, maps, np.array(R1, dtype=np.float64))

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rectified pair of a raw pair of grey uint8 images of the calibrated size (bilinear interpolation;
        pixels without a source are 0). A `ValueError` names both sizes when an image has another size."""
        self._check(left, "left")
        self._check(right, "right")
        if self._maps is None:
            return left, right
        return self._warp(left, 0), self._warp(right, 1)

    def rectify_left(self, left: np.ndarray) -> np.ndarray:
        """The rectified left image alone (what the detector sees)."""
        self._check(left, "left")
        return left if self._maps is None else self._warp(left, 0)

    def _warp(self, image: np.ndarray, side: int) -> np.ndarray:
        assert self._maps is not None
        first, second = self._maps[side]
        return cv2.remap(image, first, second, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def _check(self, image: np.ndarray, side: str) -> None:
        if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"the {side} image is not a grey uint8 image")
        height, width = image.shape
        if (width, height) != self.size:
            raise ValueError(
                f"the {side} image is {width}x{height}, the calibration's is {self.size[0]}x{self.size[1]}"
            )


def _pair_model(left: RawCamera, right: RawCamera) -> bool:
    """Whether the pair is fisheye; refuses two sizes and a fisheye camera beside a pinhole one."""
    if left.size != right.size:
        raise ValueError(f"the left image size {left.size} differs from the right's {right.size}")
    fisheye = {camera.model == "equidistant" for camera in (left, right)}
    if len(fisheye) > 1:
        raise ValueError("one camera is equidistant (fisheye) and the other is not: both need one model")
    return fisheye.pop()


def _check_shared_intrinsics(P_left: np.ndarray, P_right: np.ndarray) -> None:
    if not np.allclose(P_left[:, :3], P_right[:, :3], rtol=SAME_INTRINSICS_RTOL, atol=1e-6):
        raise ValueError("the two projection matrices differ in fx, fy, cx or cy: not a rectified pair")


def _map(camera: RawCamera, rotation: np.ndarray, projection: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The remap tables (fixed point) taking the raw camera's image to the rectified one."""
    make = cv2.fisheye.initUndistortRectifyMap if camera.model == "equidistant" else cv2.initUndistortRectifyMap
    first, second = make(camera.K, _coefficients(camera), rotation, projection, camera.size, MAP_TYPE)
    return first, second


def _coefficients(camera: RawCamera) -> np.ndarray | None:
    """The distortion coefficients as OpenCV takes them: none for an undistorted camera."""
    return camera.D if camera.D.size else None
