"""ROS 2 topics over Eclipse Cyclone DDS, with no ROS installation: names, QoS profiles, readers and writers.

A ROS 2 topic `/a/b` is the DDS topic `rt/a/b`; its type `pkg/msg/T` the DDS type `pkg::msg::dds_::T_`
(neoslam.live.messages). The QoS profiles are those ROS 2 drivers and tools use:

- sensor data (camera images, CameraInfo, odometry in): best effort, keep last N, volatile
  (rclcpp's `SensorDataQoS`): a subscriber that asks for no more than best effort matches every publisher;
- state (the corrected odometry, tf, events, status): reliable, keep last N, volatile (ROS 2's default profile);
- map (the path, the object markers): reliable, keep last 1, transient local, so that RViz or a recorder that
  starts later gets the latest at once (as map servers publish); events the same with a deeper history.

Writers carry ROS 2's type hash in their user data (`typehash=RIHS01_...;`, as rmw_cyclonedds writes it from
Iron on; Humble ignores it), computed by rosbags from the message definition.
"""

from __future__ import annotations

from contextlib import suppress
from dataclasses import dataclass
from typing import Any

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from neoslam.live.messages import ros_type_name

__all__ = [
    "ROS_PREFIX",
    "Ros2Domain",
    "dds_topic",
    "ros_topic",
    "sensor_qos",
    "state_qos",
    "map_qos",
    "event_qos",
    "type_hash",
    "taken",
]

ROS_PREFIX = "rt/"  # ROS 2's prefix of DDS topics that carry messages (rq/ and rr/ carry services)
RELIABLE_BLOCKING_S = 0.1  # the longest a reliable write may wait for a slow reader's acknowledgements
DISCOVERY_PUBLICATIONS = 256  # publications read from the DDS discovery data at once


def dds_topic(ros_name: str) -> str:
    """`/left/image_raw` (or `left/image_raw`, relative to the root namespace) -> `rt/left/image_raw`."""
    return ROS_PREFIX + ros_name.lstrip("/")


def ros_topic(dds_name: str) -> str | None:
    """`rt/left/image_raw` -> `/left/image_raw`; None for a DDS topic that is not a ROS 2 message topic."""
    return "/" + dds_name[len(ROS_PREFIX) :] if dds_name.startswith(ROS_PREFIX) else None


def sensor_qos(depth: int) -> Qos:
    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(depth), Policy.Durability.Volatile)


def state_qos(depth: int) -> Qos:
    reliability = Policy.Reliability.Reliable(duration(seconds=RELIABLE_BLOCKING_S))
    return Qos(reliability, Policy.History.KeepLast(depth), Policy.Durability.Volatile)


def map_qos() -> Qos:
    return event_qos(1)


def event_qos(depth: int) -> Qos:
    """Reliable and transient local: a reader that joins later still gets the last `depth` samples."""
    reliability = Policy.Reliability.Reliable(duration(seconds=RELIABLE_BLOCKING_S))
    return Qos(reliability, Policy.History.KeepLast(depth), Policy.Durability.TransientLocal)


_HASHES: dict[str, str] = {}


def type_hash(ros_name: str) -> str:
    """ROS 2's type hash (RIHS01) of a message type, from rosbags' Jazzy type store (cached)."""
    if ros_name not in _HASHES:
        from rosbags.typesys import Stores, get_typestore

        _HASHES[ros_name] = get_typestore(Stores.ROS2_JAZZY).hash_rihs01(ros_name)
    return _HASHES[ros_name]


def _with_type_hash(qos: Qos, message_type: type) -> Qos:
    user_data = f"typehash={type_hash(ros_type_name(message_type))};".encode()
    return Qos(*qos, Policy.Userdata(user_data))


@dataclass(frozen=True)
class Publication:
    """A publisher seen on the domain: its ROS 2 topic and type names, and whether it is reliable and transient
    local (a reader asking for no more than the writer offers matches it)."""

    topic: str
    type_name: str
    reliable: bool = False
    transient_local: bool = False

    def reader_qos(self, depth: int) -> Qos:
        """The QoS that matches this writer and keeps what it offers (as `ros2 bag record` adapts to a publisher)."""
        if not self.reliable:
            return sensor_qos(depth)
        return event_qos(depth) if self.transient_local else state_qos(depth)


class Ros2Domain:
    """One DDS participant on a ROS 2 domain (ROS_DOMAIN_ID), making the node's readers and writers."""

    def __init__(self, domain_id: int) -> None:
        self.domain_id = domain_id
        self.participant = DomainParticipant(domain_id)
        self._topics: dict[str, Topic] = {}
        self._discovery: BuiltinDataReader | None = None

    def _topic(self, ros_name: str, message_type: type) -> Topic:
        if ros_name not in self._topics:
            self._topics[ros_name] = Topic(self.participant, dds_topic(ros_name), message_type)
        return self._topics[ros_name]

    def reader(self, ros_name: str, message_type: type, qos: Qos) -> DataReader:
        return DataReader(self.participant, self._topic(ros_name, message_type), qos=qos)

    def writer(self, ros_name: str, message_type: type, qos: Qos) -> DataWriter:
        return DataWriter(self.participant, self._topic(ros_name, message_type), qos=_with_type_hash(qos, message_type))

    def start_discovery(self) -> None:
        """Start reading the domain's discovery data (publications), for `publications()` later."""
        if self._discovery is None:
            self._discovery = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)

    def publications(self) -> list[Publication]:
        """The ROS 2 message topics other participants publish on this domain, as discovered so far."""
        self.start_discovery()
        assert self._discovery is not None
        own = self.participant.guid
        seen: dict[str, Publication] = {}
        for sample in self._discovery.read(N=DISCOVERY_PUBLICATIONS):
            topic = ros_topic(sample.topic_name)
            if topic is None or _participant_of(sample) == own or not sample.sample_info.valid_data:
                continue
            policies = list(sample.qos) if sample.qos is not None else []
            reliable = any(isinstance(p, Policy.Reliability.Reliable) for p in policies)
            transient = any(p == Policy.Durability.TransientLocal for p in policies)
            seen[topic] = Publication(topic, _ros_type(sample.type_name), reliable, transient)
        return [seen[topic] for topic in sorted(seen)]

    def close(self) -> None:
        """Delete the participant and everything it made (readers, writers, topics)."""
        with suppress(Exception):  # already deleted
            self.participant.__del__()


def taken(reader: Any, most: int) -> list[Any]:
    """Up to `most` samples taken from a reader, with data: a writer's disposal or unregistration (one that
    stopped) comes as a sample with no data, and is left out."""
    return [s for s in reader.take(N=most) if getattr(getattr(s, "sample_info", None), "valid_data", True)]


def _participant_of(sample: Any) -> Any:
    return getattr(sample, "participant_key", None)


def _ros_type(dds_name: str) -> str:
    """`sensor_msgs::msg::dds_::Image_` -> `sensor_msgs/msg/Image` (other names are kept as they are)."""
    parts = dds_name.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_name
