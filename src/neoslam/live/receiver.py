"""The live node's inputs: stereo image pairs matched by stamp, the cameras' calibration and optional odometry.

One thread of the node's own takes the samples Cyclone DDS has received (a wait set on the readers, never a DDS
listener: nothing runs on DDS's threads but DDS) and matches each left image with the right image of the nearest
stamp within the configured slop. The newest pair waits in a one-place mailbox for the SLAM loop; a pair that
arrives while another still waits replaces it and is counted as dropped, so a node slower than its camera works on
the newest frames and never builds a queue. Pixels are decoded only for the pairs the loop takes.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.util import duration

from neoslam.config.live import LiveConfig
from neoslam.datasets.bag_messages import MessageError, odometry_pose
from neoslam.geometry import interpolated_pose
from neoslam.live.camera import COMPRESSED_SUFFIX
from neoslam.live.conversions import NS_PER_S, stamp_ns
from neoslam.live.messages import CameraInfo, CompressedImage, Image, Odometry
from neoslam.live.transport import Ros2Domain, sensor_qos, taken

__all__ = [
    "StereoMessages",
    "NewestPair",
    "Counters",
    "StereoPairer",
    "OdometryBuffer",
    "Receiver",
    "image_type",
    "info_topic",
]

WAIT_S = 0.05  # the receiving thread wakes at least this often to see whether the node stops
ODOMETRY_KEPT = 2000  # odometry messages kept for matching to image stamps (200 s at 10 Hz)


def image_type(topic: str) -> type:
    """sensor_msgs/CompressedImage for a topic named .../compressed (image_transport's convention), else Image."""
    return CompressedImage if topic.endswith(COMPRESSED_SUFFIX) else Image


def info_topic(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic: /ns/image_raw (or /ns/image_raw/compressed) -> /ns/camera_info."""
    namespace = image_topic.removesuffix(COMPRESSED_SUFFIX).rpartition("/")[0]
    return f"{namespace}/camera_info"


@dataclass(frozen=True)
class StereoMessages:
    """A left and a right image message taken at one time, as received."""

    stamp_ns: int  # the left image's header stamp
    left: Any
    right: Any
    received_s: float  # time.monotonic() when the pair was complete (the later of the two arrived)


@dataclass
class Counters:
    """What the receiver has seen since it started (read by the node for its status and exit summary)."""

    left: int = 0
    right: int = 0
    pairs: int = 0
    dropped: int = 0  # pairs replaced by a newer one before the node took them
    unpaired: int = 0  # images that found no partner within the slop
    out_of_order: int = 0  # pairs not newer than the last one handed on (a replay restarted)
    odometry: int = 0
    bad_messages: int = 0
    first_bad: str = ""


class NewestPair:
    """A mailbox of one place: `put` replaces what waits (counting it dropped), `take` waits for something."""

    def __init__(self, counters: Counters) -> None:
        self._counters = counters
        self._pair: StereoMessages | None = None
        self._ready = threading.Condition()

    def put(self, pair: StereoMessages) -> None:
        with self._ready:
            if self._pair is not None:
                self._counters.dropped += 1
            self._pair = pair
            self._ready.notify()

    def take(self, timeout_s: float) -> StereoMessages | None:
        with self._ready:
            if self._pair is None:
                self._ready.wait(timeout_s)
            pair, self._pair = self._pair, None
            return pair


class StereoPairer:
    """Matches left and right images by stamp: an image pairs with the other camera's waiting image of the nearest
    stamp within `slop_ns`; a pair goes to the mailbox unless it is not newer than the last one (counted out of
    order). Images older than a pair just made are forgotten (counted unpaired), and each camera keeps at most
    `depth` images waiting, so a camera whose partner has stopped holds no growing backlog."""

    def __init__(self, slop_ns: int, depth: int, counters: Counters, mailbox: NewestPair) -> None:
        self.slop_ns = slop_ns
        self.depth = depth
        self.counters = counters
        self.mailbox = mailbox
        self._waiting: dict[str, dict[int, Any]] = {"left": {}, "right": {}}
        self._last_stamp: int | None = None

    def add(self, side: str, message: Any, stamp: int, now: float) -> None:
        """One image of `side` (left or right) with its header stamp (ns), received at monotonic time `now`."""
        setattr(self.counters, side, getattr(self.counters, side) + 1)
        other = self._waiting["right" if side == "left" else "left"]
        partner = min(other, key=lambda s: abs(s - stamp), default=None)
        if partner is None or abs(partner - stamp) > self.slop_ns:
            self._waiting[side][stamp] = message
            self._bound(side)
            return
        partner_message = other.pop(partner)
        left_stamp = stamp if side == "left" else partner
        left, right = (message, partner_message) if side == "left" else (partner_message, message)
        self._forget_older(left_stamp)
        if self._last_stamp is not None and left_stamp <= self._last_stamp:
            self.counters.out_of_order += 1
            return
        self._last_stamp = left_stamp
        self.counters.pairs += 1
        self.mailbox.put(StereoMessages(left_stamp, left, right, now))

    def _forget_older(self, stamp: int) -> None:
        for waiting in self._waiting.values():
            older = [s for s in waiting if s < stamp - self.slop_ns]
            for s in older:
                del waiting[s]
            self.counters.unpaired += len(older)

    def _bound(self, side: str) -> None:
        waiting = self._waiting[side]
        while len(waiting) > self.depth:
            del waiting[min(waiting)]
            self.counters.unpaired += 1


class OdometryBuffer:
    """Recent odometry poses by stamp (ns), sorted; thread-safe."""

    def __init__(self) -> None:
        self._samples: deque[tuple[int, np.ndarray]] = deque(maxlen=ODOMETRY_KEPT)
        self._lock = threading.Lock()

    def add(self, stamp: int, pose: np.ndarray) -> None:
        with self._lock:
            if self._samples and stamp <= self._samples[-1][0]:
                return  # an older or repeated stamp: out of order, kept out so that the buffer stays sorted
            self._samples.append((stamp, pose))

    def newest_stamp(self) -> int | None:
        with self._lock:
            return self._samples[-1][0] if self._samples else None

    def pose_at(self, stamp: int, tolerance_ns: int) -> np.ndarray | None:
        with self._lock:
            if not self._samples:
                return None
            times = np.fromiter((s for s, _ in self._samples), dtype=np.int64, count=len(self._samples))
            poses = np.stack([p for _, p in self._samples])
        return interpolated_pose(times, poses, stamp, tolerance_ns)


class Receiver:
    """Subscribes to the cameras (images and CameraInfo) and optionally odometry, and pairs the images in a thread
    of its own: `start`, then `mailbox.take`, `camera_infos()`, `odometry.pose_at`; `stop` ends the thread."""

    def __init__(self, domain: Ros2Domain, config: LiveConfig) -> None:
        self.config = config
        self.topics = {
            "left": config.left_topic,
            "right": config.right_topic,
            "left_info": config.left_info_topic or info_topic(config.left_topic),
            "right_info": config.right_info_topic or info_topic(config.right_topic),
        }
        if config.odometry_topic is not None:
            self.topics["odometry"] = config.odometry_topic
        qos = sensor_qos(config.sensor_depth)
        types = {"left": image_type(config.left_topic), "right": image_type(config.right_topic)}
        types |= {"left_info": CameraInfo, "right_info": CameraInfo, "odometry": Odometry}
        self._readers = {role: domain.reader(topic, types[role], qos) for role, topic in self.topics.items()}
        self.image_types = {side: types[side] for side in ("left", "right")}
        self.counters = Counters()
        self.mailbox = NewestPair(self.counters)
        self.odometry = OdometryBuffer()
        self._infos: dict[str, Any] = {}
        self.pairer = StereoPairer(
            round(config.pair_slop_s * NS_PER_S), config.sensor_depth, self.counters, self.mailbox
        )
        self._stopping = threading.Event()
        self._lock = threading.Lock()
        self._waitset = WaitSet(domain.participant)
        mask = SampleState.NotRead | ViewState.Any | InstanceState.Any
        for reader in self._readers.values():
            self._waitset.attach(ReadCondition(reader, mask))
        self._thread = threading.Thread(target=self._run, name="neoslam-ros2-receiver", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stopping.set()
        self._thread.join(timeout=1.0)

    def camera_infos(self) -> tuple[Any, Any] | None:
        """The latest left and right CameraInfo, once both have come."""
        with self._lock:
            left, right = self._infos.get("left_info"), self._infos.get("right_info")
        return None if left is None or right is None else (left, right)

    def _run(self) -> None:
        wait = duration(seconds=WAIT_S)
        while not self._stopping.is_set():
            self._waitset.wait(wait)
            for role, reader in self._readers.items():
                for sample in taken(reader, self.config.sensor_depth * 2):
                    self._receive(role, sample, time.monotonic())

    def _receive(self, role: str, sample: Any, now: float) -> None:
        if role in ("left_info", "right_info"):
            with self._lock:
                self._infos[role] = sample
        elif role == "odometry":
            self._odometry(sample)
        else:
            self._image(role, sample, now)

    def _odometry(self, message: Odometry) -> None:
        try:
            pose = odometry_pose(message)
        except MessageError as error:
            self._bad(f"{self.topics['odometry']}: {error}")
            return
        self.counters.odometry += 1
        self.odometry.add(stamp_ns(message.header), pose)

    def _bad(self, what: str) -> None:
        self.counters.bad_messages += 1
        if not self.counters.first_bad:
            self.counters.first_bad = what

    def _image(self, side: str, message: Any, now: float) -> None:
        self.pairer.add(side, message, stamp_ns(message.header), now)
