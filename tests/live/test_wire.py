"""Wire compatibility: every message the live node reads or writes serialises, through Cyclone DDS, to exactly the
bytes of rosbags' ROS 2 serialisation (the Humble and Jazzy type stores), over random messages; and rosbags' bytes
read back through Cyclone give the same message.

One random value tree per example is built from rosbags' own field definitions, then made into both a rosbags
message and a Cyclone sample, so the two sides are never written from one another."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.conftest import require_extra

require_extra("cyclonedds", "ros2")

from neoslam.live.messages import MESSAGE_TYPES, dds_type_name  # noqa: E402

typesys = pytest.importorskip("rosbags.typesys")
STORES = {"humble": typesys.Stores.ROS2_HUMBLE, "jazzy": typesys.Stores.ROS2_JAZZY}
NODETYPE = typesys.base.Nodetype if hasattr(typesys, "base") else None

INTEGER_RANGES = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    # ROS 2's byte is an octet (0-255), but rosbags packs it as a signed char: the range both sides take
    "byte": (0, 2**7 - 1),
    "octet": (0, 2**8 - 1),
    "char": (0, 2**7 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
NUMPY_TYPES = {"float32": np.float32, "float64": np.float64, "bool": np.bool_, "byte": np.uint8, "char": np.uint8}
MAX_SEQUENCE = 3
ROS_STRING = st.text(alphabet=st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)), max_size=12)


def _typestore(distro: str) -> Any:
    return typesys.get_typestore(STORES[distro])


def _kind(node: tuple) -> str:
    return node[0].name  # BASE, NAME, ARRAY, SEQUENCE


def _base_strategy(base: str) -> st.SearchStrategy:
    if base in INTEGER_RANGES:
        low, high = INTEGER_RANGES[base]
        return st.integers(low, high)
    if base == "float64":
        return st.floats(allow_nan=False)
    if base == "float32":
        return st.floats(allow_nan=False, width=32)
    if base == "bool":
        return st.booleans()
    if base == "string":
        return ROS_STRING
    raise AssertionError(f"no strategy for base type {base}")


def _field_strategy(store: Any, node: tuple) -> st.SearchStrategy:
    kind = _kind(node)
    if kind == "BASE":
        return _base_strategy(node[1][0])
    if kind == "NAME":
        return _message_strategy(store, node[1])
    sub, length = node[1]
    if kind == "SEQUENCE" and _kind(sub) == "BASE" and sub[1][0] in ("uint8", "byte", "octet"):
        return st.binary(max_size=16)
    element = _field_strategy(store, sub)
    if kind == "ARRAY":
        return st.lists(element, min_size=length, max_size=length)
    return st.lists(element, max_size=MAX_SEQUENCE)


def _message_strategy(store: Any, name: str) -> st.SearchStrategy:
    fields = store.fielddefs[name][1]
    return st.fixed_dictionaries({field: _field_strategy(store, node) for field, node in fields})


def _rosbags_message(store: Any, name: str, values: dict) -> Any:
    arguments = {}
    for field, node in store.fielddefs[name][1]:
        arguments[field] = _rosbags_value(store, node, values[field])
    return store.types[name](**arguments)


def _rosbags_value(store: Any, node: tuple, value: Any) -> Any:
    kind = _kind(node)
    if kind == "BASE":
        return value
    if kind == "NAME":
        return _rosbags_message(store, node[1], value)
    sub = node[1][0]
    if _kind(sub) == "BASE" and sub[1][0] != "string":
        base = sub[1][0]
        dtype = NUMPY_TYPES.get(base, getattr(np, base, None))
        data = np.frombuffer(value, dtype=np.uint8) if isinstance(value, bytes) else value
        return np.array(data, dtype=dtype)
    return [_rosbags_value(store, sub, item) for item in value]


def _dds_sample(store: Any, name: str, values: dict) -> Any:
    arguments = {}
    for field, node in store.fielddefs[name][1]:
        arguments[field] = _dds_value(store, node, values[field])
    return MESSAGE_TYPES[name](**arguments)


def _dds_value(store: Any, node: tuple, value: Any) -> Any:
    kind = _kind(node)
    if kind == "BASE":
        return value
    if kind == "NAME":
        return _dds_sample(store, node[1], value)
    if isinstance(value, bytes):
        return value
    return [_dds_value(store, node[1][0], item) for item in value]


def _check_round_trip(distro: str, name: str, values: dict) -> None:
    store = _typestore(distro)
    sample = _dds_sample(store, name, values)
    expected = bytes(store.serialize_cdr(_rosbags_message(store, name, values), name))
    assert bytes(sample.serialize()) == expected
    assert MESSAGE_TYPES[name].deserialize(expected) == sample


@pytest.mark.parametrize("distro", sorted(STORES))
@pytest.mark.parametrize("name", sorted(MESSAGE_TYPES))
def test_every_type_has_the_fields_of_the_ros2_definition(distro: str, name: str) -> None:
    store = _typestore(distro)
    declared = list(MESSAGE_TYPES[name].__dataclass_fields__)
    assert declared == [field for field, _ in store.fielddefs[name][1]]
    assert MESSAGE_TYPES[name].__idl_typename__ == dds_type_name(name)


@pytest.mark.parametrize("distro", sorted(STORES))
@pytest.mark.parametrize("name", sorted(MESSAGE_TYPES))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_random_messages_serialise_to_the_bytes_of_rosbags(distro: str, name: str, data: st.DataObject) -> None:
    values = data.draw(_message_strategy(_typestore(distro), name))
    _check_round_trip(distro, name, values)


def test_an_image_of_a_real_frame_size_is_the_same_bytes() -> None:
    """A 1241x376 mono8 frame (KITTI's size): 466 kB of pixels through the `bytes` field."""
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, size=376 * 1241, dtype=np.uint8).tobytes()
    header = {"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "camera_left"}
    values = {"header": header, "height": 376, "width": 1241, "encoding": "mono8", "is_bigendian": 0}
    values |= {"step": 1241, "data": pixels}
    for distro in STORES:
        _check_round_trip(distro, "sensor_msgs/msg/Image", values)
