"""ROS messages turned into what NeoSLAM reads: header stamps, grey images, the stereo calibration, odometry poses.

The functions take rosbags' deserialised messages, whose field names follow the bag's own definitions (ROS 1's
CameraInfo has `K` and `P`, ROS 2's `k` and `p`). A message NeoSLAM cannot use raises `MessageError`; the bag
reader adds the bag, topic and message index to make it one line for the user.
"""

from __future__ import annotations

import struct
from typing import Any

import cv2
import numpy as np
from pydantic import ValidationError

from neoslam.config import CameraConfig, describe_validation_error
from neoslam.geometry import pose_from_quaternion
from neoslam.io.image_header import oversized

__all__ = [
    "IMAGE_TYPE",
    "COMPRESSED_IMAGE_TYPE",
    "CAMERA_INFO_TYPE",
    "ODOMETRY_TYPE",
    "GREY_ENCODINGS",
    "MessageError",
    "header_stamp_ns",
    "grey_image",
    "stereo_camera",
    "odometry_pose",
]

IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE_TYPE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"

NS_PER_S = 1_000_000_000
# Encoding -> (channels, OpenCV conversion to grey; None: already grey). ROS names a Bayer pattern by its first
# row, OpenCV by its second, hence the crossed names (cv_bridge's mapping). cv_bridge also reads 8UC3 as bgr8.
GREY_ENCODINGS: dict[str, tuple[int, int | None]] = {
    "mono8": (1, None),
    "8UC1": (1, None),
    "bgr8": (3, cv2.COLOR_BGR2GRAY),
    "8UC3": (3, cv2.COLOR_BGR2GRAY),
    "rgb8": (3, cv2.COLOR_RGB2GRAY),
    "bgra8": (4, cv2.COLOR_BGRA2GRAY),
    "8UC4": (4, cv2.COLOR_BGRA2GRAY),
    "rgba8": (4, cv2.COLOR_RGBA2GRAY),
    "bayer_rggb8": (1, cv2.COLOR_BayerBG2GRAY),
    "bayer_bggr8": (1, cv2.COLOR_BayerRG2GRAY),
    "bayer_gbrg8": (1, cv2.COLOR_BayerGR2GRAY),
    "bayer_grbg8": (1, cv2.COLOR_BayerGB2GRAY),
}
# Two rectified cameras of one stereo rig share their intrinsics in P; more than this relative difference means
# the two topics are not the two halves of a rectified pair.
SAME_INTRINSICS_RTOL = 1e-3
PROJECTION_SHAPE = (3, 4)
# A quaternion further than this from unit length is not a rotation written with float64 round-off.
UNIT_QUATERNION_TOLERANCE = 1e-3


class MessageError(ValueError):
    """A message NeoSLAM cannot use (unsupported encoding, inconsistent sizes, missing calibration...)."""


def header_stamp_ns(raw: bytes | memoryview, ros1: bool) -> int:
    """The header stamp of a serialised stamped message (Image, CompressedImage, CameraInfo, Odometry), in ns.

    Read from the raw bytes, without decoding the message: indexing a bag of images then reads no pixels into
    Python objects. ROS 1: the header starts with seq (uint32), then the stamp (uint32 sec, uint32 nsec). ROS 2
    (CDR): a 4-byte encapsulation header whose second byte is odd for little-endian data, then the stamp (int32
    sec, uint32 nanosec)."""
    try:
        if ros1:
            seconds, nanoseconds = struct.unpack_from("<II", raw, 4)
        else:
            order = "<" if raw[1] & 1 else ">"
            seconds, nanoseconds = struct.unpack_from(f"{order}iI", raw, 4)
    except (struct.error, IndexError):
        raise MessageError(f"message of {len(raw)} bytes is too short for a header") from None
    return seconds * NS_PER_S + nanoseconds


def grey_image(message: Any, msgtype: str) -> np.ndarray:
    """An 8-bit grey image (a fresh, writable array) from an Image or CompressedImage message."""
    if msgtype == COMPRESSED_IMAGE_TYPE:
        return _grey_from_compressed(message)
    return _grey_from_raw(message)


def _octets(data: Any) -> np.ndarray:
    """A message's uint8[] field as a flat uint8 array: rosbags gives an array, a live DDS sample bytes."""
    if isinstance(data, bytes | bytearray | memoryview):
        return np.frombuffer(data, dtype=np.uint8)
    return np.asarray(data, dtype=np.uint8).reshape(-1)


def _grey_from_raw(message: Any) -> np.ndarray:
    encoding = message.encoding
    if encoding not in GREY_ENCODINGS:
        raise MessageError(f"unsupported image encoding {encoding!r} (supported: {', '.join(GREY_ENCODINGS)})")
    channels, conversion = GREY_ENCODINGS[encoding]
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = _octets(message.data)
    if height <= 0 or width <= 0 or step < width * channels or data.size < step * height:
        raise MessageError(f"image data ({data.size} bytes, step {step}) does not hold {width}x{height} {encoding}")
    # Rows may be padded beyond width x channels bytes: `step` is the stride.
    rows = data[: step * height].reshape(height, step)[:, : width * channels]
    pixels = rows.reshape(height, width, channels) if channels > 1 else rows
    if conversion is None:
        return np.array(pixels, dtype=np.uint8, order="C")  # a copy: the message may view the bag's buffer
    return cv2.cvtColor(np.ascontiguousarray(pixels), conversion)


def _grey_from_compressed(message: Any) -> np.ndarray:
    fmt = str(message.format)
    if "compresseddepth" in fmt.lower():
        raise MessageError(f"unsupported image format {fmt!r} (a depth image, not a camera image)")
    data = _octets(message.data)
    too_large = oversized(data[: 1 << 20].tobytes())
    if too_large is not None:
        raise MessageError(f"compressed image: {too_large}")
    grey = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
    if grey is None:
        raise MessageError(f"compressed image (format {fmt!r}, {data.size} bytes) cannot be decoded")
    return grey


def _projection(info: Any) -> np.ndarray:
    values = info.p if hasattr(info, "p") else info.P
    projection = np.asarray(values, dtype=np.float64).reshape(-1)
    if projection.size != np.prod(PROJECTION_SHAPE) or not np.isfinite(projection).all():
        raise MessageError("CameraInfo's projection matrix P is not 12 finite numbers")
    return projection.reshape(PROJECTION_SHAPE)


def stereo_camera(left_info: Any, right_info: Any, image_size: tuple[int, int]) -> CameraConfig:
    """The rectified stereo calibration: fx, fy, cx, cy from the left camera's P, the baseline from the right's
    (P_right = K [I | -b e_x], so its fourth column holds -fx b), the size from the left CameraInfo (or, where that
    leaves it 0, from the first image: `image_size` = (width, height))."""
    left, right = _projection(left_info), _projection(right_info)
    fx, fy, cx, cy = left[0, 0], left[1, 1], left[0, 2], left[1, 2]
    if fx <= 0 or fy <= 0:
        raise MessageError(f"the left CameraInfo has no calibration (P gives focal lengths {fx:g}, {fy:g})")
    if not np.allclose(left[:, :3], right[:, :3], rtol=SAME_INTRINSICS_RTOL, atol=1e-6):
        raise MessageError("the two CameraInfo projection matrices differ in fx, fy, cx or cy: not a rectified pair")
    baseline = -(right[0, 3] - left[0, 3]) / fx  # as KITTI's calib.txt is read, so a converted KITTI run matches
    if baseline <= 0:
        raise MessageError(f"the right CameraInfo's P gives a non-positive baseline ({baseline:.4f} m)")
    width = int(left_info.width) or image_size[0]
    height = int(left_info.height) or image_size[1]
    try:
        return CameraConfig(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height, baseline=baseline)
    except ValidationError as error:  # e.g. a focal length of 1e300 px
        raise MessageError(f"the CameraInfo calibration gives camera.{describe_validation_error(error)}") from None


def odometry_pose(message: Any) -> np.ndarray:
    """T_odom_base (4x4) of a nav_msgs/Odometry message. ROS bodies follow REP-103 (x forward, y left, z up), as
    NeoSLAM's robot frame does, so the pose is used as it is."""
    pose = message.pose.pose
    translation = np.array([pose.position.x, pose.position.y, pose.position.z], dtype=np.float64)
    quaternion = np.array(
        [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w], dtype=np.float64
    )
    if not np.isfinite(translation).all():
        raise MessageError(f"odometry position is not finite ({', '.join(f'{v:g}' for v in translation)})")
    if not np.isfinite(quaternion).all():
        raise MessageError(f"odometry orientation is not finite ({', '.join(f'{v:g}' for v in quaternion)})")
    norm = float(np.linalg.norm(quaternion))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise MessageError(f"odometry orientation is not a unit quaternion (norm {norm:.4f})")
    return pose_from_quaternion(translation, quaternion)[0]  # scipy normalises the quaternion
