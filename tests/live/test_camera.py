"""A live camera's calibration from CameraInfo: rectified images used as they come, raw ones rectified."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from neoslam.config import CameraConfig
from neoslam.config.live import LiveConfig
from neoslam.datasets.bag_messages import MessageError
from neoslam.live.camera import live_camera
from neoslam.live.messages import CameraInfo, Image
from neoslam.live.player import camera_infos, image_message

CAMERA = CameraConfig(fx=700.0, fy=700.0, cx=320.0, cy=240.0, width=640, height=480, baseline=0.5)
IMAGES = (Image, Image)


def _texture(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (0, 0), 2)


def test_a_rectified_pair_is_calibrated_by_p_and_its_pixels_pass_untouched() -> None:
    left_info, right_info = camera_infos(CAMERA, 0, ("l", "r"))
    camera = live_camera(LiveConfig(), left_info, right_info, IMAGES, (640, 480))
    assert camera.camera == CAMERA
    image = _texture()
    left, right = camera.grey_pair(image_message(image, 0, "l", False), image_message(image, 0, "r", False))
    assert np.array_equal(left, image) and np.array_equal(right, image)


def _raw_infos(distortion: list[float]) -> tuple[CameraInfo, CameraInfo]:
    """A raw stereo pair calibrated as camera_calibration writes it: K, D, and R, P from stereoRectify."""
    K = np.array([[690.0, 0, 330], [0, 692, 236], [0, 0, 1]])
    D = np.array(distortion)
    rotation = cv2.Rodrigues(np.array([0.0, 0.01, 0.002]))[0]
    translation = np.array([[-0.5], [0.004], [0.0]])
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K, D, K, D, (640, 480), rotation, translation, alpha=0)
    infos = []
    for R, P in ((R1, P1), (R2, P2)):
        infos.append(CameraInfo(height=480, width=640, distortion_model="plumb_bob", d=list(D),
                                k=list(K.ravel()), r=list(R.ravel()), p=list(P.ravel())))  # fmt: skip
    return infos[0], infos[1]


def test_raw_images_are_rectified_with_the_camera_infos_k_d_r_p() -> None:
    left_info, right_info = _raw_infos([-0.28, 0.07, 0.0002, 0.00002, 0.0])
    camera = live_camera(LiveConfig(), left_info, right_info, IMAGES, (640, 480))
    assert camera.rectifier is not None and not camera.rectifier.identity
    assert camera.camera.baseline == pytest.approx(0.5, rel=0.01)
    image = _texture()
    left, right = camera.grey_pair(image_message(image, 0, "l", False), image_message(image, 0, "r", False))
    assert left.shape == image.shape and not np.array_equal(left, image)


def test_images_said_rectified_are_not_warped_whatever_the_camera_info_says() -> None:
    left_info, right_info = _raw_infos([-0.28, 0.07, 0.0002, 0.00002, 0.0])
    config = LiveConfig(left_topic="/left/image_rect", right_topic="/right/image_rect")
    camera = live_camera(config, left_info, right_info, IMAGES, (640, 480))
    assert camera.rectifier is None


def test_an_image_of_another_size_than_its_camera_info_is_refused_in_one_sentence() -> None:
    left_info, right_info = camera_infos(CAMERA, 0, ("l", "r"))
    camera = live_camera(LiveConfig(), left_info, right_info, IMAGES, (640, 480))
    small = np.zeros((240, 320), dtype=np.uint8)
    with pytest.raises(MessageError, match="the left image is 320x240, its CameraInfo says 640x480"):
        camera.grey_pair(image_message(small, 0, "l", False), image_message(small, 0, "r", False))


def test_a_camera_info_without_calibration_is_refused_in_one_sentence() -> None:
    with pytest.raises(MessageError, match="no calibration"):
        live_camera(LiveConfig(images="rectified"), CameraInfo(), CameraInfo(), IMAGES, (640, 480))
    with pytest.raises(MessageError, match="left CameraInfo"):
        live_camera(LiveConfig(), CameraInfo(), CameraInfo(), IMAGES, (640, 480))
