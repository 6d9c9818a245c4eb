"""ROS 2 messages and their CDR bytes, without ROS 2: ``rosbags``' typestore for ROS 2 Jazzy.

    msg = types()[LASER_SCAN](header=..., angle_min=..., ...)   # rosbags' message classes
    data = serialize(msg)                       # CDR with its 4-byte encapsulation header
    msg = deserialize(data, LASER_SCAN)         # DecodeError on anything malformed
    type_hash(LASER_SCAN)  -> "RIHS01_64c1..."  # REP-2016, as in rmw_zenoh's keys
    msgdef(LASER_SCAN)     -> the .msg text with its dependencies (MCAP's "ros2msg" schema)

The payload of an rmw_zenoh sample is exactly these bytes: the CDR encapsulation (``00 01 00
00``, little-endian; big-endian ``00 00`` is read too) and the message, padded to at most 3
bytes. The message types and hashes are those of Jazzy; Iron, Kilted and Rolling have the same
hashes for the types used here (the tests check the four), Humble has no type hashes.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from rosbags.typesys import Stores, get_typestore

from protocol.codec import MAX_PAYLOAD, DecodeError

__all__ = [
    "CLOCK",
    "LASER_SCAN",
    "ODOMETRY",
    "TF_MESSAGE",
    "TWIST",
    "TWIST_STAMPED",
    "deserialize",
    "msgdef",
    "serialize",
    "type_hash",
    "types",
]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
CLOCK = "rosgraph_msgs/msg/Clock"

STORE = Stores.ROS2_JAZZY


@cache
def _store():
    return get_typestore(STORE)


def types() -> dict[str, type]:
    """The message classes by ROS 2 type name (``types()[TWIST](linear=..., angular=...)``)."""
    return _store().types


def _known(typename: str) -> None:
    if typename not in _store().types:
        raise ValueError(f"{typename!r} is not a ROS 2 {STORE.name} message type")


@cache
def type_hash(typename: str) -> str:
    """The type's RIHS01 hash (``RIHS01_`` and 64 hex digits), as ROS 2 computes it."""
    _known(typename)
    return _store().hash_rihs01(typename)


@cache
def msgdef(typename: str) -> str:
    """The type's complete ``.msg`` definition: its own fields first, then each type it uses
    after a line of 80 ``=`` and ``MSG: <package>/<Name>`` (the "ros2msg" schema encoding of
    MCAP files and rosbag2)."""
    _known(typename)
    return _store().generate_msgdef(typename, ros_version=2)[0]


def serialize(msg: Any) -> bytes:
    """CDR bytes (little-endian, with the encapsulation header) of a rosbags message."""
    typename = getattr(msg, "__msgtype__", None)
    if not isinstance(typename, str):
        raise ValueError(f"expected a ROS 2 message of the typestore, got {type(msg).__name__}")
    return bytes(_store().serialize_cdr(msg, typename))


def deserialize(data: Any, typename: str, max_size: int = MAX_PAYLOAD) -> Any:
    """The message of type ``typename`` in the CDR ``data`` (bytes, or a zenoh payload). Too
    large, truncated, padded by more than 3 bytes, with another encapsulation or with a bad
    length or string inside: :class:`DecodeError` naming the type."""
    _known(typename)
    if hasattr(data, "to_bytes"):  # zenoh.ZBytes
        data = data.to_bytes()
    if not isinstance(data, bytes | bytearray | memoryview):
        raise DecodeError(f"{typename}: expected CDR bytes, got {type(data).__name__}")
    if len(data) > max_size:
        raise DecodeError(f"{typename}: payload of {len(data)} bytes exceeds the "
                          f"{max_size}-byte limit")
    try:
        return _store().deserialize_cdr(bytes(data), typename)
    except Exception as e:  # rosbags raises SerdeError; anything else is malformed input too
        raise DecodeError(f"{typename}: not valid CDR ({type(e).__name__}: {e})") from None
