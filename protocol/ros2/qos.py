"""ROS 2 quality of service as rmw_zenoh encodes it in liveliness tokens (docs/ros2.md, "QoS").

A profile is a ``rosbags.interfaces.Qos`` (the rmw fields and enum values; what a rosbag2 file
records too). Before rmw_zenoh announces an entity it resolves the profile's "defaults"
(:func:`adapt`, rmw_zenoh's ``QoS::best_available_qos``), then writes each field that differs
from its own default profile, :data:`RMW_ZENOH_DEFAULT`, and leaves the others empty::

    <reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<lease s>,<ns>

    qos_to_keyexpr(DEFAULT_QOS)      -> "::,10:,:,:,,"       (ROS 2's default profile)
    qos_to_keyexpr(SENSOR_DATA_QOS)  -> "2::,5:,:,:,,"       (best effort, depth 5)
    qos_from_keyexpr("2::,5:,:,:,,") == adapt(SENSOR_DATA_QOS)

The numbers are rmw's enum values (reliability 1 reliable, 2 best effort; durability 1
transient local, 2 volatile; history 1 keep last, 2 keep all; liveliness 1 automatic, 3 manual
by topic). rmw_zenoh's default durability is volatile since rmw_zenoh 0.2.3 (Jazzy), 0.1.2
(Humble) and 0.5.0 (Rolling); before, it was transient local, so an older peer reads an empty
durability as transient local.
"""

from __future__ import annotations

import re

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from protocol.codec import DecodeError

__all__ = [
    "DEFAULT_QOS",
    "INFINITE",
    "RMW_ZENOH_DEFAULT",
    "SENSOR_DATA_QOS",
    "UNSPECIFIED",
    "Qos",
    "adapt",
    "qos_from_keyexpr",
    "qos_to_keyexpr",
]

INFINITE = QosTime(9223372036, 854775807)  # RMW_DURATION_INFINITE
UNSPECIFIED = QosTime(0, 0)  # RMW_DURATION_UNSPECIFIED: "the middleware's default"

# rmw's rmw_qos_profile_default and rmw_qos_profile_sensor_data (rmw/qos_profiles.h), what
# rclcpp passes for QoS(10) and SensorDataQoS().
DEFAULT_QOS = Qos(
    history=QosHistory.KEEP_LAST,
    depth=10,
    reliability=QosReliability.RELIABLE,
    durability=QosDurability.VOLATILE,
    deadline=UNSPECIFIED,
    lifespan=UNSPECIFIED,
    liveliness=QosLiveliness.SYSTEM_DEFAULT,
    liveliness_lease_duration=UNSPECIFIED,
    avoid_ros_namespace_conventions=False,
)
SENSOR_DATA_QOS = DEFAULT_QOS._replace(depth=5, reliability=QosReliability.BEST_EFFORT)

# rmw_zenoh's own defaults (qos.cpp): what an empty field in a token means.
RMW_ZENOH_DEFAULT = DEFAULT_QOS._replace(
    depth=42, deadline=INFINITE, lifespan=INFINITE, liveliness=QosLiveliness.AUTOMATIC,
    liveliness_lease_duration=INFINITE)

_UNKNOWN = (QosHistory.UNKNOWN, QosReliability.UNKNOWN, QosDurability.UNKNOWN,
            QosLiveliness.UNKNOWN)


def adapt(qos: Qos) -> Qos:
    """The profile rmw_zenoh announces for ``qos``: system defaults, depth 0 and unspecified
    durations replaced by :data:`RMW_ZENOH_DEFAULT`'s values. An UNKNOWN policy is refused
    (rmw_zenoh does not create such an entity)."""
    for v in (qos.history, qos.reliability, qos.durability, qos.liveliness):
        if v in _UNKNOWN:
            raise ValueError(f"a QoS policy of {v} is not supported by rmw_zenoh")
    d = RMW_ZENOH_DEFAULT

    def pick(value, system_default, default):
        return default if value == system_default else value

    return Qos(
        history=pick(qos.history, QosHistory.SYSTEM_DEFAULT, d.history),
        depth=d.depth if qos.depth == 0 else int(qos.depth),
        reliability=pick(qos.reliability, QosReliability.SYSTEM_DEFAULT, d.reliability),
        durability=pick(qos.durability, QosDurability.SYSTEM_DEFAULT, d.durability),
        deadline=pick(qos.deadline, UNSPECIFIED, d.deadline),
        lifespan=pick(qos.lifespan, UNSPECIFIED, d.lifespan),
        liveliness=pick(qos.liveliness, QosLiveliness.SYSTEM_DEFAULT, d.liveliness),
        liveliness_lease_duration=pick(qos.liveliness_lease_duration, UNSPECIFIED,
                                       d.liveliness_lease_duration),
        avoid_ros_namespace_conventions=qos.avoid_ros_namespace_conventions,
    )


def _field(value, default) -> str:
    if value == default:
        return ""
    return str(value.value if hasattr(value, "value") else int(value))


def qos_to_keyexpr(qos: Qos) -> str:
    """The ``<qos>`` chunk of a liveliness token for an entity created with ``qos``."""
    q, d = adapt(qos), RMW_ZENOH_DEFAULT
    return ":".join((
        _field(q.reliability, d.reliability),
        _field(q.durability, d.durability),
        f"{_field(q.history, d.history)},{_field(q.depth, d.depth)}",
        f"{_field(q.deadline.sec, d.deadline.sec)},{_field(q.deadline.nsec, d.deadline.nsec)}",
        f"{_field(q.lifespan.sec, d.lifespan.sec)},{_field(q.lifespan.nsec, d.lifespan.nsec)}",
        f"{_field(q.liveliness, d.liveliness)},"
        f"{_field(q.liveliness_lease_duration.sec, d.liveliness_lease_duration.sec)},"
        f"{_field(q.liveliness_lease_duration.nsec, d.liveliness_lease_duration.nsec)}",
    ))


_NUMBER = re.compile(r"^[0-9]{1,20}$")


def qos_from_keyexpr(text: str) -> Qos:
    """Parse a token's ``<qos>`` chunk (empty fields: :data:`RMW_ZENOH_DEFAULT`). A malformed
    chunk raises :class:`DecodeError` naming the field."""
    what = f"liveliness token QoS {text!r}"
    parts = text.split(":") if isinstance(text, str) else []
    sizes = (1, 1, 2, 2, 2, 3)
    if len(parts) != len(sizes):
        raise DecodeError(f"{what}: expected 6 ':'-separated fields, got {len(parts)}")
    fields = [p.split(",") for p in parts]
    for f, n, name in zip(fields, sizes, ("reliability", "durability", "history,depth",
                                          "deadline", "lifespan", "liveliness"), strict=True):
        if len(f) != n:
            raise DecodeError(f"{what}: field {name!r}: expected {n} ','-separated values, "
                              f"got {len(f)}")
    d = RMW_ZENOH_DEFAULT

    def num(s: str, default: int, name: str) -> int:
        if s == "":
            return default
        if not _NUMBER.match(s):
            raise DecodeError(f"{what}: field {name!r}: expected a non-negative integer, got {s!r}")
        return int(s)

    def enum(s: str, cls, default, name: str):
        v = num(s, default.value, name)
        try:
            return cls(v)
        except ValueError:
            raise DecodeError(f"{what}: field {name!r}: {v} is not a {cls.__name__} value "
                              f"({', '.join(f'{e.value} {e.name}' for e in cls)})") from None

    def duration(f: list[str], default: QosTime, name: str) -> QosTime:
        return QosTime(num(f[0], default.sec, name + " s"), num(f[1], default.nsec, name + " ns"))

    return Qos(
        history=enum(fields[2][0], QosHistory, d.history, "history"),
        depth=num(fields[2][1], d.depth, "depth"),
        reliability=enum(fields[0][0], QosReliability, d.reliability, "reliability"),
        durability=enum(fields[1][0], QosDurability, d.durability, "durability"),
        deadline=duration(fields[3], d.deadline, "deadline"),
        lifespan=duration(fields[4], d.lifespan, "lifespan"),
        liveliness=enum(fields[5][0], QosLiveliness, d.liveliness, "liveliness"),
        liveliness_lease_duration=duration(fields[5][1:], d.liveliness_lease_duration,
                                           "liveliness lease"),
        avoid_ros_namespace_conventions=False,
    )
