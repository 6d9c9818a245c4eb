"""Key expressions of the rhbl protocol (docs/protocol.md): the one place keys are built,
parsed and made into wildcards.

``<robot>`` is a single key chunk (letters, digits, ``_``, ``-``, ``.``); robot number ``i`` is
named ``r<i>`` by default (:func:`robot_name`). ``index`` is the Player device index (0).

    scan_key("r0")                 -> rhbl/r0/laser/0/data/scan
    scan_key(EVERY)                -> rhbl/*/laser/0/data/scan   (the same key of every robot)
    fiducial_key("r0")             -> rhbl/r0/fiducial/0/data/fiducials
    robot_keys("r0"), robot_keys() -> rhbl/r0/**, rhbl/**         (everything of one, of all)
    every_token()                  -> rhbl/alive/**              (every process's token)
    parse("rhbl/r0/position2d/0/cmd/vel/teacher")
        -> KeyInfo(kind="cmd", robot="r0", iface="position2d", index=0, source="teacher")
"""

from __future__ import annotations

import functools
import re
from typing import NamedTuple

__all__ = [
    "EVERY",
    "KINDS",
    "PREFIX",
    "KeyInfo",
    "alive_key",
    "check_chunk",
    "cmd_vel_key",
    "cmd_vel_subscription",
    "controller_decision_key",
    "driver_key",
    "every_token",
    "fiducial_key",
    "learner_ack_key",
    "learner_notice_key",
    "learner_snapshot_key",
    "parse",
    "request_key",
    "robot_keys",
    "robot_name",
    "scan_key",
    "sim_request_key",
    "source_of_cmd_key",
    "state_key",
    "teacher_action_key",
    "teacher_labeled_key",
    "teacher_withdraw_key",
]

PREFIX = "rhbl"
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")


class _Wildcard(str):
    """A wildcard chunk given on purpose (a plain ``"*"``, from a command line say, is refused)."""


EVERY = _Wildcard("*")  # in place of a robot: the same key of every robot (to subscribe)


def check_chunk(value: str, what: str = "name", wildcard: bool = False) -> str:
    """Return ``value`` if it is a valid single key chunk, else raise ValueError. With
    ``wildcard``, ``*`` and ``**`` are accepted too (for subscriptions and queries); ``EVERY``
    always is."""
    if (wildcard or isinstance(value, _Wildcard)) and value in ("*", "**"):
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


def fiducial_key(robot: str = "r0", index: int = 0) -> str:
    """The beacons a robot's fiducial finder sees (``Fiducial``), published by the server every
    tick in a world with beacons (Player's ``fiducial`` interface)."""
    return f"{_dev(robot, 'fiducial', index)}/data/fiducials"


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
    """The ``<source>`` of a per-source command key (every chunk after ``cmd/vel``), or None for
    the public key."""
    return parse(key).source


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


def teacher_withdraw_key(robot: str = "r0") -> str:
    """A teacher's withdrawal of labels it gave (``Withdrawal``: undo, a discarded episode),
    teacher -> learner; delivered like a label (kept until acknowledged, resent)."""
    check_chunk(robot, "robot")
    return f"{PREFIX}/{robot}/teacher/withdraw"


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


def robot_keys(robot: str = EVERY) -> str:
    """Every key of ``robot`` (``rhbl/<robot>/**``), by default of every robot (``rhbl/**``,
    liveliness tokens included)."""
    if robot is EVERY:
        return f"{PREFIX}/**"
    return f"{PREFIX}/{check_chunk(robot, 'robot')}/**"


def every_token() -> str:
    """Every process's liveliness token (``rhbl/alive/**``)."""
    return f"{PREFIX}/alive/**"


# ---- parsing ----------------------------------------------------------------------------------
# what a key of ours is: the message it carries (docs/protocol.md section 3)
KINDS = ("state", "scan", "fiducial", "driver", "cmd", "request", "sim", "label", "labeled", "withdraw",
         "ack", "notice", "snapshot", "decision", "alive", "other")
_DATA = {("position2d", "state"): "state", ("laser", "scan"): "scan",
         ("fiducial", "fiducials"): "fiducial", ("position2d", "driver"): "driver"}
_ROLE_KEYS = {("teacher", "action"): "label", ("teacher", "labeled"): "labeled",
              ("teacher", "withdraw"): "withdraw",
              ("learner", "ack"): "ack", ("learner", "notice"): "notice",
              ("learner", "snapshot"): "snapshot", ("controller", "decision"): "decision"}


class KeyInfo(NamedTuple):
    """What a key names. ``kind`` (one of ``KINDS``; ``other``: not a key of ours), ``robot``
    (``""`` when it names none), for device keys ``iface`` and ``index``, ``name`` (a request's
    name; the robot a server's token says it hosts), ``source`` (the per-source chunk(s) of a
    command key, None on the public key), and for a liveliness token ``role`` and ``ident``
    (``<robot>-<pid>`` for a process of one robot; a server declares
    ``rhbl/alive/server/<ident>/<robot>`` for each robot it hosts)."""

    kind: str
    robot: str = ""
    iface: str = ""
    index: int | None = None
    name: str = ""
    source: str | None = None
    role: str = ""
    ident: str = ""

    def names_robot(self, robot: str) -> bool:
        """Whether the key is ``robot``'s: its robot chunk; for a token, a server's of that
        robot or one whose ident is ``<robot>-...`` (a robot name may hold ``-``: the prefix is
        checked, not split)."""
        if self.kind != "alive":
            return self.robot == robot
        if self.name:  # a server's token of the robot it hosts
            return self.name == robot
        return self.ident.startswith(f"{robot}-")


def parse(key) -> KeyInfo:
    """What ``key`` (a str or a zenoh key expression) names; ``kind="other"`` for a key that is
    not one of ours. Never raises. Cached (a bus has few keys: callbacks parse them cheaply)."""
    return _parse(str(key))


@functools.lru_cache(maxsize=4096)
def _parse(key: str) -> KeyInfo:
    parts = key.split("/")
    if len(parts) < 3 or parts[0] != PREFIX:
        return KeyInfo("other")
    if parts[1] == "alive":
        return _parse_alive(parts)
    robot, rest = parts[1], parts[2:]
    if len(rest) == 2 and (rest[0], rest[1]) in _ROLE_KEYS:
        return KeyInfo(_ROLE_KEYS[rest[0], rest[1]], robot)
    if len(rest) == 3 and rest[:2] == ["sim", "req"]:
        return KeyInfo("sim", robot, name=rest[2])
    if len(rest) >= 4 and rest[1].isdigit():
        return _parse_device(robot, rest)
    return KeyInfo("other", robot)


def _parse_device(robot: str, rest: list[str]) -> KeyInfo:
    """``<iface>/<index>/data/<what>``, ``.../cmd/vel[/<source>...]``, ``.../req/<name>``."""
    iface, index, group = rest[0], int(rest[1]), rest[2]
    if group == "data" and len(rest) == 4 and (iface, rest[3]) in _DATA:
        return KeyInfo(_DATA[iface, rest[3]], robot, iface, index)
    if group == "cmd" and rest[3] == "vel" and iface == "position2d":
        return KeyInfo("cmd", robot, iface, index, source="/".join(rest[4:]) or None)
    if group == "req" and len(rest) == 4:
        return KeyInfo("request", robot, iface, index, name=rest[3])
    return KeyInfo("other", robot)


def _parse_alive(parts: list[str]) -> KeyInfo:
    """``rhbl/alive/<role>/<ident>[/<robot>]``: a server's tokens name the robot in a chunk of
    their own; a process of one robot names it in its ident (``<robot>-<pid>``)."""
    role = parts[2]
    ident = parts[3] if len(parts) > 3 else ""
    if len(parts) == 5:  # a server's token of a robot it hosts
        return KeyInfo("alive", parts[4], name=parts[4], role=role, ident=ident)
    own = ident.split("-", 1)[0] if "-" in ident else ""
    return KeyInfo("alive", own, role=role, ident=ident)
