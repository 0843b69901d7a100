"""Which topics of a ROS bag NeoSLAM reads: the left and right camera images, the CameraInfo beside each, and
optionally the odometry. Found by name and message type when unambiguous; otherwise one line lists the candidates
and names the option (--left-topic, --right-topic, --odometry-topic) that chooses."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from neoslam.datasets.bag_messages import CAMERA_INFO_TYPE, COMPRESSED_IMAGE_TYPE, IMAGE_TYPE, ODOMETRY_TYPE
from neoslam.errors import InputError

__all__ = ["BagTopics", "IMAGE_TYPES", "choose_topics"]

IMAGE_TYPES = (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE)
# Words that name a camera of a stereo rig in common topic names: /stereo/left/image_rect, /cam0/image_raw
# (EuRoC), /camera/infra1/image_rect_raw (RealSense), /kitti/camera_gray_left/image_raw.
SIDE_WORDS = {"left": frozenset({"left", "cam0", "infra1"}), "right": frozenset({"right", "cam1", "infra2"})}


@dataclass(frozen=True)
class BagTopics:
    left: str
    right: str
    left_info: str
    right_info: str
    odometry: str | None = None


def _side_of(topic: str) -> str | None:
    words = set(re.split(r"[/_.\-]", topic.lower()))
    sides = [side for side, names in SIDE_WORDS.items() if words & names]
    return sides[0] if len(sides) == 1 else None


def _listing(topics: dict[str, str], types: tuple[str, ...]) -> str:
    found = [f"{name} ({msgtype.rsplit('/', 1)[-1]})" for name, msgtype in sorted(topics.items()) if msgtype in types]
    return ", ".join(found) or "none"


def _image_topic(path: Path, topics: dict[str, str], side: str, given: str | None) -> str:
    images = _listing(topics, IMAGE_TYPES)
    if given is not None:
        if topics.get(given) not in IMAGE_TYPES:
            problem = f"--{side}-topic {given} is not an Image or CompressedImage topic (images: {images})"
            raise InputError(path, problem)
        return given
    candidates = [name for name, msgtype in topics.items() if msgtype in IMAGE_TYPES and _side_of(name) == side]
    if len(candidates) != 1:
        raise InputError(path, f"cannot tell the {side} camera's topic: choose with --{side}-topic (images: {images})")
    return candidates[0]


def _camera_info_topic(path: Path, topics: dict[str, str], image_topic: str) -> str:
    """The CameraInfo topic in the image topic's namespace (/ns/image_raw -> /ns/camera_info), the deepest one."""
    infos = [name for name, msgtype in topics.items() if msgtype == CAMERA_INFO_TYPE]
    beside = [name for name in infos if image_topic.startswith(name.rsplit("/", 1)[0] + "/")]
    if not beside:
        listing = ", ".join(sorted(infos)) or "none"
        problem = f"no CameraInfo topic beside {image_topic}: its calibration is needed (CameraInfo topics: {listing})"
        raise InputError(path, problem)
    return max(beside, key=lambda name: name.count("/"))


def _odometry_topic(path: Path, topics: dict[str, str], given: str | None, wanted: bool) -> str | None:
    listing = _listing(topics, (ODOMETRY_TYPE,))
    if given is not None:
        if topics.get(given) != ODOMETRY_TYPE:
            raise InputError(path, f"--odometry-topic {given} is not a nav_msgs/Odometry topic (odometry: {listing})")
        return given
    if not wanted:
        return None
    candidates = [name for name, msgtype in topics.items() if msgtype == ODOMETRY_TYPE]
    if len(candidates) != 1:
        raise InputError(path, f"cannot tell the odometry topic: choose with --odometry-topic (odometry: {listing})")
    return candidates[0]


def choose_topics(
    path: Path,
    topics: dict[str, str],
    left: str | None = None,
    right: str | None = None,
    odometry: str | None = None,
    odometry_wanted: bool = False,
) -> BagTopics:
    """The bag's topics to read, from its {topic: message type}; one line listing the candidates when a choice is
    ambiguous or a named topic is not there."""
    left = _image_topic(path, topics, "left", left)
    right = _image_topic(path, topics, "right", right)
    if left == right:
        raise InputError(path, f"the left and right images are both {left}: name two topics")
    left_info, right_info = _camera_info_topic(path, topics, left), _camera_info_topic(path, topics, right)
    if left_info == right_info:
        raise InputError(path, f"{left} and {right} share the CameraInfo topic {left_info}: each camera needs its own")
    return BagTopics(left, right, left_info, right_info, _odometry_topic(path, topics, odometry, odometry_wanted))
