"""Real ROS 1 and ROS 2 bags written at test time with rosbags' writers, from the frames of kitti_06_51 (its
images are not copied into the repository: each test writes its bags under tmp_path).

`bag_writer` opens a bag of a kind ("ros1", "sqlite3", "mcap") and adds messages to it; `stereo_bag` writes a KITTI
sequence's first frames as a stereo bag (Image or CompressedImage, CameraInfo, optionally nav_msgs/Odometry);
`kitti_subset` makes a KITTI root of the same first frames (links to the images) for the run to compare with.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from neoslam.datasets.kitti import KittiSequence, read_calibration, read_kitti_sequence
from neoslam.geometry import quaternion_from_pose

EPOCH_NS = 1_317_384_000 * 10**9  # stamps as a real recording has them: seconds since 1970
RECEIVE_DELAY_NS = 2_000_000  # the bag's receive time lags the header stamp, as in a recording
LEFT, RIGHT = "/stereo/left/image_rect", "/stereo/right/image_rect"
LEFT_INFO, RIGHT_INFO = "/stereo/left/camera_info", "/stereo/right/camera_info"
ODOMETRY = "/odom"


class BagWriter:
    """Messages of one bag, built with the bag's own type store (ROS 1 Noetic or ROS 2 Humble)."""

    def __init__(self, writer: Any, typestore: Any, ros1: bool) -> None:
        self.writer, self.typestore, self.ros1 = writer, typestore, ros1
        self.types = typestore.types
        self._connections: dict[str, Any] = {}
        self._seq = 0

    def add(self, topic: str, msgtype: str, message: Any, log_ns: int) -> None:
        if topic not in self._connections:
            self._connections[topic] = self.writer.add_connection(topic, msgtype, typestore=self.typestore)
        if self.ros1:
            data = self.typestore.serialize_ros1(message, msgtype)
        else:
            data = self.typestore.serialize_cdr(message, msgtype)
        self.writer.write(self._connections[topic], log_ns, data)

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        stamp = self.types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        if self.ros1:
            self._seq += 1
            return self.types["std_msgs/msg/Header"](seq=self._seq, stamp=stamp, frame_id=frame_id)
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def image(self, stamp_ns: int, pixels: np.ndarray, encoding: str = "mono8") -> Any:
        height, width = pixels.shape[:2]
        step = pixels.strides[0] if pixels.ndim > 1 else width
        return self.types["sensor_msgs/msg/Image"](
            header=self.header(stamp_ns, "camera"),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=0,
            step=step,
            data=np.ascontiguousarray(pixels).reshape(-1).view(np.uint8),
        )

    def compressed(self, stamp_ns: int, data: bytes, fmt: str = "mono8; png compressed") -> Any:
        return self.types["sensor_msgs/msg/CompressedImage"](
            header=self.header(stamp_ns, "camera"), format=fmt, data=np.frombuffer(data, dtype=np.uint8)
        )

    def camera_info(self, stamp_ns: int, projection: np.ndarray, width: int, height: int) -> Any:
        matrices = {"D": np.zeros(5), "K": projection[:, :3].reshape(-1), "R": np.eye(3).reshape(-1)}
        matrices["P"] = projection.reshape(-1).astype(np.float64)
        if not self.ros1:  # ROS 2 names the fields in lower case
            matrices = {key.lower(): value for key, value in matrices.items()}
        region = self.types["sensor_msgs/msg/RegionOfInterest"]
        roi = region(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        return self.types["sensor_msgs/msg/CameraInfo"](
            header=self.header(stamp_ns, "camera"),
            height=height,
            width=width,
            distortion_model="plumb_bob",
            binning_x=0,
            binning_y=0,
            roi=roi,
            **matrices,
        )

    def odometry(self, stamp_ns: int, pose: np.ndarray) -> Any:
        types = self.types
        qx, qy, qz, qw = quaternion_from_pose(pose[None])[0]
        point = types["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3])
        orientation = types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)
        covariance = np.zeros(36)
        zero = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return types["nav_msgs/msg/Odometry"](
            header=self.header(stamp_ns, "odom"),
            child_frame_id="base_link",
            pose=types["geometry_msgs/msg/PoseWithCovariance"](
                pose=types["geometry_msgs/msg/Pose"](position=point, orientation=orientation), covariance=covariance
            ),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=types["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=covariance
            ),
        )


@contextmanager
def open_bag_writer(path: Path, kind: str) -> Iterator[BagWriter]:
    """A ROS 1 bag (kind "ros1", path ending .bag) or a ROS 2 bag folder with sqlite3 or mcap storage."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    if kind == "ros1":
        with Writer1(path) as writer:
            yield BagWriter(writer, get_typestore(Stores.ROS1_NOETIC), ros1=True)
        return
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[kind]
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        yield BagWriter(writer, get_typestore(Stores.ROS2_HUMBLE), ros1=False)


def stamp_ns(sequence: KittiSequence, index: int) -> int:
    return EPOCH_NS + round(float(sequence.timestamps[index]) * 1e9)


def write_stereo_bag(
    path: Path,
    sequence: KittiSequence,
    frames: int,
    kind: str,
    right_compressed: bool = False,
    odometry: np.ndarray | None = None,
    right_info: bool = True,
) -> Path:
    """The first `frames` stereo frames of a KITTI sequence as a bag: mono8 Images (the right camera's as its
    PNG file's bytes in a CompressedImage if asked), a CameraInfo per camera and frame with KITTI's P0 and P1
    (the right one left out if asked), and `odometry` (robot poses, one per frame) on /odom if given."""
    left_projection, right_projection = read_calibration(sequence.root / "sequences" / sequence.sequence / "calib.txt")
    width, height = sequence.camera.width, sequence.camera.height
    with open_bag_writer(path, kind) as bag:
        for index in range(frames):
            stamp = stamp_ns(sequence, index)
            received = stamp + RECEIVE_DELAY_NS
            left = cv2.imread(str(sequence.left_images[index]), cv2.IMREAD_GRAYSCALE)
            bag.add(LEFT, "sensor_msgs/msg/Image", bag.image(stamp, left), received)
            if right_compressed:
                png = sequence.right_images[index].read_bytes()
                bag.add(RIGHT, "sensor_msgs/msg/CompressedImage", bag.compressed(stamp, png), received)
            else:
                right = cv2.imread(str(sequence.right_images[index]), cv2.IMREAD_GRAYSCALE)
                bag.add(RIGHT, "sensor_msgs/msg/Image", bag.image(stamp, right), received)
            infos = [(LEFT_INFO, left_projection)] + [(RIGHT_INFO, right_projection)] * right_info
            for topic, projection in infos:
                info = bag.camera_info(stamp, projection, width, height)
                bag.add(topic, "sensor_msgs/msg/CameraInfo", info, received)
            if odometry is not None:
                bag.add(ODOMETRY, "nav_msgs/msg/Odometry", bag.odometry(stamp, odometry[index]), received)
    return path


def write_kitti_subset(root: Path, sequence: KittiSequence, frames: int) -> Path:
    """A KITTI root holding the first `frames` frames of a sequence (image links, cut times and poses)."""
    source = sequence.root / "sequences" / sequence.sequence
    folder = root / "sequences" / sequence.sequence
    for camera in ("image_0", "image_1"):
        (folder / camera).mkdir(parents=True)
        for index in range(frames):
            name = f"{index:06d}.png"
            (folder / camera / name).symlink_to(source / camera / name)
    (folder / "calib.txt").symlink_to(source / "calib.txt")
    (folder / "times.txt").write_text("".join((source / "times.txt").read_text().splitlines(True)[:frames]))
    poses = sequence.root / "poses" / f"{sequence.sequence}.txt"
    (root / "poses").mkdir()
    (root / "poses" / poses.name).write_text("".join(poses.read_text().splitlines(True)[:frames]))
    return root


@pytest.fixture(scope="session")
def street(shared_data: Path) -> KittiSequence:
    """The 51 real frames of KITTI 06."""
    return read_kitti_sequence(shared_data / "kitti_06_51", "06")


@pytest.fixture(scope="session")
def bag_writer() -> Callable[[Path, str], Any]:
    return open_bag_writer


@pytest.fixture(scope="session")
def stereo_bag() -> Callable[..., Path]:
    return write_stereo_bag


@pytest.fixture(scope="session")
def kitti_subset() -> Callable[[Path, KittiSequence, int], Path]:
    return write_kitti_subset
