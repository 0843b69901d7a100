"""Reading ROS bags (neoslam.datasets.bag) on real bags written with rosbags: the same pixels, calibration and stamps
as the KITTI folder they were written from, in ROS 1 and ROS 2 (sqlite3, mcap); pairing by stamp; topics found or
asked for; every encoding; the odometry topic; and one-line errors for what cannot be read."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from neoslam.config.perception import BagConfig
from neoslam.datasets import bag as bag_module
from neoslam.datasets.bag import is_bag, open_bag, pair_by_stamp
from neoslam.datasets.bag_messages import header_stamp_ns
from neoslam.datasets.bag_topics import choose_topics
from neoslam.errors import InputError
from neoslam.geometry import make_pose

FRAMES = 6
EPOCH_NS = 1_600_000_000 * 10**9
PERIOD_NS = 100_000_000
SMALL = (48, 64)  # height, width of the synthetic images of the small bags
P_LEFT = np.array([[50.0, 0, 32, 0], [0, 50.0, 24, 0], [0, 0, 1, 0]])
P_RIGHT = np.array([[50.0, 0, 32, -25.0], [0, 50.0, 24, 0], [0, 0, 1, 0]])  # baseline 0.5 m
IMAGE, INFO = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"


def _grey(index: int, camera: int) -> np.ndarray:
    rng = np.random.default_rng([index, camera])
    return rng.integers(0, 256, SMALL, dtype=np.uint8)


def _small_bag(bag_writer, path: Path, kind: str = "ros1", *, frames: int = FRAMES, right_offset_ns=0, encode=None,
               topics=("/left/image_raw", "/right/image_raw"), infos=("/left/camera_info", "/right/camera_info"),
               extra=None) -> Path:  # fmt: skip
    """A small stereo bag of random grey frames; `encode(bag, stamp, index, camera)` may give another message."""
    with bag_writer(path, kind) as bag:
        for index in range(frames):
            stamp = EPOCH_NS + index * PERIOD_NS
            for camera, (topic, info, projection) in enumerate(zip(topics, infos, (P_LEFT, P_RIGHT), strict=True)):
                at = stamp + (right_offset_ns if camera else 0)
                if encode is None:
                    msgtype, message = IMAGE, bag.image(at, _grey(index, camera))
                else:
                    msgtype, message = encode(bag, at, index, camera)
                bag.add(topic, msgtype, message, at)
                if info is not None:
                    bag.add(info, INFO, bag.camera_info(at, projection, SMALL[1], SMALL[0]), at)
            if extra is not None:
                extra(bag, index, stamp)
    return path


def _one_line_error(error: pytest.ExceptionInfo, *expected: str) -> None:
    message = str(error.value)
    assert "\n" not in message
    for text in expected:
        assert text in message, message


# --- the KITTI frames, read back from each kind of bag ---


@pytest.mark.parametrize(("kind", "name", "compressed"), [("ros1", "s.bag", False), ("sqlite3", "s2", True),
                                                         ("mcap", "s3", False)])  # fmt: skip
def test_a_bag_gives_the_kitti_frames_back(street, stereo_bag, tmp_path: Path, kind, name, compressed) -> None:
    path = stereo_bag(tmp_path / name, street, FRAMES, kind, right_compressed=compressed)
    sequence = open_bag(path, BagConfig())
    assert is_bag(path) and len(sequence) == FRAMES and sequence.ground_truth is None
    assert sequence.camera == street.camera  # fx, fy, cx, cy from P0, the baseline from P1, the size
    assert sequence.topics.left == "/stereo/left/image_rect" and sequence.topics.right == "/stereo/right/image_rect"
    assert sequence.topics.left_info == "/stereo/left/camera_info" and sequence.odometry is None
    assert np.allclose(sequence.timestamps - 1_317_384_000, street.timestamps[:FRAMES], atol=1e-6)
    for index in (0, 3, FRAMES - 1):  # any order: each frame is found again by its receive time
        for got, want in zip(sequence.stereo_pair(index), street.stereo_pair(index), strict=True):
            assert got.dtype == np.uint8 and got.flags.writeable
            assert np.array_equal(got, want)
    assert np.array_equal(sequence.left_image(2), street.left_image(2))


def test_opening_decodes_only_the_first_pair(street, stereo_bag, tmp_path: Path, monkeypatch) -> None:
    """Opening indexes stamps from the raw bytes: only the first pair is decoded (to check the encoding and size),
    the others when their frame is read."""
    path = stereo_bag(tmp_path / "lazy.bag", street, FRAMES, "ros1")
    decoded = []
    real = bag_module.grey_image
    monkeypatch.setattr(bag_module, "grey_image", lambda *args: decoded.append(1) or real(*args))
    sequence = open_bag(path, BagConfig())
    assert len(decoded) == 2
    sequence.stereo_pair(4)
    assert len(decoded) == 4


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_header_stamps_are_read_from_the_raw_bytes(bag_writer, tmp_path: Path, kind: str) -> None:
    from rosbags.highlevel import AnyReader

    path = _small_bag(bag_writer, tmp_path / ("h.bag" if kind == "ros1" else "h"), kind, frames=3)
    with AnyReader([path]) as reader:
        for connection, _, raw in reader.messages():
            header = reader.deserialize(raw, connection.msgtype).header
            assert header_stamp_ns(raw, kind == "ros1") == header.stamp.sec * 10**9 + header.stamp.nanosec


# --- pairing ---


def test_pairs_are_mutually_nearest_within_the_tolerance() -> None:
    left = np.array([0, 100, 200, 300, 400])
    right = np.array([2, 99, 150, 260, 401, 402])
    pairs = pair_by_stamp(left, right, tolerance=5)
    assert [list(p) for p in pairs] == [[0, 1, 4], [0, 1, 4]]  # 200 and 300 have no partner within 5
    shuffled = pair_by_stamp(left[::-1], right, tolerance=5)
    assert list(left[::-1][shuffled[0]]) == [0, 100, 400]  # ordered by the left stamp


def test_a_small_offset_pairs_and_a_large_one_is_an_error(bag_writer, tmp_path: Path) -> None:
    near = _small_bag(bag_writer, tmp_path / "near.bag", right_offset_ns=3_000_000)
    assert len(open_bag(near, BagConfig())) == FRAMES
    far = _small_bag(bag_writer, tmp_path / "far.bag", right_offset_ns=20_000_000)
    with pytest.raises(InputError) as error:
        open_bag(far, BagConfig())
    _one_line_error(error, "far.bag", "no stereo pairs", "within 5 ms")
    assert len(open_bag(far, BagConfig(pair_tolerance_s=0.025))) == FRAMES


def test_unpaired_images_are_an_error_unless_skipped(bag_writer, tmp_path: Path) -> None:
    def extra_left(bag, index, stamp):  # a left image half-way between frames: no right partner
        if index == 2:
            bag.add("/left/image_raw", IMAGE, bag.image(stamp + PERIOD_NS // 2, _grey(9, 0)), stamp + PERIOD_NS // 2)

    path = _small_bag(bag_writer, tmp_path / "gap.bag", extra=extra_left)
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig())
    _one_line_error(error, "gap.bag", "1 of 7 images on /left/image_raw", "message 3", "skip_unpaired")
    sequence = open_bag(path, BagConfig(skip_unpaired=True))
    assert len(sequence) == FRAMES
    assert np.array_equal(sequence.left_image(3), _grey(3, 0))


# --- topics ---


def test_topics_are_found_when_unambiguous() -> None:
    topics = {
        "/cam0/image_raw": IMAGE,
        "/cam1/image_raw": "sensor_msgs/msg/CompressedImage",
        "/cam0/camera_info": INFO,
        "/cam1/camera_info": INFO,
        "/odom": "nav_msgs/msg/Odometry",
    }
    chosen = choose_topics(Path("b.bag"), topics, odometry_wanted=True)
    assert (chosen.left, chosen.right, chosen.left_info, chosen.right_info, chosen.odometry) == (
        "/cam0/image_raw", "/cam1/image_raw", "/cam0/camera_info", "/cam1/camera_info", "/odom"
    )  # fmt: skip
    assert choose_topics(Path("b.bag"), topics).odometry is None  # stereo odometry unless asked


def test_ambiguous_topics_list_the_candidates(bag_writer, tmp_path: Path) -> None:
    def raw_too(bag, index, stamp):
        bag.add("/stereo/left/image_raw", IMAGE, bag.image(stamp, _grey(index, 0)), stamp)

    topics = ("/stereo/left/image_rect", "/stereo/right/image_rect")
    infos = ("/stereo/left/camera_info", "/stereo/right/camera_info")
    path = _small_bag(bag_writer, tmp_path / "two.bag", topics=topics, infos=infos, extra=raw_too)
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig())
    _one_line_error(error, "left camera's topic", "--left-topic", "/stereo/left/image_raw (Image)",
                    "/stereo/left/image_rect (Image)", "/stereo/right/image_rect (Image)")  # fmt: skip
    sequence = open_bag(path, BagConfig(), left_topic="/stereo/left/image_rect")
    assert sequence.topics.left_info == "/stereo/left/camera_info" and len(sequence) == FRAMES
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig(), left_topic="/stereo/left/camera_info")
    _one_line_error(error, "--left-topic /stereo/left/camera_info is not an Image or CompressedImage topic")


def test_missing_calibration_is_one_line(bag_writer, tmp_path: Path) -> None:
    path = _small_bag(bag_writer, tmp_path / "nocal.bag", infos=("/left/camera_info", None))
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig())
    _one_line_error(error, "nocal.bag", "no CameraInfo topic beside /right/image_raw", "/left/camera_info")


# --- encodings ---


@pytest.mark.parametrize(
    ("encoding", "channels", "conversion"),
    [("bgr8", 3, cv2.COLOR_BGR2GRAY), ("rgb8", 3, cv2.COLOR_RGB2GRAY), ("rgba8", 4, cv2.COLOR_RGBA2GRAY),
     ("bayer_rggb8", 1, cv2.COLOR_BayerBG2GRAY), ("mono8", 1, None)],
)  # fmt: skip
def test_image_encodings_become_grey(bag_writer, tmp_path: Path, encoding: str, channels: int, conversion) -> None:
    def colour(index: int, camera: int) -> np.ndarray:
        shape = (*SMALL, channels) if channels > 1 else SMALL
        return np.random.default_rng([index, camera, 7]).integers(0, 256, shape, dtype=np.uint8)

    def padded(bag, stamp, index, camera):  # rows padded beyond the pixels, as some drivers send them
        pixels = colour(index, camera)
        wide = np.zeros((SMALL[0], pixels[0].size + 16), dtype=np.uint8)
        wide[:, : pixels[0].size] = pixels.reshape(SMALL[0], -1)
        message = bag.image(stamp, pixels, encoding)
        message.step, message.data = wide.shape[1], wide.reshape(-1)
        return IMAGE, message

    path = _small_bag(bag_writer, tmp_path / "enc.bag", encode=padded)
    left = open_bag(path, BagConfig()).left_image(1)
    pixels = colour(1, 0)
    assert np.array_equal(left, pixels if conversion is None else cv2.cvtColor(pixels, conversion))


def test_unsupported_encoding_stops_at_opening(bag_writer, tmp_path: Path) -> None:
    def mono16(bag, stamp, index, camera):
        return IMAGE, bag.image(stamp, _grey(index, camera).astype(np.uint16) * 256, "mono16")

    path = _small_bag(bag_writer, tmp_path / "deep.bag", encode=mono16)
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig())
    _one_line_error(error, "deep.bag", "message 0 of /left/image_raw", "unsupported image encoding 'mono16'", "mono8")


def test_an_image_of_another_size_is_one_line(bag_writer, tmp_path: Path) -> None:
    def shrink_frame_4(bag, stamp, index, camera):
        grey = _grey(index, camera)
        return IMAGE, bag.image(stamp, np.ascontiguousarray(grey[:40] if index == 4 else grey))

    sequence = open_bag(_small_bag(bag_writer, tmp_path / "size.bag", encode=shrink_frame_4), BagConfig())
    with pytest.raises(InputError) as error:
        sequence.stereo_pair(4)
    _one_line_error(error, "message 4 of /left/image_raw", "image is 64x40", "64x48")


# --- odometry ---


def test_odometry_is_taken_at_the_image_stamps(bag_writer, tmp_path: Path) -> None:
    """Odometry at twice the frame rate, a quarter period off the images: each image's pose is interpolated."""

    def truth(t_s: float) -> np.ndarray:
        return make_pose(Rotation.from_euler("z", 0.3 * t_s), [2.0 * t_s, 0.5 * t_s**2, 0.0])

    def odometry(bag, index, stamp):
        for at in (stamp - PERIOD_NS // 4, stamp + PERIOD_NS // 4):
            bag.add("/odom", "nav_msgs/msg/Odometry", bag.odometry(at, truth((at - EPOCH_NS) / 1e9)), at)

    path = _small_bag(bag_writer, tmp_path / "odom.bag", extra=odometry)
    sequence = open_bag(path, BagConfig(), odometry_topic="/odom")
    poses = sequence.odometry.poses
    assert sequence.topics.odometry == "/odom" and len(poses) == FRAMES
    assert np.allclose(sequence.odometry.timestamps, sequence.timestamps)
    for index in range(FRAMES):
        expected = truth(index * PERIOD_NS / 1e9)
        assert np.allclose(poses[index][:3, :3], expected[:3, :3], atol=1e-12)  # the yaw grows linearly: exact
        assert np.allclose(poses[index][:3, 3], expected[:3, 3], atol=1e-3)  # y grows with t^2: near
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig(odometry_tolerance_s=0.02), odometry_topic="/odom")
    _one_line_error(error, "no odometry on /odom within 20 ms", "odometry_tolerance_s")


# --- corrupt bags ---


def _truncated_bag(bag_writer, tmp_path: Path) -> Path:
    whole = _small_bag(bag_writer, tmp_path / "whole.bag")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    return cut


def _garbage(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(3).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    return path


def _bad_metadata(bag_writer, tmp_path: Path) -> Path:
    folder = _small_bag(bag_writer, tmp_path / "ros2", "sqlite3")
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [not, a, mapping\n")
    return folder


def _missing_storage(bag_writer, tmp_path: Path) -> Path:
    folder = _small_bag(bag_writer, tmp_path / "ros2", "mcap")
    next(folder.glob("*.mcap")).unlink()
    return folder


@pytest.mark.parametrize(
    "make",
    [
        _truncated_bag,
        lambda writer, tmp: _garbage(tmp, "noise.bag"),
        lambda writer, tmp: _garbage(tmp, "noise.db3"),
        lambda writer, tmp: _garbage(tmp, "noise.mcap"),
        _bad_metadata,
        _missing_storage,
    ],
    ids=["truncated-ros1", "noise-ros1", "noise-db3", "noise-mcap", "bad-metadata", "missing-storage"],
)
def test_a_corrupt_bag_is_one_line(bag_writer, tmp_path: Path, make) -> None:
    path = make(bag_writer, tmp_path)
    with pytest.raises(InputError) as error:
        open_bag(path, BagConfig())
    _one_line_error(error, str(path))
