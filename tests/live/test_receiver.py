"""Stereo pairing by stamp, the newest-pair mailbox and the odometry buffer: the receiver's logic without DDS."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from neoslam.geometry import make_pose
from neoslam.live.receiver import Counters, NewestPair, OdometryBuffer, StereoPairer, image_type, info_topic

MS = 1_000_000


def _pairer(slop_ms: float = 5, depth: int = 5) -> tuple[StereoPairer, NewestPair, Counters]:
    counters = Counters()
    mailbox = NewestPair(counters)
    return StereoPairer(round(slop_ms * MS), depth, counters, mailbox), mailbox, counters


def test_images_of_one_stamp_pair_in_either_order_of_arrival() -> None:
    pairer, mailbox, counters = _pairer()
    pairer.add("left", "L0", 100 * MS, 1.0)
    pairer.add("right", "R0", 100 * MS, 1.5)
    pair = mailbox.take(0)
    assert (pair.left, pair.right, pair.stamp_ns, pair.received_s) == ("L0", "R0", 100 * MS, 1.5)
    pairer.add("right", "R1", 200 * MS, 2.0)
    pairer.add("left", "L1", 202 * MS, 2.1)  # within the slop: the left stamp is the pair's
    pair = mailbox.take(0)
    assert (pair.left, pair.right, pair.stamp_ns) == ("L1", "R1", 202 * MS)
    assert counters.pairs == 2 and counters.unpaired == 0


def test_images_farther_apart_than_the_slop_do_not_pair_and_are_forgotten_once_a_newer_pair_forms() -> None:
    pairer, mailbox, counters = _pairer(slop_ms=5)
    pairer.add("left", "L0", 100 * MS, 1.0)
    pairer.add("right", "R0", 110 * MS, 1.0)
    assert mailbox.take(0) is None
    pairer.add("left", "L1", 200 * MS, 2.0)
    pairer.add("right", "R1", 200 * MS, 2.0)
    assert mailbox.take(0).left == "L1"
    assert counters.unpaired == 2


def test_the_newest_pair_replaces_one_not_taken_yet_and_counts_it_dropped() -> None:
    pairer, mailbox, counters = _pairer()
    for k in range(4):
        pairer.add("left", f"L{k}", k * 100 * MS, k)
        pairer.add("right", f"R{k}", k * 100 * MS, k)
    assert mailbox.take(0).left == "L3"
    assert counters.dropped == 3 and counters.pairs == 4


def test_a_pair_not_newer_than_the_last_is_counted_out_of_order() -> None:
    pairer, mailbox, counters = _pairer()
    pairer.add("left", "L", 500 * MS, 1.0)
    pairer.add("right", "R", 500 * MS, 1.0)
    mailbox.take(0)
    pairer.add("left", "old", 100 * MS, 2.0)  # a replay that started again
    pairer.add("right", "old", 100 * MS, 2.0)
    assert mailbox.take(0) is None and counters.out_of_order == 1


def test_a_camera_whose_partner_stopped_keeps_a_bounded_backlog() -> None:
    pairer, _, counters = _pairer(depth=3)
    for k in range(50):
        pairer.add("left", k, k * 100 * MS, k)
    assert len(pairer._waiting["left"]) == 3 and counters.unpaired == 47


def test_take_waits_for_a_pair_and_gives_up_after_its_timeout() -> None:
    counters = Counters()
    mailbox = NewestPair(counters)
    start = time.monotonic()
    assert mailbox.take(0.05) is None
    assert time.monotonic() - start >= 0.04
    pairer = StereoPairer(0, 5, counters, mailbox)
    threading.Timer(0.05, lambda: (pairer.add("left", "L", 1, 0), pairer.add("right", "R", 1, 0))).start()
    assert mailbox.take(5.0).left == "L"


def test_the_odometry_buffer_interpolates_between_the_messages_around_a_stamp() -> None:
    buffer = OdometryBuffer()
    buffer.add(0, np.eye(4))
    buffer.add(100 * MS, make_pose(np.eye(3), np.array([1.0, 0.0, 0.0])))
    buffer.add(50 * MS, np.eye(4))  # older than the newest: kept out
    pose = buffer.pose_at(25 * MS, 100 * MS)
    np.testing.assert_allclose(pose[:3, 3], [0.25, 0, 0])
    assert buffer.pose_at(150 * MS, 100 * MS) is None  # after the newest message
    assert buffer.pose_at(25 * MS, 10 * MS) is None  # the neighbours are too far from the stamp
    assert buffer.newest_stamp() == 100 * MS


@pytest.mark.parametrize(
    ("topic", "info"),
    [
        ("/left/image_raw", "/left/camera_info"),
        ("/stereo/left/image_rect/compressed", "/stereo/left/camera_info"),
        ("cam0/image", "cam0/camera_info"),
    ],
)
def test_camera_info_lies_beside_the_image_topic(topic: str, info: str) -> None:
    assert info_topic(topic) == info


def test_a_topic_named_compressed_carries_compressed_images() -> None:
    assert image_type("/left/image_raw/compressed").__name__ == "CompressedImage"
    assert image_type("/left/image_raw").__name__ == "Image"
