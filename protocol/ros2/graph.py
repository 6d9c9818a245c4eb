"""The ROS 2 graph over zenoh as rmw_zenoh lays it out: topic keys and liveliness tokens.

Data key of a topic (where its CDR samples are put)::

    <domain>/<fully qualified name without the leading '/'>/<DDS type name>/<RIHS01 type hash>
    Topic("/r0/scan", LASER_SCAN, SENSOR_DATA_QOS).key(0)
      -> "0/r0/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c1...d828"

Liveliness token of a node and of a publisher or subscription (what ``ros2 node list`` and
``ros2 topic list`` read; names mangled, ``/`` -> ``%``)::

    @ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>
    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<MP|MS>/<enclave>/<namespace>/<node>/<topic>/<DDS type>/<hash>/<qos>

    node = Node("rhbl_bridge", namespace="/r0")
    LivelinessToken.for_node(zid, 0, node).key()
    LivelinessToken.for_topic(zid, 0, 1, EntityKind.PUBLISHER, node, topic).key()
    LivelinessToken.parse(key)    # DecodeError if it is not such a token

``zid`` is the zenoh session id as zenoh prints it (``str(session.info.zid())``, lowercase
hex); node and entity ids are numbers unique within the session (rmw_zenoh counts them from 0
per context, nodes and entities alike). Every entity's GID (:meth:`LivelinessToken.gid`) is the
XXH3-128 hash of its token key, low 64 bits first, each little-endian: what rmw_zenoh reports
and puts in the sample attachments of a publisher.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import Enum

import xxhash

from protocol.codec import DecodeError
from protocol.ros2 import cdr
from protocol.ros2.names import (
    check_namespace,
    check_node_name,
    check_topic_name,
    dds_type_name,
    demangle,
    fully_qualified,
    mangle,
    ros_type_name,
)
from protocol.ros2.qos import (
    DEFAULT_QOS,
    SENSOR_DATA_QOS,
    Qos,
    qos_from_keyexpr,
    qos_to_keyexpr,
)

__all__ = [
    "ADMIN_SPACE",
    "EntityKind",
    "LivelinessToken",
    "Node",
    "RobotTopics",
    "Topic",
    "liveliness_space",
]

ADMIN_SPACE = "@ros2_lv"
_ZID = re.compile(r"^[0-9a-f]{1,32}$")
_HASH = re.compile(r"^RIHS01_[0-9a-f]{64}$")
_ID = re.compile(r"^[0-9]{1,20}$")


class EntityKind(Enum):
    """The ``<entity kind>`` chunk of a token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


def _domain(domain) -> int:
    if isinstance(domain, bool) or not isinstance(domain, int) or domain < 0:
        raise ValueError(f"a ROS 2 domain id is an integer >= 0, got {domain!r}")
    return domain


def liveliness_space(domain: int = 0) -> str:
    """What to subscribe to (or query) for every token of a domain: ``@ros2_lv/<domain>/**``."""
    return f"{ADMIN_SPACE}/{_domain(domain)}/**"


@dataclass(frozen=True)
class Node:
    """A ROS 2 node: its ``name``, ``namespace`` (``/`` if none), ``domain`` id and SROS
    ``enclave`` (``/`` if none)."""

    name: str
    namespace: str = "/"
    domain: int = 0
    enclave: str = "/"

    def __post_init__(self):
        check_node_name(self.name)
        check_namespace(self.namespace)
        _domain(self.domain)
        check_namespace(self.enclave)

    @property
    def fully_qualified_name(self) -> str:
        return ("" if self.namespace == "/" else self.namespace) + "/" + self.name


@dataclass(frozen=True)
class Topic:
    """A topic: its fully qualified ``name``, ROS 2 ``typename`` (``sensor_msgs/msg/LaserScan``),
    the ``qos`` of our endpoint and the type's RIHS01 ``type_hash`` (default: computed from the
    Jazzy typestore)."""

    name: str
    typename: str
    qos: Qos
    type_hash: str = ""

    def __post_init__(self):
        check_topic_name(self.name)
        dds_type_name(self.typename)
        if not self.type_hash:
            object.__setattr__(self, "type_hash", cdr.type_hash(self.typename))
        if not _HASH.match(self.type_hash):
            raise ValueError(f"a type hash is 'RIHS01_' and 64 lowercase hex digits, "
                             f"got {self.type_hash!r}")

    def key(self, domain: int = 0) -> str:
        """The zenoh key of this topic's samples in ``domain``."""
        return (f"{_domain(domain)}/{self.name[1:]}/{dds_type_name(self.typename)}/"
                f"{self.type_hash}")


@dataclass(frozen=True)
class RobotTopics:
    """The ROS 2 topics of one rhbl robot, with the QoS ROS 2 nodes use for them (docs/ros2.md,
    "Mapping"): ``scan`` (sensor data: best effort, depth 5), ``odom`` and ``cmd_vel`` (ROS 2's
    default: reliable, depth 10), ``tf`` (tf2's broadcaster: reliable, depth 100) and ``clock``
    (rclcpp's clock QoS: best effort, depth 1)."""

    scan: Topic
    odom: Topic
    cmd_vel: Topic
    tf: Topic
    clock: Topic

    @classmethod
    def of(cls, robot: str, namespace: str = "/", *, scan: str = "scan", odom: str = "odom",
           cmd_vel: str = "cmd_vel", tf: str = "/tf", clock: str = "/clock") -> RobotTopics:
        """``<namespace>/<robot>/scan``, ``.../odom``, ``.../cmd_vel``; ``/tf`` and ``/clock``
        are shared by every robot. ``robot`` must be a ROS 2 name token (no ``-`` or ``.``).
        Other names: a relative one is put under ``<namespace>/<robot>``, an absolute one
        (``/scan``) is kept as it is (a ValueError names a bad one)."""
        ns = fully_qualified(robot, namespace)
        return cls(
            scan=Topic(fully_qualified(scan, ns), cdr.LASER_SCAN, SENSOR_DATA_QOS),
            odom=Topic(fully_qualified(odom, ns), cdr.ODOMETRY, DEFAULT_QOS),
            cmd_vel=Topic(fully_qualified(cmd_vel, ns), cdr.TWIST, DEFAULT_QOS),
            tf=Topic(fully_qualified(tf, ns), cdr.TF_MESSAGE, DEFAULT_QOS._replace(depth=100)),
            clock=Topic(fully_qualified(clock, ns), cdr.CLOCK,
                        SENSOR_DATA_QOS._replace(depth=1)),
        )

    @property
    def cmd_vel_stamped(self) -> Topic:
        """The ``cmd_vel`` topic carrying ``geometry_msgs/msg/TwistStamped`` (what Nav2 sends
        with ``enable_stamped_cmd_vel``): another key, read beside the plain ``Twist``."""
        return Topic(self.cmd_vel.name, cdr.TWIST_STAMPED, self.cmd_vel.qos)

    @property
    def published(self) -> tuple[Topic, Topic, Topic, Topic]:
        """What an rhbl robot publishes to ROS 2: scan, odom, tf, clock."""
        return (self.scan, self.odom, self.tf, self.clock)


@dataclass(frozen=True)
class LivelinessToken:
    """One rmw_zenoh liveliness token: who (``zid``, ``node_id``, ``entity_id``), what
    (``kind``), on which ``node``, and for a publisher, subscription, service or client its
    ``topic`` (``None`` for a node)."""

    zid: str
    node_id: int
    entity_id: int
    kind: EntityKind
    node: Node
    topic: Topic | None = None

    def __post_init__(self):
        if not isinstance(self.zid, str) or not _ZID.match(self.zid):
            raise ValueError(f"a zenoh session id is 1-32 lowercase hex digits, got {self.zid!r}")
        for name in ("node_id", "entity_id"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        if not isinstance(self.kind, EntityKind):
            raise ValueError(f"kind must be an EntityKind, got {self.kind!r}")
        if (self.kind is EntityKind.NODE) != (self.topic is None):
            raise ValueError(f"a {self.kind.name.lower()} token "
                             f"{'has no' if self.kind is EntityKind.NODE else 'needs a'} topic")

    @classmethod
    def for_node(cls, zid: str, node_id: int, node: Node) -> LivelinessToken:
        """A node's token (its entity id is its node id, as in rmw_zenoh)."""
        return cls(zid, node_id, node_id, EntityKind.NODE, node)

    @classmethod
    def for_topic(cls, zid: str, node_id: int, entity_id: int, kind: EntityKind, node: Node,
                  topic: Topic) -> LivelinessToken:
        return cls(zid, node_id, entity_id, kind, node, topic)

    def key(self) -> str:
        n = self.node
        parts = [ADMIN_SPACE, str(n.domain), self.zid, str(self.node_id), str(self.entity_id),
                 self.kind.value, mangle(n.enclave), mangle(n.namespace), mangle(n.name)]
        if self.topic is not None:
            t = self.topic
            parts += [mangle(t.name), dds_type_name(t.typename), t.type_hash,
                      qos_to_keyexpr(t.qos)]
        return "/".join(parts)

    def gid(self) -> bytes:
        """The entity's 16-byte GID, as rmw_zenoh derives it from the token key."""
        return xxhash.xxh3_128_intdigest(self.key().encode()).to_bytes(16, "little")

    @classmethod
    def parse(cls, key: str) -> LivelinessToken:
        """The token of a liveliness key expression. Its topic's ``qos`` is the profile the
        entity runs with (empty fields read as rmw_zenoh's defaults)."""
        what = f"liveliness token {str(key)[:200]!r}"
        parts = str(key).split("/")
        if parts[0] != ADMIN_SPACE:
            raise DecodeError(f"{what}: does not start with {ADMIN_SPACE!r}")
        if len(parts) not in (9, 13) or not all(parts):
            raise DecodeError(f"{what}: expected 9 (a node) or 13 non-empty '/'-separated "
                              f"chunks, got {len(parts)}")
        _, domain, zid, nid, eid, kind_s, enclave, ns, name = parts[:9]
        for chunk, label in ((domain, "domain id"), (nid, "node id"), (eid, "entity id")):
            if not _ID.match(chunk):
                raise DecodeError(f"{what}: the {label} {chunk!r} is not a number")
        try:
            kind = EntityKind(kind_s)
        except ValueError:
            raise DecodeError(f"{what}: unknown entity kind {kind_s!r} (expected one of "
                              f"{', '.join(k.value for k in EntityKind)})") from None
        if (kind is EntityKind.NODE) != (len(parts) == 9):
            raise DecodeError(f"{what}: a {kind_s} token has {'9' if kind is EntityKind.NODE else '13'} "
                              f"chunks, got {len(parts)}")
        try:
            node = Node(demangle(name), demangle(ns), int(domain), demangle(enclave))
            topic = None
            if len(parts) == 13:
                tname, ttype, thash, tqos = parts[9:]
                topic = Topic(demangle(tname), ros_type_name(ttype), qos_from_keyexpr(tqos),
                              thash)
            return cls(zid, int(nid), int(eid), kind, node, topic)
        except ValueError as e:  # DecodeError included: the names, type and QoS inside
            raise DecodeError(f"{what}: {e}") from None
