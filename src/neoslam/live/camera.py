"""A live stereo camera's calibration from its two CameraInfo messages, and its images as rectified grey pairs.

ROS's CameraInfo describes the raw camera (K, D and the distortion model) and the rectified one (R, P). Raw images
are rectified with image_proc's maps from K, D, R, P (neoslam.perception.rectification); rectified images (an
`image_rect` topic, or `live.images: rectified`) are used as they come, calibrated by P as a bag's are. With
`live.images: auto`, a CameraInfo whose D is zero, R the identity and P's left 3x3 equal to K needs no warp either,
so a driver that publishes rectified images under another name still gives the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from neoslam.config import CameraConfig
from neoslam.config.live import LiveConfig
from neoslam.datasets.bag_messages import COMPRESSED_IMAGE_TYPE, IMAGE_TYPE, MessageError, grey_image, stereo_camera
from neoslam.live.messages import CompressedImage
from neoslam.perception.rectification import RawCamera, StereoRectifier

__all__ = ["LiveCamera", "live_camera"]

RECTIFIED_NAME = "rect"  # image_proc names rectified topics image_rect, image_rect_color
COMPRESSED_SUFFIX = "/compressed"  # image_transport's compressed topic beside an image topic
# ROS distortion models and the rectifier's: rational_polynomial's 8 coefficients are OpenCV's standard model too
DISTORTION_MODELS = {"plumb_bob": "plumb_bob", "rational_polynomial": "plumb_bob", "equidistant": "equidistant"}


@dataclass(frozen=True)
class LiveCamera:
    """The rectified pair's calibration and how a received pair becomes two rectified grey images."""

    camera: CameraConfig
    rectifier: StereoRectifier | None  # None: the images are rectified already
    message_types: tuple[str, str]  # the ROS type of the left and right image messages

    def grey_pair(self, left: Any, right: Any) -> tuple[np.ndarray, np.ndarray]:
        """Decode both images to 8-bit grey, check their size and rectify them."""
        images = [grey_image(message, kind) for message, kind in zip((left, right), self.message_types, strict=True)]
        expected = (self.camera.height, self.camera.width)
        for side, image in zip(("left", "right"), images, strict=True):
            if image.shape != expected:
                size = f"{image.shape[1]}x{image.shape[0]}"
                raise MessageError(f"the {side} image is {size}, its CameraInfo says {expected[1]}x{expected[0]}")
        if self.rectifier is None or self.rectifier.identity:
            return images[0], images[1]
        return self.rectifier.rectify(images[0], images[1])


def _raw_camera(info: Any, size: tuple[int, int], side: str) -> RawCamera:
    model = str(info.distortion_model)
    coefficients = np.asarray(info.d, dtype=np.float64)
    if model not in DISTORTION_MODELS and coefficients.any():
        known = ", ".join(DISTORTION_MODELS)
        raise MessageError(f"the {side} CameraInfo's distortion model {model!r} is not one of {known}")
    chosen = DISTORTION_MODELS.get(model, "none")
    try:
        return RawCamera(np.asarray(info.k, dtype=np.float64).reshape(3, 3), coefficients, chosen, size)
    except ValueError as error:
        raise MessageError(f"the {side} CameraInfo: {error}") from None


def _image_size(info: Any, first_image: tuple[int, int]) -> tuple[int, int]:
    """(width, height) from the CameraInfo, or from the first image where the CameraInfo leaves them 0."""
    return int(info.width) or first_image[0], int(info.height) or first_image[1]


def _said_rectified(config: LiveConfig) -> bool:
    """live.images, or with auto whether both image topics are named rectified (/ns/image_rect[/compressed])."""
    if config.images != "auto":
        return config.images == "rectified"
    names = (
        topic.removesuffix(COMPRESSED_SUFFIX).rpartition("/")[2] for topic in (config.left_topic, config.right_topic)
    )
    return all(RECTIFIED_NAME in name for name in names)


def live_camera(
    config: LiveConfig, left_info: Any, right_info: Any, image_types: tuple[type, type], first_image: tuple[int, int]
) -> LiveCamera:
    """The stereo calibration of two CameraInfo messages (raising MessageError with what is wrong).
    `first_image` is the (width, height) of the first left image, for a CameraInfo that leaves its size 0."""
    kinds = tuple(COMPRESSED_IMAGE_TYPE if kind is CompressedImage else IMAGE_TYPE for kind in image_types)
    size = _image_size(left_info, first_image)
    if _said_rectified(config):
        return LiveCamera(stereo_camera(left_info, right_info, size), None, kinds)  # type: ignore[arg-type]
    cameras = [_raw_camera(info, size, side) for info, side in ((left_info, "left"), (right_info, "right"))]
    rotations = [np.asarray(info.r, dtype=np.float64).reshape(3, 3) for info in (left_info, right_info)]
    projections = [np.asarray(info.p, dtype=np.float64).reshape(3, 4) for info in (left_info, right_info)]
    try:
        rectifier = StereoRectifier.from_projections(*cameras, *rotations, *projections)
    except ValueError as error:
        raise MessageError(f"the CameraInfo pair cannot be rectified: {error}") from None
    return LiveCamera(rectifier.camera, rectifier, kinds)  # type: ignore[arg-type]
