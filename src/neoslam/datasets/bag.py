"""ROS 1 and ROS 2 bags as stereo sequences, read with rosbags (pure Python, no ROS install).

Accepted: a ROS 1 `.bag` file, a ROS 2 bag folder (`metadata.yaml` with sqlite3 or mcap storage) or a bare ROS 2
`.db3` / `.mcap` file. What is read: the left and right camera's `sensor_msgs/Image` or `CompressedImage` topic
(rectified images), the `CameraInfo` topic beside each (fx, fy, cx, cy from the left's P, the baseline from the
right's), and optionally a `nav_msgs/Odometry` topic as the motion source instead of stereo odometry.

Opening a bag indexes it: every image's header stamp (read from the raw bytes, no pixels decoded), the stereo pairs
(mutually nearest stamps within `perception.bag.pair_tolerance_s`), the calibration and the odometry. Pixels are
decoded only when a frame is asked for, one message at a time, so a long bag takes little memory.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.config import CameraConfig
from neoslam.config.perception import BagConfig
from neoslam.datasets.bag_messages import (
    NS_PER_S,
    MessageError,
    grey_image,
    header_stamp_ns,
    odometry_pose,
    stereo_camera,
)
from neoslam.datasets.bag_topics import BagTopics, choose_topics
from neoslam.errors import InputError, NeoSLAMError
from neoslam.geometry import interpolated_pose
from neoslam.inputs import check_input_file, check_input_folder_files
from neoslam.types import Trajectory

__all__ = ["BagSequence", "BagTopics", "is_bag", "open_bag", "pair_by_stamp"]

BAG_SUFFIXES = (".bag", ".db3", ".mcap")


def is_bag(path: Path) -> bool:
    """A ROS 1 .bag, a ROS 2 .db3 or .mcap file, or a ROS 2 bag folder (metadata.yaml)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix in BAG_SUFFIXES


@dataclass(frozen=True, slots=True)
class _MessageRef:
    """Where an image message is: the bag's receive time (the key readers seek by), its rank among the topic's
    messages received at that same time, and its index in the topic (for error messages)."""

    log_ns: int
    rank: int
    index: int


class BagSequence:
    """A stereo sequence read from a bag, frame by frame; it satisfies `perception.frontend.StereoSequence`.
    `odometry` holds the poses of the odometry topic at the frames' stamps, when one was chosen."""

    def __init__(
        self,
        path: Path,
        reader: Any,
        topics: BagTopics,
        camera: CameraConfig,
        stamps_ns: np.ndarray,
        refs: dict[str, list[_MessageRef]],
        odometry: Trajectory | None,
    ) -> None:
        self.path = path
        self.topics = topics
        self.camera = camera
        self.stamps_ns = stamps_ns
        self.timestamps = stamps_ns / NS_PER_S  # left image stamps, seconds
        self.odometry = odometry
        self._reader = reader
        self._refs = refs
        self._connections = {t: [c for c in reader.connections if c.topic == t] for t in (topics.left, topics.right)}
        weakref.finalize(self, _close_quietly, reader)  # the reader stays open while frames are read

    @property
    def name(self) -> str:
        return f"bag-{self.path.stem if self.path.is_file() else self.path.name}"

    @property
    def ground_truth(self) -> Trajectory | None:
        return None  # a bag holds no ground truth NeoSLAM knows of

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def stereo_pair(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """The left and right grey images of a frame, checked against the calibrated size."""
        return self.left_image(index), self._image(self.topics.right, index)

    def left_image(self, index: int) -> np.ndarray:
        """The left grey image of a frame (what the detector sees)."""
        return self._image(self.topics.left, index)

    def close(self) -> None:
        _close_quietly(self._reader)

    def _image(self, topic: str, index: int) -> np.ndarray:
        ref = self._refs[topic][index]
        image = _decode(self.path, self._reader, topic, ref, self._connections[topic])
        expected = (self.camera.height, self.camera.width)
        if image.shape != expected:
            size = f"{image.shape[1]}x{image.shape[0]}"
            problem = f"image is {size}, the calibration's is {expected[1]}x{expected[0]}"
            raise InputError(self.path, f"message {ref.index} of {topic}: {problem}")
        return image


def _close_quietly(reader: Any) -> None:
    with suppress(Exception):  # already closed, or the bag vanished: nothing left to release
        reader.close()


@contextmanager
def _reading(path: Path, where: str = "") -> Iterator[None]:
    """Errors while reading become one line naming the bag and where in it. A corrupt file can fail anywhere
    inside rosbags' parsers (struct, sqlite, zstd, lz4, its own errors), so any exception is reported so."""
    prefix = f"{where}: " if where else ""
    try:
        yield
    except NeoSLAMError:
        raise
    except MessageError as error:
        raise InputError(path, f"{prefix}{error}") from None
    except Exception as error:  # see the docstring: a corrupt bag fails anywhere
        detail = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise InputError(path, f"{prefix}cannot be read as a ROS bag ({detail})") from None


def open_bag(
    path: Path,
    config: BagConfig,
    left_topic: str | None = None,
    right_topic: str | None = None,
    odometry_topic: str | None = None,
    odometry_wanted: bool = False,
) -> BagSequence:
    """Open and index a bag. Topics not given are found when unambiguous; `odometry_wanted` looks for the one
    nav_msgs/Odometry topic when none is named."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if path.is_dir():
        check_input_folder_files(path)
    else:
        check_input_file(path, "bag not found")  # a bag is as long as its recording: no bound on its size
    with _reading(path):
        # A ROS 2 bag without message definitions (older sqlite3 bags) is read with the standard types.
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    try:
        with _reading(path):
            available = {name: info.msgtype for name, info in reader.topics.items()}
        topics = choose_topics(path, available, left_topic, right_topic, odometry_topic, odometry_wanted)
        stamps, refs = _index_stereo_pairs(path, reader, topics, config)
        camera = _calibration(path, reader, topics, refs)
        odometry = None
        if topics.odometry is not None:
            poses = _odometry_at(path, reader, topics.odometry, stamps, config)
            odometry = Trajectory(stamps / NS_PER_S, poses)
        return BagSequence(path, reader, topics, camera, stamps, refs, odometry)
    except BaseException:
        _close_quietly(reader)
        raise


# --- indexing and pairing ---


def pair_by_stamp(left: np.ndarray, right: np.ndarray, tolerance: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i, j) of left and right stamps that are each other's nearest and at most `tolerance` apart,
    ordered by the left stamp. Mutual nearness keeps one image from serving two pairs."""
    if len(left) == 0 or len(right) == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    nearest_right = _nearest(right, left)
    nearest_left = _nearest(left, right)
    lefts = np.arange(len(left))
    mutual = nearest_left[nearest_right] == lefts
    close = np.abs(left - right[nearest_right]) <= tolerance
    keep = lefts[mutual & close]
    keep = keep[np.argsort(left[keep], kind="stable")]
    return keep, nearest_right[keep]


def _nearest(stamps: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """For each query, the index of the nearest of `stamps` (ties to the earlier)."""
    order = np.argsort(stamps, kind="stable")
    ordered = stamps[order]
    after = np.clip(np.searchsorted(ordered, queries), 1, len(ordered) - 1) if len(ordered) > 1 else None
    if after is None:
        return np.zeros(len(queries), dtype=int)
    before = after - 1
    pick = np.where(np.abs(queries - ordered[before]) <= np.abs(ordered[after] - queries), before, after)
    return order[pick]


def _index_stereo_pairs(
    path: Path, reader: Any, topics: BagTopics, config: BagConfig
) -> tuple[np.ndarray, dict[str, list[_MessageRef]]]:
    """Stamps (ns) of the frames and, per camera topic, where each frame's image is."""
    ros1 = not reader.is2
    stamps: dict[str, list[int]] = {topics.left: [], topics.right: []}
    refs: dict[str, list[_MessageRef]] = {topics.left: [], topics.right: []}
    last: dict[str, tuple[int, int]] = {}  # per topic: (log time, rank) of its previous message
    connections = [c for c in reader.connections if c.topic in stamps]
    with _reading(path):
        for connection, log_ns, raw in reader.messages(connections):
            topic = connection.topic
            index = len(refs[topic])
            with _reading(path, f"message {index} of {topic}"):
                stamp = header_stamp_ns(raw, ros1)
            previous = last.get(topic)
            rank = previous[1] + 1 if previous is not None and previous[0] == log_ns else 0
            last[topic] = (log_ns, rank)
            stamps[topic].append(stamp or log_ns)  # an unstamped header: the time the bag received it
            refs[topic].append(_MessageRef(log_ns, rank, index))
    left, right = (np.array(stamps[t], dtype=np.int64) for t in (topics.left, topics.right))
    for topic, topic_stamps in ((topics.left, left), (topics.right, right)):
        _refuse_repeated_stamps(path, topic, topic_stamps)
    tolerance = round(config.pair_tolerance_s * NS_PER_S)
    pairs_left, pairs_right = pair_by_stamp(left, right, tolerance)
    _check_pairs(path, topics, config, left, right, pairs_left, pairs_right)
    frames = left[pairs_left]
    repeated = np.flatnonzero(np.diff(frames) <= 0)
    if len(repeated):
        first, second = (int(pairs_left[k]) for k in (repeated[0], repeated[0] + 1))
        raise InputError(path, f"messages {first} and {second} of {topics.left} have the same stamp")
    return frames, {
        topics.left: [refs[topics.left][i] for i in pairs_left],
        topics.right: [refs[topics.right][j] for j in pairs_right],
    }


def _refuse_repeated_stamps(path: Path, topic: str, stamps: np.ndarray) -> None:
    """Two images of one camera with one stamp: which of them pairs is a guess, so the bag is refused."""
    order = np.argsort(stamps, kind="stable")
    repeated = np.flatnonzero(np.diff(stamps[order]) == 0)
    if len(repeated):
        first, second = sorted(int(order[k]) for k in (repeated[0], repeated[0] + 1))
        raise InputError(path, f"messages {first} and {second} of {topic} have the same stamp ({stamps[first]} ns)")


def _check_pairs(
    path: Path,
    topics: BagTopics,
    config: BagConfig,
    left: np.ndarray,
    right: np.ndarray,
    pairs_left: np.ndarray,
    pairs_right: np.ndarray,
) -> None:
    """No pairs at all is an error; so is any image without a partner, unless `skip_unpaired`."""
    tolerance_ms = f"{config.pair_tolerance_s * 1e3:g} ms"
    if len(pairs_left) == 0:
        counts = f"{len(left)} left and {len(right)} right images"
        raise InputError(path, f"no stereo pairs: {counts} on {topics.left} and {topics.right} within {tolerance_ms}")
    if config.skip_unpaired:
        return
    for topic, stamps, paired, other, other_stamps in (
        (topics.left, left, pairs_left, topics.right, right),
        (topics.right, right, pairs_right, topics.left, left),
    ):
        unpaired = np.setdiff1d(np.arange(len(stamps)), paired)
        if len(unpaired):
            first = int(unpaired[0])
            gap_ms = np.abs(other_stamps - stamps[first]).min() / 1e6
            raise InputError(
                path,
                f"{len(unpaired)} of {len(stamps)} images on {topic} have no partner on {other} within "
                f"{tolerance_ms} (first: message {first}, nearest {gap_ms:.1f} ms away); raise "
                "perception.bag.pair_tolerance_s or set perception.bag.skip_unpaired",
            )


# --- calibration and odometry ---


def _first_message(path: Path, reader: Any, topic: str) -> Any:
    connections = [c for c in reader.connections if c.topic == topic]
    with _reading(path, f"message 0 of {topic}"):
        for connection, _, raw in reader.messages(connections):
            return reader.deserialize(raw, connection.msgtype)
    raise InputError(path, f"{topic} holds no messages")


def _calibration(path: Path, reader: Any, topics: BagTopics, refs: dict[str, list[_MessageRef]]) -> CameraConfig:
    """The stereo calibration from the two CameraInfo topics; the size from the first left image where the
    CameraInfo leaves it 0. Both first images are decoded now, so an unsupported encoding stops before any work."""
    left_info = _first_message(path, reader, topics.left_info)
    right_info = _first_message(path, reader, topics.right_info)
    images = {topic: _decode(path, reader, topic, refs[topic][0]) for topic in (topics.left, topics.right)}
    height, width = images[topics.left].shape
    with _reading(path, f"{topics.left_info} and {topics.right_info}"):
        camera = stereo_camera(left_info, right_info, (width, height))
    for topic, image in images.items():
        if image.shape != (camera.height, camera.width):
            size = f"{image.shape[1]}x{image.shape[0]}"
            problem = f"image is {size}, its CameraInfo says {camera.width}x{camera.height}"
            raise InputError(path, f"message {refs[topic][0].index} of {topic}: {problem}")
    return camera


def _decode(path: Path, reader: Any, topic: str, ref: _MessageRef, connections: list | None = None) -> np.ndarray:
    """Decode one image message, found again by its receive time and rank (readers seek by time)."""
    if connections is None:
        connections = [c for c in reader.connections if c.topic == topic]
    with _reading(path, f"message {ref.index} of {topic}"):
        found = reader.messages(connections, start=ref.log_ns, stop=ref.log_ns + 1)
        connection, raw = next((c, raw) for rank, (c, _, raw) in enumerate(found) if rank == ref.rank)
        return grey_image(reader.deserialize(raw, connection.msgtype), connection.msgtype)


def _odometry_at(path: Path, reader: Any, topic: str, stamps: np.ndarray, config: BagConfig) -> np.ndarray:
    """The odometry topic's pose at each frame stamp: the message at that stamp, or interpolated between the two
    around it (position linearly, rotation along the shortest arc), both within the configured tolerance."""
    connections = [c for c in reader.connections if c.topic == topic]
    times, poses = [], []
    with _reading(path):
        for index, (connection, log_ns, raw) in enumerate(reader.messages(connections)):
            with _reading(path, f"message {index} of {topic}"):
                message = reader.deserialize(raw, connection.msgtype)
                stamp = message.header.stamp.sec * NS_PER_S + message.header.stamp.nanosec
                times.append(stamp or log_ns)
                poses.append(odometry_pose(message))
    if not times:
        raise InputError(path, f"{topic} holds no messages")
    order = np.argsort(np.array(times, dtype=np.int64), kind="stable")
    sample_times = np.array(times, dtype=np.int64)[order]
    sample_poses = np.array(poses)[order]
    tolerance = round(config.odometry_tolerance_s * NS_PER_S)
    return np.array([_pose_at(path, topic, sample_times, sample_poses, int(t), tolerance) for t in stamps])


def _pose_at(path: Path, topic: str, times: np.ndarray, poses: np.ndarray, stamp: int, tolerance: int) -> np.ndarray:
    pose = interpolated_pose(times, poses, stamp, tolerance)
    if pose is not None:
        return pose
    span = f"{times[0] / NS_PER_S:.3f}-{times[-1] / NS_PER_S:.3f} s"
    limit = f"{tolerance / 1e6:g} ms"
    image = f"the image at {stamp / NS_PER_S:.3f} s"
    problem = f"no odometry on {topic} within {limit} around {image} (odometry spans {span})"
    raise InputError(path, f"{problem}; see perception.bag.odometry_tolerance_s")
