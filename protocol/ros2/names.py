"""ROS 2 names as rmw_zenoh writes them into zenoh keys (docs/ros2.md, "Keys").

    fully_qualified("scan", "/r0")            -> "/r0/scan"
    fully_qualified("/tf", "/r0")             -> "/tf"
    dds_type_name("sensor_msgs/msg/LaserScan") -> "sensor_msgs::msg::dds_::LaserScan_"
    ros_type_name("sensor_msgs::msg::dds_::LaserScan_") -> "sensor_msgs/msg/LaserScan"
    mangle("/r0/scan") -> "%r0%scan"           (a name inside one key chunk; demangle undoes it)

Names follow ROS 2's rules (tokens of letters, digits and ``_``, not starting with a digit,
separated by ``/``); a name that breaks them is refused with a ``ValueError`` naming it, since
neither a ROS 2 node nor a zenoh key could carry it. The ``~`` (private) and ``{}``
(substitution) forms of rcl's name expansion are not supported.
"""

from __future__ import annotations

import re

__all__ = [
    "check_namespace",
    "check_node_name",
    "check_topic_name",
    "dds_type_name",
    "demangle",
    "fully_qualified",
    "mangle",
    "ros_type_name",
]

MAX_NAME = 255  # characters (rmw's limit for a node name; topics are kept to the same)
_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_FQN = re.compile(rf"^(/{_TOKEN})+$")
_NODE = re.compile(rf"^{_TOKEN}$")
_RELATIVE = re.compile(rf"^{_TOKEN}(/{_TOKEN})*$")
_TYPE = re.compile(rf"^({_TOKEN})/(msg|srv|action)/([A-Za-z][A-Za-z0-9_]*)$")
_DDS_TYPE = re.compile(rf"^({_TOKEN})::(msg|srv|action)::dds_::([A-Za-z][A-Za-z0-9_]*)_$")


def _check(value, pattern: re.Pattern, what: str, rule: str) -> str:
    if not isinstance(value, str) or len(value) > MAX_NAME or not pattern.match(value):
        raise ValueError(f"{what} must be {rule} (at most {MAX_NAME} characters), got {value!r}")
    return value


def check_node_name(name: str) -> str:
    """A ROS 2 node name: one token (``rhbl_bridge``)."""
    return _check(name, _NODE, "a ROS 2 node name",
                  "letters, digits and '_', not starting with a digit")


def check_namespace(namespace: str) -> str:
    """A ROS 2 namespace: ``/`` or absolute tokens (``/fleet/r0``), no trailing ``/``."""
    if namespace == "/":
        return namespace
    return _check(namespace, _FQN, "a ROS 2 namespace",
                  "'/' or '/'-separated tokens of letters, digits and '_' starting with '/'")


def check_topic_name(name: str) -> str:
    """A fully qualified ROS 2 topic name (``/r0/scan``)."""
    return _check(name, _FQN, "a fully qualified ROS 2 topic name",
                  "'/'-separated tokens of letters, digits and '_' starting with '/'")


def fully_qualified(name: str, namespace: str = "/") -> str:
    """``name`` resolved in ``namespace`` as rcl does for plain names: an absolute name stays,
    a relative one is put under the namespace."""
    check_namespace(namespace)
    if isinstance(name, str) and name.startswith("/"):
        return check_topic_name(name)
    _check(name, _RELATIVE, "a ROS 2 topic name",
           "'/'-separated tokens of letters, digits and '_' ('~' and '{}' are not supported)")
    return check_topic_name(("" if namespace == "/" else namespace) + "/" + name)


def dds_type_name(typename: str) -> str:
    """The type name rmw_zenoh puts in keys: the DDS name of the type's CDR typesupport."""
    m = _TYPE.match(typename) if isinstance(typename, str) else None
    if m is None:
        raise ValueError(f"a ROS 2 type name is 'package/msg/Name', got {typename!r}")
    package, kind, name = m.groups()
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of :func:`dds_type_name`."""
    m = _DDS_TYPE.match(dds_name) if isinstance(dds_name, str) else None
    if m is None:
        raise ValueError(f"a DDS type name of a ROS 2 type is 'package::msg::dds_::Name_', "
                         f"got {dds_name!r}")
    package, kind, name = m.groups()
    return f"{package}/{kind}/{name}"


def mangle(name: str) -> str:
    """A name inside one key chunk, as rmw_zenoh's liveliness tokens carry it: ``/`` -> ``%``."""
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    """The inverse of :func:`mangle`: ``%`` -> ``/``."""
    return chunk.replace("%", "/")
