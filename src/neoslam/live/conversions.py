"""NeoSLAM's poses, objects and figures as ROS 2 messages, and message stamps as nanoseconds.

Poses are T_parent_child 4x4 matrices in REP-103 axes (x forward, y left, z up), which is what ROS 2's
geometry_msgs carry, so no axis change happens here. A message stamp is int32 seconds and uint32 nanoseconds;
NeoSLAM's frame time is the stamp in seconds (`stamp_seconds`), computed from the integer nanoseconds so that a
stamp written from a KITTI times.txt value reads back as the same float.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from neoslam.geometry import pose_from_quaternion, quaternion_from_pose
from neoslam.live.messages import (
    ColorRGBA,
    DiagnosticArray,
    DiagnosticStatus,
    Header,
    KeyValue,
    Marker,
    MarkerArray,
    Odometry,
    Path,
    Point,
    Pose,
    PoseStamped,
    PoseWithCovariance,
    Quaternion,
    String,
    TFMessage,
    Time,
    Transform,
    TransformStamped,
    Twist,
    TwistWithCovariance,
    Vector3,
)
from neoslam.mapping.object_map import MapObject

__all__ = [
    "NS_PER_S",
    "stamp_ns",
    "stamp_seconds",
    "time_message",
    "pose_message",
    "pose_matrix",
    "transform_message",
    "tf_message",
    "odometry_message",
    "path_message",
    "object_markers",
    "event_message",
    "status_message",
]

NS_PER_S = 1_000_000_000
MARKER_NAMESPACE = "objects"
LABEL_NAMESPACE = "labels"
# a marker's size per class, m (length, width, height): for the view only
OBJECT_SCALE_M = {"car": (4.2, 1.8, 1.5), "truck": (7.0, 2.5, 3.0), "bicycle": (1.8, 0.6, 1.2)}
OBJECT_SCALE_M["person"] = (0.6, 0.6, 1.7)
OTHER_SCALE_M = (1.0, 1.0, 1.0)
LABEL_HEIGHT_M = 1.0  # the text marker's letter height
LABEL_LIFT_M = 2.0  # the label floats this far above the object's centre
CLASS_COLOURS = {"car": (0.26, 0.52, 0.96), "truck": (0.98, 0.55, 0.0), "bicycle": (0.26, 0.63, 0.28)}
CLASS_COLOURS["person"] = (0.9, 0.22, 0.21)
OTHER_COLOUR = (0.62, 0.62, 0.62)
STATUS_LEVELS = {"ok": 0, "warn": 1, "error": 2, "stale": 3}
# visualization_msgs/Marker's constants for its type and action fields
MARKER_CUBE = 1
MARKER_TEXT_VIEW_FACING = 9
MARKER_DELETEALL = 3


def stamp_ns(header: Header) -> int:
    """A message header's stamp in integer nanoseconds."""
    return int(header.stamp.sec) * NS_PER_S + int(header.stamp.nanosec)


def stamp_seconds(nanoseconds: int) -> float:
    """Seconds from integer nanoseconds: one correctly rounded division, the float nearest the decimal stamp."""
    return nanoseconds / NS_PER_S


def time_message(nanoseconds: int) -> Time:
    seconds, remainder = divmod(int(nanoseconds), NS_PER_S)
    return Time(sec=seconds, nanosec=remainder)


def _header(nanoseconds: int, frame_id: str) -> Header:
    return Header(stamp=time_message(nanoseconds), frame_id=frame_id)


def pose_message(pose: np.ndarray) -> Pose:
    """A 4x4 pose as geometry_msgs/Pose (quaternion with w >= 0)."""
    x, y, z, w = (float(v) for v in quaternion_from_pose(pose[None])[0])
    position = Point(*(float(v) for v in pose[:3, 3]))
    return Pose(position=position, orientation=Quaternion(x=x, y=y, z=z, w=w))


def pose_matrix(pose: Pose) -> np.ndarray:
    """geometry_msgs/Pose as a 4x4 pose (the quaternion normalised)."""
    q = pose.orientation
    translation = np.array([pose.position.x, pose.position.y, pose.position.z])
    return pose_from_quaternion(translation, np.array([q.x, q.y, q.z, q.w]))[0]


def transform_message(parent: str, child: str, pose: np.ndarray, nanoseconds: int) -> TransformStamped:
    """T_parent_child as a stamped tf transform."""
    message = pose_message(pose)
    translation = Vector3(message.position.x, message.position.y, message.position.z)
    return TransformStamped(
        header=_header(nanoseconds, parent),
        child_frame_id=child,
        transform=Transform(translation=translation, rotation=message.orientation),
    )


def tf_message(transforms: Iterable[TransformStamped]) -> TFMessage:
    return TFMessage(transforms=list(transforms))


def odometry_message(
    pose: np.ndarray, linear: np.ndarray, angular: np.ndarray, nanoseconds: int, frame: str, child: str
) -> Odometry:
    """The corrected pose of `child` in `frame`, with the body-frame velocities of the step. The covariances are
    left zero: NeoSLAM does not estimate them per frame (ROS's convention for "not given")."""
    twist = Twist(linear=Vector3(*(float(v) for v in linear)), angular=Vector3(*(float(v) for v in angular)))
    return Odometry(
        header=_header(nanoseconds, frame),
        child_frame_id=child,
        pose=PoseWithCovariance(pose=pose_message(pose)),
        twist=TwistWithCovariance(twist=twist),
    )


def path_message(poses: np.ndarray, stamps: Sequence[int], frame: str, nanoseconds: int) -> Path:
    """The trajectory (n, 4, 4) with each pose's stamp (ns), in `frame`."""
    quaternions = quaternion_from_pose(poses) if len(poses) else np.zeros((0, 4))
    entries = []
    for pose, quaternion, stamp in zip(poses, quaternions, stamps, strict=True):
        x, y, z, w = (float(v) for v in quaternion)
        message = Pose(position=Point(*(float(v) for v in pose[:3, 3])), orientation=Quaternion(x, y, z, w))
        entries.append(PoseStamped(header=_header(stamp, frame), pose=message))
    return Path(header=_header(nanoseconds, frame), poses=entries)


def _colour(label: str) -> ColorRGBA:
    r, g, b = CLASS_COLOURS.get(label, OTHER_COLOUR)
    return ColorRGBA(r=r, g=g, b=b, a=1.0)


def object_markers(objects: Sequence[MapObject], frame: str, nanoseconds: int) -> MarkerArray:
    """The object map for RViz: first a DELETEALL (objects merge and are forgotten, so the set is replaced whole),
    then per object a cube of its class's size and a text label "class id" above it; marker ids are object ids."""
    header = _header(nanoseconds, frame)
    markers = [Marker(header=header, action=MARKER_DELETEALL)]
    for item in objects:
        x, y, z = (float(v) for v in item.position)
        scale = Vector3(*OBJECT_SCALE_M.get(item.label, OTHER_SCALE_M))
        markers.append(
            Marker(
                header=header,
                ns=MARKER_NAMESPACE,
                id=int(item.id),
                type=MARKER_CUBE,
                pose=Pose(position=Point(x, y, z)),
                scale=scale,
                color=_colour(item.label),
            )
        )
        markers.append(
            Marker(
                header=header,
                ns=LABEL_NAMESPACE,
                id=int(item.id),
                type=MARKER_TEXT_VIEW_FACING,
                pose=Pose(position=Point(x, y, z + LABEL_LIFT_M)),
                scale=Vector3(z=LABEL_HEIGHT_M),
                color=ColorRGBA(1.0, 1.0, 1.0, 1.0),
                text=f"{item.label} {item.id}",
            )
        )
    return MarkerArray(markers=markers)


def event_message(kind: str, nanoseconds: int, **fields: Any) -> String:
    """An event as one JSON object in a std_msgs/String: {"event": kind, "stamp_ns": ..., fields...}, keys in a
    fixed order so that the same event gives the same bytes."""
    return String(data=json.dumps({"event": kind, "stamp_ns": int(nanoseconds), **fields}, sort_keys=False))


def status_message(name: str, level: str, message: str, values: dict[str, Any], nanoseconds: int) -> DiagnosticArray:
    """The node's status as diagnostic_msgs/DiagnosticArray (what `ros2 topic echo` and rqt_runtime_monitor show)."""
    pairs = [KeyValue(key=str(key), value=str(value)) for key, value in values.items()]
    status = DiagnosticStatus(level=STATUS_LEVELS[level], name=name, message=message, values=pairs)
    return DiagnosticArray(header=_header(nanoseconds, ""), status=[status])
