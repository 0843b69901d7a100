"""What the live node publishes, with the topics, types and QoS each has (NAMESPACE is `live.namespace`):

| topic | type | QoS | when |
|---|---|---|---|
| NAMESPACE/odometry | nav_msgs/Odometry | reliable, keep last 10 | every frame: the corrected pose in `map_frame` |
| /tf | tf2_msgs/TFMessage | reliable, keep last 100 | every frame: map -> odom (the correction), odom -> robot (odometry) |
| NAMESPACE/path | nav_msgs/Path | reliable, transient local, keep last 1 | when the map changes (at most every `path_period_s`) and at the end: the corrected trajectory, every frame |
| NAMESPACE/objects | visualization_msgs/MarkerArray | reliable, transient local, keep last 1 | with the path: the object map |
| NAMESPACE/events | std_msgs/String (JSON) | reliable, transient local, keep last 100 | a loop closure or a relocalisation, as it happens |
| NAMESPACE/status | diagnostic_msgs/DiagnosticArray | reliable, keep last 10 | every `status_period_s` |
| NAMESPACE/route | nav_msgs/Path | reliable, transient local, keep last 1 | with `--goal`: the route, when planned (again) |
| NAMESPACE/guidance | std_msgs/String (JSON) | reliable, keep last 10 | with `--goal`: every frame's guidance |

An event is one JSON object: `{"event": "loop_closure", "stamp_ns": ..., "query_frame", "match_frame",
"query_keyframe", "match_keyframe", "score", "matches", "relative_pose"}` (T_match_query, 16 numbers row-major) or
`{"event": "relocalised", "stamp_ns": ..., "frame", "map_keyframe"}` (a session of a stored map joined it). Guidance
is one JSON object a frame: the columns of a run's guidance.csv (neoslam.navigation.session) and `stamp_ns`.
"""  # noqa: E501

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from cyclonedds.util import duration

from neoslam.config.live import LiveConfig
from neoslam.geometry import invert_pose
from neoslam.live.conversions import (
    event_message,
    object_markers,
    odometry_message,
    path_message,
    status_message,
    tf_message,
    transform_message,
)
from neoslam.live.messages import DiagnosticArray, MarkerArray, Odometry, Path, String, TFMessage
from neoslam.live.transport import Ros2Domain, event_qos, map_qos, state_qos
from neoslam.mapping.object_map import MapObject
from neoslam.types import Frame, LoopClosure

__all__ = ["Outputs", "output_topics"]

ODOMETRY_DEPTH = 10
TF_DEPTH = 100  # tf2's own subscription depth
EVENTS_DEPTH = 100
STATUS_DEPTH = 10
STATUS_NAME = "neoslam"


def output_topics(config: LiveConfig) -> dict[str, str]:
    """Every topic the node publishes, with its ROS 2 type."""
    ns = config.namespace.rstrip("/")
    return {
        f"{ns}/odometry": "nav_msgs/msg/Odometry",
        "/tf": "tf2_msgs/msg/TFMessage",
        f"{ns}/path": "nav_msgs/msg/Path",
        f"{ns}/objects": "visualization_msgs/msg/MarkerArray",
        f"{ns}/events": "std_msgs/msg/String",
        f"{ns}/status": "diagnostic_msgs/msg/DiagnosticArray",
        f"{ns}/route": "nav_msgs/msg/Path",
        f"{ns}/guidance": "std_msgs/msg/String",
    }


class Outputs:
    """The node's writers: the pose and tf every frame, the path and objects when the map changes, events, status."""

    def __init__(self, domain: Ros2Domain, config: LiveConfig, guided: bool = False) -> None:
        """`guided`: the node guides to a goal, and publishes the route and the guidance too."""
        self.config = config
        topics = list(output_topics(config))
        self._odometry = domain.writer(topics[0], Odometry, state_qos(ODOMETRY_DEPTH))
        self._tf = domain.writer(topics[1], TFMessage, state_qos(TF_DEPTH))
        self._path = domain.writer(topics[2], Path, map_qos())
        self._objects = domain.writer(topics[3], MarkerArray, map_qos())
        self._events = domain.writer(topics[4], String, event_qos(EVENTS_DEPTH))
        self._status = domain.writer(topics[5], DiagnosticArray, state_qos(STATUS_DEPTH))
        self._writers = [self._odometry, self._tf, self._path, self._objects, self._events, self._status]
        self._route = self._guidance = None
        if guided:
            self._route = domain.writer(topics[6], Path, map_qos())
            self._guidance = domain.writer(topics[7], String, state_qos(STATUS_DEPTH))
            self._writers += [self._route, self._guidance]

    def pose(self, frame: Frame, pose: np.ndarray, stamp: int) -> None:
        """The corrected pose T_map_robot of a frame, as odometry and as tf (map -> odom -> robot)."""
        live = self.config
        message = odometry_message(
            pose, frame.linear_velocity, frame.angular_velocity, stamp, live.map_frame, live.robot_frame
        )
        self._odometry.write(message)
        map_from_odom = pose @ invert_pose(frame.odometry_pose)
        transforms = [
            transform_message(live.map_frame, live.odom_frame, map_from_odom, stamp),
            transform_message(live.odom_frame, live.robot_frame, frame.odometry_pose, stamp),
        ]
        self._tf.write(tf_message(transforms))

    def map(self, poses: np.ndarray, stamps: Sequence[int], objects: Sequence[MapObject], stamp: int) -> None:
        """The corrected trajectory (one pose per frame, with the frames' stamps) and the object map."""
        self._path.write(path_message(poses, stamps, self.config.map_frame, stamp))
        self._objects.write(object_markers(objects, self.config.map_frame, stamp))

    def loop_closure(self, closure: LoopClosure, stamp: int) -> None:
        fields = {
            "query_frame": closure.query_frame,
            "match_frame": closure.match_frame,
            "query_keyframe": closure.query_keyframe,
            "match_keyframe": closure.match_keyframe,
            "score": float(closure.score),
            "matches": closure.n_matches,
            "relative_pose": [float(v) for v in np.asarray(closure.relative_pose).ravel()],
        }
        self._events.write(event_message("loop_closure", stamp, **fields))

    def relocalised(self, frame: int, map_keyframe: int | None, stamp: int) -> None:
        self._events.write(event_message("relocalised", stamp, frame=frame, map_keyframe=map_keyframe))

    def route(self, poses: np.ndarray, stamp: int) -> None:
        """A route's waypoints (the experiences' corrected poses) as a path, all stamped with the frame's stamp."""
        assert self._route is not None
        self._route.write(path_message(poses, [stamp] * len(poses), self.config.map_frame, stamp))

    def guidance(self, row: dict[str, Any], stamp: int) -> None:
        assert self._guidance is not None
        finite = {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in row.items()}
        self._guidance.write(String(data=json.dumps({"stamp_ns": int(stamp), **finite}, allow_nan=False)))

    def status(self, level: str, message: str, values: dict[str, Any], stamp: int) -> None:
        self._status.write(status_message(STATUS_NAME, level, message, values, stamp))

    def wait_for_readers(self, timeout_s: float) -> None:
        """Give reliable readers the chance to acknowledge what was written (before the node exits)."""
        for writer in self._writers:
            try:
                writer.wait_for_acks(duration(seconds=timeout_s / len(self._writers)))
            except Exception:  # noqa: BLE001 - a writer without readers has nothing to wait for
                continue
