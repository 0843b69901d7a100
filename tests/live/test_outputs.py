"""What the node publishes, read back over DDS in this process: the pose as odometry and as a tf chain that composes
to it, the path and objects kept for late readers (transient local), events as JSON, the guidance's route."""

from __future__ import annotations

import json
import time

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.config.live import LiveConfig
from neoslam.geometry import make_pose
from neoslam.live.conversions import pose_matrix
from neoslam.live.messages import MarkerArray, Odometry, Path, String, TFMessage
from neoslam.live.outputs import Outputs, output_topics
from neoslam.live.transport import Ros2Domain, event_qos, map_qos, state_qos
from neoslam.mapping.object_map import MapObject
from neoslam.types import Frame, LoopClosure

WAIT_S = 5.0


def _take(reader, count: int = 1) -> list:
    got, deadline = [], time.monotonic() + WAIT_S
    while len(got) < count and time.monotonic() < deadline:
        got += [s for s in reader.take(N=100) if getattr(s.sample_info, "valid_data", True)]
        time.sleep(0.01)
    assert len(got) >= count, f"{len(got)} of {count} samples"
    return got


def _transform(message) -> np.ndarray:
    t, q = message.transform.translation, message.transform.rotation
    return make_pose(Rotation.from_quat([q.x, q.y, q.z, q.w]), np.array([t.x, t.y, t.z]))


def test_the_pose_is_published_as_odometry_and_as_a_tf_chain_that_composes_to_it(domain_id: int) -> None:
    node, listener = Ros2Domain(domain_id), Ros2Domain(domain_id)
    try:
        readers = {
            "odometry": listener.reader("/neoslam/odometry", Odometry, state_qos(10)),
            "tf": listener.reader("/tf", TFMessage, state_qos(10)),
        }
        outputs = Outputs(node, LiveConfig())
        time.sleep(0.5)
        odometry_pose = make_pose(Rotation.from_euler("z", 0.3), np.array([10.0, 2.0, 0.0]))
        corrected = make_pose(Rotation.from_euler("z", 0.35), np.array([10.5, 1.0, 0.1]))
        frame = Frame(3, 0.3, odometry_pose, np.array([5.0, 0, 0]), np.zeros(3))
        outputs.pose(frame, corrected, 300_000_000)
        odometry = _take(readers["odometry"])[0]
        np.testing.assert_allclose(pose_matrix(odometry.pose.pose), corrected, atol=1e-12)
        assert (odometry.header.frame_id, odometry.child_frame_id) == ("map", "camera_link")
        chain = {(t.header.frame_id, t.child_frame_id): _transform(t) for t in _take(readers["tf"])[0].transforms}
        assert set(chain) == {("map", "odom"), ("odom", "camera_link")}
        np.testing.assert_allclose(chain["odom", "camera_link"], odometry_pose, atol=1e-12)
        np.testing.assert_allclose(chain["map", "odom"] @ chain["odom", "camera_link"], corrected, atol=1e-9)
    finally:
        node.close()
        listener.close()


def test_the_map_reaches_a_reader_that_comes_later_and_events_are_json(domain_id: int) -> None:
    node, listener = Ros2Domain(domain_id), Ros2Domain(domain_id)
    try:
        outputs = Outputs(node, LiveConfig(), guided=True)
        poses = np.stack([make_pose(np.eye(3), np.array([float(k), 0.0, 0.0])) for k in range(4)])
        car = MapObject(2, "car", np.array([1.0, 3.0, 0.5]), 3)
        outputs.map(poses, [0, 1, 2, 3], [car], 3)
        outputs.route(poses[:2], 3)
        closure = LoopClosure(40, 2, 7, 1, 0.9, 5, np.eye(4))
        outputs.loop_closure(closure, 4)
        time.sleep(0.3)
        # subscribed only now: transient local keeps the last path, objects, route and events for late readers
        path = _take(listener.reader("/neoslam/path", Path, map_qos()))[-1]
        assert [p.pose.position.x for p in path.poses] == [0.0, 1.0, 2.0, 3.0]
        markers = _take(listener.reader("/neoslam/objects", MarkerArray, map_qos()))[-1].markers
        assert [m.text for m in markers if m.text] == ["car 2"]
        route = _take(listener.reader("/neoslam/route", Path, map_qos()))[-1]
        assert len(route.poses) == 2
        event = json.loads(_take(listener.reader("/neoslam/events", String, event_qos(100)))[-1].data)
        assert event["event"] == "loop_closure" and event["match_keyframe"] == 1 and len(event["relative_pose"]) == 16
    finally:
        node.close()
        listener.close()


def test_every_published_topic_is_listed_with_its_type() -> None:
    topics = output_topics(LiveConfig(namespace="/robot1/slam"))
    assert topics["/robot1/slam/odometry"] == "nav_msgs/msg/Odometry" and topics["/tf"] == "tf2_msgs/msg/TFMessage"
    assert len(topics) == 8
