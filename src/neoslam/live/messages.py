"""The ROS 2 messages the live node reads and writes, declared for Eclipse Cyclone DDS.

A ROS 2 topic `/name` of type `pkg/msg/Type` is the DDS topic `rt/name` of type `pkg::msg::dds_::Type_`; its
samples are plain CDR (XCDR1, little-endian), so a struct declared here field by field, in the order and with the
widths of the `.msg` definition, serialises to the bytes any ROS 2 node sends. Field names do not reach the wire;
they are ROS 2's so that code reads the same as with rclpy. The `uint8[]` fields (image data) hold `bytes`: Cyclone
would read them as a list of Python ints, 5 ms for one camera frame before any conversion, so their members are
read and written as one block of bytes (`_as_bytes`: the same CDR, a uint32 length and the octets). The annotations
are evaluated when the classes are made (no `from __future__ import annotations`): Cyclone reads them as types.

The definitions are those of ROS 2 Humble and Jazzy, which agree on every type here (Jazzy adds only a constant to
Marker). `tests/live/test_wire.py` checks each type's bytes against rosbags' Humble and Jazzy type stores.
"""

from dataclasses import dataclass, field

import cyclonedds.idl.types as t
from cyclonedds.idl import IdlStruct
from cyclonedds.idl._machinery import BytesMachine

__all__ = [
    "MESSAGE_TYPES",
    "dds_type_name",
    "ros_type_name",
    "Time",
    "Duration",
    "Header",
    "ColorRGBA",
    "String",
    "Point",
    "Quaternion",
    "Pose",
    "PoseWithCovariance",
    "Vector3",
    "Twist",
    "TwistWithCovariance",
    "Transform",
    "TransformStamped",
    "PoseStamped",
    "RegionOfInterest",
    "CameraInfo",
    "Image",
    "CompressedImage",
    "Odometry",
    "Path",
    "TFMessage",
    "UVCoordinate",
    "MeshFile",
    "Marker",
    "MarkerArray",
    "KeyValue",
    "DiagnosticStatus",
    "DiagnosticArray",
]

COVARIANCE_SIZE = 36  # 6x6, row-major (x, y, z, rotation about x, y, z)


def dds_type_name(ros_name: str) -> str:
    """`sensor_msgs/msg/Image` -> `sensor_msgs::msg::dds_::Image_` (the name ROS 2's DDS middleware gives a type)."""
    package, kind, name = ros_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def _zeros(size: int):
    return field(default_factory=lambda: [0.0] * size)


# --- builtin_interfaces, std_msgs ---


@dataclass
class Time(IdlStruct, typename=dds_type_name("builtin_interfaces/msg/Time")):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Duration(IdlStruct, typename=dds_type_name("builtin_interfaces/msg/Duration")):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header(IdlStruct, typename=dds_type_name("std_msgs/msg/Header")):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class ColorRGBA(IdlStruct, typename=dds_type_name("std_msgs/msg/ColorRGBA")):
    r: t.float32 = 0.0
    g: t.float32 = 0.0
    b: t.float32 = 0.0
    a: t.float32 = 0.0


@dataclass
class String(IdlStruct, typename=dds_type_name("std_msgs/msg/String")):
    data: str = ""


# --- geometry_msgs ---


@dataclass
class Point(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Point")):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Quaternion")):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@dataclass
class Pose(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Pose")):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseWithCovariance(IdlStruct, typename=dds_type_name("geometry_msgs/msg/PoseWithCovariance")):
    pose: Pose = field(default_factory=Pose)
    covariance: t.array[t.float64, COVARIANCE_SIZE] = _zeros(COVARIANCE_SIZE)


@dataclass
class Vector3(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Vector3")):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Twist(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Twist")):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class TwistWithCovariance(IdlStruct, typename=dds_type_name("geometry_msgs/msg/TwistWithCovariance")):
    twist: Twist = field(default_factory=Twist)
    covariance: t.array[t.float64, COVARIANCE_SIZE] = _zeros(COVARIANCE_SIZE)


@dataclass
class Transform(IdlStruct, typename=dds_type_name("geometry_msgs/msg/Transform")):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename=dds_type_name("geometry_msgs/msg/TransformStamped")):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class PoseStamped(IdlStruct, typename=dds_type_name("geometry_msgs/msg/PoseStamped")):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


# --- sensor_msgs ---


@dataclass
class RegionOfInterest(IdlStruct, typename=dds_type_name("sensor_msgs/msg/RegionOfInterest")):
    x_offset: t.uint32 = 0
    y_offset: t.uint32 = 0
    height: t.uint32 = 0
    width: t.uint32 = 0
    do_rectify: bool = False


@dataclass
class CameraInfo(IdlStruct, typename=dds_type_name("sensor_msgs/msg/CameraInfo")):
    header: Header = field(default_factory=Header)
    height: t.uint32 = 0
    width: t.uint32 = 0
    distortion_model: str = ""
    d: t.sequence[t.float64] = field(default_factory=list)
    k: t.array[t.float64, 9] = _zeros(9)
    r: t.array[t.float64, 9] = _zeros(9)
    p: t.array[t.float64, 12] = _zeros(12)
    binning_x: t.uint32 = 0
    binning_y: t.uint32 = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class Image(IdlStruct, typename=dds_type_name("sensor_msgs/msg/Image")):
    header: Header = field(default_factory=Header)
    height: t.uint32 = 0
    width: t.uint32 = 0
    encoding: str = ""
    is_bigendian: t.uint8 = 0
    step: t.uint32 = 0
    data: t.sequence[t.uint8] = b""


@dataclass
class CompressedImage(IdlStruct, typename=dds_type_name("sensor_msgs/msg/CompressedImage")):
    header: Header = field(default_factory=Header)
    format: str = ""
    data: t.sequence[t.uint8] = b""


# --- nav_msgs, tf2_msgs ---


@dataclass
class Odometry(IdlStruct, typename=dds_type_name("nav_msgs/msg/Odometry")):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@dataclass
class Path(IdlStruct, typename=dds_type_name("nav_msgs/msg/Path")):
    header: Header = field(default_factory=Header)
    poses: t.sequence[PoseStamped] = field(default_factory=list)


@dataclass
class TFMessage(IdlStruct, typename=dds_type_name("tf2_msgs/msg/TFMessage")):
    transforms: t.sequence[TransformStamped] = field(default_factory=list)


# --- visualization_msgs ---


@dataclass
class UVCoordinate(IdlStruct, typename=dds_type_name("visualization_msgs/msg/UVCoordinate")):
    u: t.float32 = 0.0
    v: t.float32 = 0.0


@dataclass
class MeshFile(IdlStruct, typename=dds_type_name("visualization_msgs/msg/MeshFile")):
    filename: str = ""
    data: t.sequence[t.uint8] = b""


@dataclass
class Marker(IdlStruct, typename=dds_type_name("visualization_msgs/msg/Marker")):
    header: Header = field(default_factory=Header)
    ns: str = ""
    id: t.int32 = 0
    type: t.int32 = 0
    action: t.int32 = 0
    pose: Pose = field(default_factory=Pose)
    scale: Vector3 = field(default_factory=Vector3)
    color: ColorRGBA = field(default_factory=ColorRGBA)
    lifetime: Duration = field(default_factory=Duration)
    frame_locked: bool = False
    points: t.sequence[Point] = field(default_factory=list)
    colors: t.sequence[ColorRGBA] = field(default_factory=list)
    texture_resource: str = ""
    texture: CompressedImage = field(default_factory=CompressedImage)
    uv_coordinates: t.sequence[UVCoordinate] = field(default_factory=list)
    text: str = ""
    mesh_resource: str = ""
    mesh_file: MeshFile = field(default_factory=MeshFile)
    mesh_use_embedded_materials: bool = False


@dataclass
class MarkerArray(IdlStruct, typename=dds_type_name("visualization_msgs/msg/MarkerArray")):
    markers: t.sequence[Marker] = field(default_factory=list)


# --- diagnostic_msgs ---


@dataclass
class KeyValue(IdlStruct, typename=dds_type_name("diagnostic_msgs/msg/KeyValue")):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename=dds_type_name("diagnostic_msgs/msg/DiagnosticStatus")):
    level: t.uint8 = 0  # OK 0, WARN 1, ERROR 2, STALE 3
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: t.sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename=dds_type_name("diagnostic_msgs/msg/DiagnosticArray")):
    header: Header = field(default_factory=Header)
    status: t.sequence[DiagnosticStatus] = field(default_factory=list)


def _as_bytes(message_type: type[IdlStruct], member: str) -> None:
    """Read and write a uint8[] member as `bytes` (its type information stays sequence<uint8>)."""
    idl = message_type.__idl__
    idl.populate()
    for machine in (idl.v1_machine, idl.v2_machine):
        machine.members_machines[member] = BytesMachine()


for _octet_message in (Image, CompressedImage, MeshFile):
    _as_bytes(_octet_message, "data")

MESSAGE_TYPES: dict[str, type[IdlStruct]] = {
    "builtin_interfaces/msg/Time": Time,
    "builtin_interfaces/msg/Duration": Duration,
    "std_msgs/msg/Header": Header,
    "std_msgs/msg/ColorRGBA": ColorRGBA,
    "std_msgs/msg/String": String,
    "geometry_msgs/msg/Point": Point,
    "geometry_msgs/msg/Quaternion": Quaternion,
    "geometry_msgs/msg/Pose": Pose,
    "geometry_msgs/msg/PoseWithCovariance": PoseWithCovariance,
    "geometry_msgs/msg/Vector3": Vector3,
    "geometry_msgs/msg/Twist": Twist,
    "geometry_msgs/msg/TwistWithCovariance": TwistWithCovariance,
    "geometry_msgs/msg/Transform": Transform,
    "geometry_msgs/msg/TransformStamped": TransformStamped,
    "geometry_msgs/msg/PoseStamped": PoseStamped,
    "sensor_msgs/msg/RegionOfInterest": RegionOfInterest,
    "sensor_msgs/msg/CameraInfo": CameraInfo,
    "sensor_msgs/msg/Image": Image,
    "sensor_msgs/msg/CompressedImage": CompressedImage,
    "nav_msgs/msg/Odometry": Odometry,
    "nav_msgs/msg/Path": Path,
    "tf2_msgs/msg/TFMessage": TFMessage,
    "visualization_msgs/msg/UVCoordinate": UVCoordinate,
    "visualization_msgs/msg/MeshFile": MeshFile,
    "visualization_msgs/msg/Marker": Marker,
    "visualization_msgs/msg/MarkerArray": MarkerArray,
    "diagnostic_msgs/msg/KeyValue": KeyValue,
    "diagnostic_msgs/msg/DiagnosticStatus": DiagnosticStatus,
    "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
}
_ROS_NAMES = {cls: name for name, cls in MESSAGE_TYPES.items()}


def ros_type_name(message_type: type[IdlStruct]) -> str:
    """The ROS 2 name (`pkg/msg/Type`) of a message type declared here."""
    return _ROS_NAMES[message_type]
