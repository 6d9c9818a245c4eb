"""Key expressions of the rhbl protocol (docs/protocol.md).

``<robot>`` is a single key chunk (letters, digits, ``_``, ``-``, ``.``); robot number ``i`` is
named ``r<i>`` by default (:func:`robot_name`). ``index`` is the Player device index (0).
"""

from __future__ import annotations

import re

__all__ = [
    "PREFIX",
    "alive_key",
    "check_chunk",
    "cmd_vel_key",
    "cmd_vel_subscription",
    "controller_decision_key",
    "driver_key",
    "learner_ack_key",
    "learner_notice_key",
    "learner_snapshot_key",
    "request_key",
    "robot_name",
    "scan_key",
    "sim_request_key",
    "source_of_cmd_key",
    "state_key",
    "teacher_action_key",
    "teacher_labeled_key",
]

PREFIX = "rhbl"
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")


def check_chunk(value: str, what: str = "name", wildcard: bool = False) -> str:
    """Return ``value`` if it is a valid single key chunk, else raise ValueError. With
    ``wildcard``, ``*`` and ``**`` are accepted too (for subscriptions and queries)."""
    if wildcard and value in ("*", "**"):
        return value
    if not isinstance(value, str) or not _CHUNK.match(value):
        raise ValueError(
            f"{what} must be a non-empty key chunk of letters, digits, '_', '-', '.', got {value!r}"
        )
    return value


def robot_name(i: int) -> str:
    """Default name of robot number ``i``: ``r0``, ``r1``, ..."""
    return f"r{int(i)}"


def _dev(robot: str, iface: str, index: int) -> str:
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/{iface}/{int(index)}"


def state_key(robot: str = "r0", index: int = 0) -> str:
    """Position2d state (odometry, velocity, stall), published by the server every tick."""
    return f"{_dev(robot, 'position2d', index)}/data/state"


def scan_key(robot: str = "r0", index: int = 0) -> str:
    """Laser scans, published by the server every tick."""
    return f"{_dev(robot, 'laser', index)}/data/scan"


def driver_key(robot: str = "r0", index: int = 0) -> str:
    """Which command source drives the robot (published by the server on change and each second)."""
    return f"{_dev(robot, 'position2d', index)}/data/driver"


def cmd_vel_key(robot: str = "r0", index: int = 0, source: str | None = None) -> str:
    """Velocity commands. With ``source``, the per-source key ``.../cmd/vel/<source>`` (the
    message's ``source`` field must then equal it); without, the public key ``.../cmd/vel``."""
    base = f"{_dev(robot, 'position2d', index)}/cmd/vel"
    if source is None:
        return base
    return f"{base}/{check_chunk(source, 'source')}"


def cmd_vel_subscription(robot: str = "r0", index: int = 0) -> str:
    """What the server subscribes to: the public key and every per-source key."""
    return f"{cmd_vel_key(robot, index)}/**"


def source_of_cmd_key(key: str) -> str | None:
    """The ``<source>`` chunk of a per-source command key, or None for the public key."""
    parts = str(key).split("/")
    try:
        i = parts.index("vel")
    except ValueError:
        return None
    rest = parts[i + 1 :]
    if not rest:
        return None
    return "/".join(rest)


def request_key(
    robot: str = "r0", iface: str = "position2d", name: str = "get_geom", index: int = 0
) -> str:
    """A request (queryable), e.g. ``request_key('r0', 'laser', 'get_config')``."""
    check_chunk(iface, "iface")
    check_chunk(name, "request name")
    return f"{_dev(robot, iface, index)}/req/{name}"


def sim_request_key(robot: str = "r0", name: str = "set_pose") -> str:
    """A simulation-only request (queryable) ``rhbl/<robot>/sim/req/<name>``: ``set_pose``,
    ``get_pose``, ``get_world`` (Player's ``simulation`` interface). Outside the device tree on purpose: the
    secured router grants ``rhbl/*/*/*/req/**`` (device requests) and ``rhbl/*/sim/req/**``
    (teleporting the robot) to different roles."""
    check_chunk(robot, "robot")
    check_chunk(name, "request name")
    return f"{PREFIX}/{robot}/sim/req/{name}"


def teacher_action_key(robot: str = "r0") -> str:
    """The teacher's label for a scan (``TeacherAction``), teacher -> learner."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/teacher/action"


def teacher_labeled_key(robot: str = "r0") -> str:
    """A label resent with its scan (``LabeledScan``), teacher -> learner: only for labels the
    learner has not acknowledged."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/teacher/labeled"


def learner_ack_key(robot: str = "r0") -> str:
    """Which labels the learner holds in its journal (``LearnerAck``), learner -> teacher."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/learner/ack"


def learner_notice_key(robot: str = "r0") -> str:
    """ "Tree updated" notices (``TreeNotice``), learner -> all."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/learner/notice"


def learner_snapshot_key(robot: str = "r0") -> str:
    """The learner's queryable answering with its latest tree snapshot."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/learner/snapshot"


def controller_decision_key(robot: str = "r0") -> str:
    """The controller's decision for each scan it answers (``Decision``), controller -> all."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/controller/decision"


def alive_key(role: str, ident: str) -> str:
    """Liveliness token of a process: ``rhbl/alive/<role>/<ident>`` (``*``/``**`` allowed, to
    query or subscribe, e.g. ``alive_key("server", "*")``)."""
    role = check_chunk(role, "role", wildcard=True)
    return f"{PREFIX}/alive/{role}/{check_chunk(ident, 'ident', wildcard=True)}"
