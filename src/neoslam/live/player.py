"""A stereo sequence played on ROS 2 topics as a stereo camera driver publishes it: per frame a left and a right
sensor_msgs/Image (mono8; or CompressedImage, PNG) and the CameraInfo beside each, all with the frame's stamp.

The images are the sequence's rectified ones, so the CameraInfo describes a rectified pair: D empty, R the
identity, K the rectified intrinsics and P = K [I | -b e_x] for the right camera (what a driver publishes for
rectified images; the node reads them as they are). Frames are sent on a fixed schedule (`rate_hz`) or as fast as
they can be read and written, and each frame's send time is kept for latency measurements.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from neoslam.config import CameraConfig
from neoslam.config.live import LiveConfig
from neoslam.errors import InputError
from neoslam.live.conversions import NS_PER_S, time_message
from neoslam.live.messages import CameraInfo, CompressedImage, Header, Image
from neoslam.live.receiver import image_type, info_topic
from neoslam.live.transport import Ros2Domain, sensor_qos
from neoslam.perception.frontend import StereoSequence

__all__ = ["PlayReport", "play_sequence", "camera_infos", "image_message"]

WAIT_POLL_S = 0.05
DISTORTION_MODEL = "plumb_bob"
PNG = ".png"


@dataclass
class PlayReport:
    """What was played: frames sent, with each frame's stamp and the monotonic time it was written."""

    stamps_ns: list[int] = field(default_factory=list)
    sent_s: list[float] = field(default_factory=list)
    subscribers: int = 0  # readers of the left image topic when playing started

    @property
    def frames(self) -> int:
        return len(self.stamps_ns)


def camera_infos(camera: CameraConfig, nanoseconds: int, frames: tuple[str, str]) -> tuple[CameraInfo, CameraInfo]:
    """The CameraInfo of a rectified stereo pair, left and right."""
    k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    infos = []
    for frame_id, shift in zip(frames, (0.0, -camera.fx * camera.baseline), strict=True):
        p = [camera.fx, 0.0, camera.cx, shift, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        header = Header(stamp=time_message(nanoseconds), frame_id=frame_id)
        infos.append(
            CameraInfo(
                header=header,
                height=camera.height,
                width=camera.width,
                distortion_model=DISTORTION_MODEL,
                d=[],
                k=k,
                r=identity,
                p=p,
            )  # fmt: skip
        )
    return infos[0], infos[1]


def image_message(image: np.ndarray, nanoseconds: int, frame_id: str, compressed: bool) -> Image | CompressedImage:
    """A grey image as sensor_msgs/Image (mono8) or CompressedImage (PNG, lossless)."""
    header = Header(stamp=time_message(nanoseconds), frame_id=frame_id)
    if compressed:
        ok, encoded = cv2.imencode(PNG, image)
        if not ok:
            raise ValueError("the image could not be encoded as PNG")
        return CompressedImage(header=header, format="mono8; png compressed", data=encoded.tobytes())
    height, width = image.shape
    data = np.ascontiguousarray(image, dtype=np.uint8).tobytes()
    return Image(header=header, height=height, width=width, encoding="mono8", is_bigendian=0, step=width, data=data)


def _stamps_ns(sequence: StereoSequence) -> np.ndarray:
    stamps = np.round(np.asarray(sequence.timestamps, dtype=np.float64) * NS_PER_S).astype(np.int64)
    if len(stamps) > 1 and (np.diff(stamps) <= 0).any():
        raise InputError(sequence.name, "the frames' times do not increase: they cannot be stamps of a camera")
    return stamps


def play_sequence(
    sequence: StereoSequence,
    domain: Ros2Domain,
    config: LiveConfig,
    stop: threading.Event,
    rate_hz: float | None = None,
    compressed: bool = False,
    wait_for_subscribers_s: float = 0.0,
    frames: range | None = None,
) -> PlayReport:
    """Publish the sequence's frames (all, or `frames`) on the configured camera topics, each frame's images and
    CameraInfo stamped with its time; at `rate_hz` frames a second (None: as fast as possible). With
    `wait_for_subscribers_s`, first wait that long at most for a reader of both image topics."""
    qos = sensor_qos(config.sensor_depth)
    image_kind = CompressedImage if compressed else Image
    left_topic = _topic(config.left_topic, compressed)
    right_topic = _topic(config.right_topic, compressed)
    writers = {
        "left": domain.writer(left_topic, image_kind, qos),
        "right": domain.writer(right_topic, image_kind, qos),
        "left_info": domain.writer(config.left_info_topic or info_topic(config.left_topic), CameraInfo, qos),
        "right_info": domain.writer(config.right_info_topic or info_topic(config.right_topic), CameraInfo, qos),
    }
    report = PlayReport(subscribers=_wait_for_readers(writers, wait_for_subscribers_s, stop))
    stamps = _stamps_ns(sequence)
    chosen = frames if frames is not None else range(len(sequence))
    frame_ids = ("camera_left", "camera_right")
    start = time.monotonic()
    for number, index in enumerate(chosen):
        if stop.is_set():
            break
        if rate_hz is not None:
            _sleep_until(start + number / rate_hz, stop)
        left, right = sequence.stereo_pair(index)
        stamp = int(stamps[index])
        left_info, right_info = camera_infos(sequence.camera, stamp, frame_ids)
        writers["left_info"].write(left_info)
        writers["right_info"].write(right_info)
        writers["left"].write(image_message(left, stamp, frame_ids[0], compressed))
        writers["right"].write(image_message(right, stamp, frame_ids[1], compressed))
        report.stamps_ns.append(stamp)
        report.sent_s.append(time.monotonic())
    return report


def _topic(topic: str, compressed: bool) -> str:
    """The image topic to publish on: image_transport's `/compressed` beside it when compressed (if not given)."""
    if compressed and image_type(topic) is not CompressedImage:
        return f"{topic}/compressed"
    return topic


def _wait_for_readers(writers: dict, timeout_s: float, stop: threading.Event) -> int:
    """Wait up to `timeout_s` for a reader on both image topics; the left topic's reader count."""
    deadline = time.monotonic() + timeout_s
    while True:
        counts = [writers[side].get_publication_matched_status().current_count for side in ("left", "right")]
        if min(counts) > 0 or time.monotonic() >= deadline or stop.is_set():
            return counts[0]
        time.sleep(WAIT_POLL_S)


def _sleep_until(moment: float, stop: threading.Event) -> None:
    remaining = moment - time.monotonic()
    if remaining > 0:
        stop.wait(remaining)
