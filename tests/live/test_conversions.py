"""Poses, stamps, paths, object markers, events and status as ROS 2 messages."""

from __future__ import annotations

import json

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.geometry import make_pose
from neoslam.live.conversions import (
    event_message,
    object_markers,
    odometry_message,
    path_message,
    pose_matrix,
    pose_message,
    stamp_ns,
    stamp_seconds,
    status_message,
    time_message,
    transform_message,
)
from neoslam.live.messages import Header
from neoslam.mapping.object_map import MapObject


def _pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_pose(Rotation.random(random_state=seed), rng.normal(size=3) * 10)


def test_a_pose_survives_the_message_both_ways() -> None:
    for seed in range(20):
        pose = _pose(seed)
        message = pose_message(pose)
        assert message.orientation.w >= 0
        np.testing.assert_allclose(pose_matrix(message), pose, atol=1e-12)


def test_a_stamp_read_back_is_the_float_of_the_decimal_time() -> None:
    """KITTI's times.txt values, through nanoseconds and back, give the float a times.txt reader gives."""
    for text in ("0.000000e+00", "1.044989e-01", "5.195994e+00", "1403715273.262142976"):
        nanoseconds = round(float(text) * 1e9) if "e" in text else int(text.replace(".", ""))
        message = time_message(nanoseconds)
        assert stamp_ns(Header(stamp=message)) == nanoseconds
        assert stamp_seconds(nanoseconds) == float(text)


def test_odometry_and_tf_carry_the_frames_and_the_pose() -> None:
    pose = _pose(1)
    odometry = odometry_message(pose, np.array([1.0, 0, 0]), np.zeros(3), 5_000_000_123, "map", "camera_link")
    assert (odometry.header.frame_id, odometry.child_frame_id) == ("map", "camera_link")
    assert (odometry.header.stamp.sec, odometry.header.stamp.nanosec) == (5, 123)
    np.testing.assert_allclose(pose_matrix(odometry.pose.pose), pose, atol=1e-12)
    assert odometry.twist.twist.linear.x == 1.0
    transform = transform_message("map", "odom", pose, 7)
    assert (transform.header.frame_id, transform.child_frame_id) == ("map", "odom")
    assert transform.transform.translation.x == pose[0, 3]


def test_a_path_holds_every_pose_with_its_stamp() -> None:
    poses = np.stack([_pose(seed) for seed in range(5)])
    path = path_message(poses, [10, 20, 30, 40, 50], "map", 50)
    assert [p.header.stamp.nanosec for p in path.poses] == [10, 20, 30, 40, 50]
    for entry, pose in zip(path.poses, poses, strict=True):
        np.testing.assert_allclose(pose_matrix(entry.pose), pose, atol=1e-12)
    assert path_message(np.zeros((0, 4, 4)), [], "map", 0).poses == []


def test_object_markers_replace_the_whole_set_and_label_each_object() -> None:
    objects = [MapObject(3, "car", np.array([1.0, 2.0, 0.5]), 4), MapObject(7, "truck", np.array([5.0, 0, 1]), 2)]
    markers = object_markers(objects, "map", 1).markers
    assert markers[0].action == 3  # DELETEALL first: merged and forgotten objects vanish from the view
    cubes = [m for m in markers[1:] if m.ns == "objects"]
    labels = [m for m in markers[1:] if m.ns == "labels"]
    assert [m.id for m in cubes] == [3, 7] and [m.text for m in labels] == ["car 3", "truck 7"]
    assert cubes[0].pose.position.x == 1.0 and cubes[1].scale.x > cubes[0].scale.x


def test_an_event_is_one_json_object_and_the_same_event_the_same_bytes() -> None:
    first = event_message("loop_closure", 12, query_frame=3, score=0.5)
    assert json.loads(first.data) == {"event": "loop_closure", "stamp_ns": 12, "query_frame": 3, "score": 0.5}
    assert first.serialize() == event_message("loop_closure", 12, query_frame=3, score=0.5).serialize()


def test_the_status_is_a_diagnostic_array_of_key_values() -> None:
    status = status_message("neoslam", "warn", "waiting for stereo images", {"frames": 0, "dropped": 2}, 9)
    entry = status.status[0]
    assert (entry.level, entry.name, entry.message) == (1, "neoslam", "waiting for stereo images")
    assert [(v.key, v.value) for v in entry.values] == [("frames", "0"), ("dropped", "2")]
