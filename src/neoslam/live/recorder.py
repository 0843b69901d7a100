"""ROS 2 topics recorded into a ROS 2 bag (rosbags' writer, sqlite3 or mcap storage), with no ROS installation.

As `ros2 bag record` does, each topic is subscribed with the QoS its publisher offers (so a transient-local path or
map published before the recording started is still recorded) and each message is stored as its CDR bytes with
the time it was received. Only the message types of neoslam.live.messages can be recorded (those the live node
reads and writes).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.util import duration

from neoslam.errors import ConfigError
from neoslam.live.messages import MESSAGE_TYPES
from neoslam.live.transport import Publication, Ros2Domain, taken

__all__ = ["RecordReport", "record_topics"]

DISCOVERY_POLL_S = 0.05
WAIT_S = 0.05
READER_DEPTH = 100
STORAGES = ("sqlite3", "mcap")


@dataclass
class RecordReport:
    """What was recorded: messages per topic, and topics asked for that never appeared."""

    messages: dict[str, int] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)


def _discover(domain: Ros2Domain, topics: list[str], timeout_s: float, stop: threading.Event) -> dict[str, Publication]:
    """The publishers of the wanted topics, waiting up to `timeout_s` for all of them to appear."""
    deadline = time.monotonic() + timeout_s
    while True:
        found = {p.topic: p for p in domain.publications() if p.topic in topics}
        if len(found) == len(topics) or time.monotonic() >= deadline or stop.is_set():
            return found
        time.sleep(DISCOVERY_POLL_S)


def record_topics(
    domain: Ros2Domain,
    topics: list[str],
    bag: Path,
    stop: threading.Event,
    discovery_s: float = 10.0,
    storage: str = "sqlite3",
    idle_exit_s: float | None = None,
    ready: Callable[[list[str]], None] | None = None,
) -> RecordReport:
    """Record `topics` into a new ROS 2 bag folder `bag` until `stop` is set (or nothing came for `idle_exit_s`
    after something did). A topic must appear within `discovery_s`; one that does not is left out (named in the
    report). The bag is written through rosbags; `bag` must not exist."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    if storage not in STORAGES:
        raise ConfigError(f"unknown bag storage {storage!r}; choose {' or '.join(STORAGES)}")
    publications = _discover(domain, topics, discovery_s, stop)
    unknown = sorted(p.topic for p in publications.values() if p.type_name not in MESSAGE_TYPES)
    if unknown:
        raise ConfigError(f"cannot record {', '.join(unknown)}: only the live node's message types are known")
    typestore = get_typestore(Stores.ROS2_JAZZY)
    report = RecordReport(missing=[t for t in topics if t not in publications])
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(bag, version=Writer.VERSION_LATEST, storage_plugin=plugin) as writer:
        readers: dict[str, tuple[Any, Any]] = {}
        for topic, publication in sorted(publications.items()):
            message_type = MESSAGE_TYPES[publication.type_name]
            reader = domain.reader(topic, message_type, publication.reader_qos(READER_DEPTH))
            connection = writer.add_connection(topic, publication.type_name, typestore=typestore)
            readers[topic] = (reader, connection)
            report.messages[topic] = 0
        if ready is not None:
            ready(sorted(readers))
        _drain_until_stopped(domain, readers, writer, report, stop, idle_exit_s)
    return report


def _drain_until_stopped(
    domain: Ros2Domain,
    readers: dict[str, tuple[Any, Any]],
    writer: Any,
    report: RecordReport,
    stop: threading.Event,
    idle_exit_s: float | None,
) -> None:
    waitset = WaitSet(domain.participant)
    mask = SampleState.NotRead | ViewState.Any | InstanceState.Any
    for reader, _ in readers.values():
        waitset.attach(ReadCondition(reader, mask))
    last = None
    while not stop.is_set():
        waitset.wait(duration(seconds=WAIT_S))
        now = time.monotonic()
        for topic, (reader, connection) in readers.items():
            for sample in taken(reader, READER_DEPTH):
                writer.write(connection, time.time_ns(), bytes(sample.serialize()))
                report.messages[topic] += 1
                last = now
        if idle_exit_s is not None and last is not None and now - last > idle_exit_s:
            return
