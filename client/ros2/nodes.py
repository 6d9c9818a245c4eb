"""ROS 2 over zenoh for the processes: nodes, publishers and subscriptions the rmw_zenoh way,
and a ROS 2 robot as the controller sees a robot (docs/ros2.md).

``protocol.ros2`` is the pure wire layer (keys, tokens, attachments, CDR, conversions); this
module puts it on a zenoh session::

    graph = Ros2Graph(session, domain=0)          # rmw_zenoh's "context": one per session
    node = graph.node("rhbl_bridge", "/r0")       # declares the node's liveliness token
    scan = node.publisher(topics.scan)            # ... and the publisher's (MP)
    scan.put(laserscan)                           # CDR, with the attachment (seq, time, GID)
    node.subscription(topics.cmd_vel, on_twist)   # a zenoh subscriber and its token (MS)
    graph.close()                                 # undeclares everything, in reverse

    robot = Ros2Robot(session, "r0", options, spec=lambda: policy.features)
    channel = robot.scans()        # LaserScan + Odometry in, as rhbl Scans in the tree's layout
    robot.answer(scan, vx, va)     # a Twist on cmd_vel

Node and entity ids are counted from 0 per graph, nodes and entities alike, as rmw_zenoh
counts them per context; they are unique within the session as long as one graph is made per
session. ``Ros2Options`` holds the options ``rhbl ros2`` and ``rhbl controller --ros2`` share
(domain, namespace, topic names), with their help texts in one place.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import logging
import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh

from client.behaviour.features import FeatureSpec
from client.behaviour.resample import TAUGHT_BEAMS, CoverageError, LaserResampler
from process import arguments
from process.runtime import EXIT_USAGE, ProcessError
from protocol.codec import DecodeError
from protocol.decoding import Decoder
from protocol.messages import Scan, VelCmd
from protocol.ros2 import cdr
from protocol.ros2.attachment import Attachment
from protocol.ros2.convert import pose_from_odometry, scan_from_laserscan, twist_from_velcmd
from protocol.ros2.graph import EntityKind, LivelinessToken, Node, RobotTopics, Topic
from protocol.ros2.names import check_namespace, fully_qualified
from protocol.ros2.qos import QosHistory, QosReliability

__all__ = [
    "Cdr",
    "Ros2Graph",
    "Ros2Node",
    "Ros2Options",
    "Ros2Publisher",
    "Ros2Robot",
    "Ros2ScanChannel",
    "add_ros2_arguments",
]

log = logging.getLogger(__name__)

_ROS_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,254}$")


# ---- options ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Ros2Options:
    """The ROS 2 side of a process: the ``domain`` id, the ROS 2 ``namespace`` the robots'
    topics go under (``<namespace>/<robot>/scan``) and the topic names (relative ones under
    ``<namespace>/<robot>``, absolute ones as they are)."""

    domain: int = 0
    namespace: str = "/"
    scan: str = "scan"
    odom: str = "odom"
    cmd_vel: str = "cmd_vel"
    tf: str = "/tf"
    clock: str = "/clock"

    def __post_init__(self):
        if isinstance(self.domain, bool) or not isinstance(self.domain, int) or \
                not 0 <= self.domain <= 232:
            # ROS 2's limit (rmw's RMW_DEFAULT_DOMAIN_ID range; 0-101 and 215-232 on Linux)
            raise ValueError(f"--domain must be a ROS 2 domain id 0..232, got {self.domain!r}")
        try:
            check_namespace(self.namespace)
        except ValueError as exc:
            raise ValueError(f"--ros-namespace: {exc}") from None
        for name, flag in (("scan", "--scan-topic"), ("odom", "--odom-topic"),
                           ("cmd_vel", "--cmd-vel-topic"), ("tf", "--tf-topic"),
                           ("clock", "--clock-topic")):
            try:
                fully_qualified(getattr(self, name), "/r0")
            except ValueError as exc:
                raise ValueError(f"{flag}: {exc}") from None

    def topics(self, robot: str) -> RobotTopics:
        """The robot's topics; a robot whose name ROS 2 cannot carry is a ValueError."""
        if not isinstance(robot, str) or not _ROS_TOKEN.match(robot):
            raise ValueError(f"robot {robot!r} has no ROS 2 name: ROS 2 names are letters, "
                             f"digits and '_', not starting with a digit (rename it with "
                             f"rhbl server --robot)")
        return RobotTopics.of(robot, self.namespace, scan=self.scan, odom=self.odom,
                              cmd_vel=self.cmd_vel, tf=self.tf, clock=self.clock)

    def node_namespace(self, robot: str) -> str:
        """The namespace of the node that serves ``robot``: ``<namespace>/<robot>``."""
        return fully_qualified(robot, self.namespace)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> Ros2Options:
        """The options given (see :func:`add_ros2_arguments`); ValueError names a bad one."""
        given = {name: getattr(args, dest) for name, dest in _DESTS.items()
                 if getattr(args, dest, None) is not None}
        return cls(**given)

    @staticmethod
    def given(args: argparse.Namespace) -> list[str]:
        """The ROS 2 options given on the command line (their flags)."""
        return [flag for flag, dest in _FLAGS.items() if getattr(args, dest, None) is not None]


# name in Ros2Options -> argparse dest; flag -> dest
_DESTS = {"domain": "domain", "namespace": "ros_namespace", "scan": "scan_topic",
          "odom": "odom_topic", "cmd_vel": "cmd_vel_topic", "tf": "tf_topic",
          "clock": "clock_topic"}
_FLAGS = {"--" + dest.replace("_", "-"): dest for dest in _DESTS.values()}


# a ROS 2 domain id, as ROS_DOMAIN_ID (rmw_zenoh: 0-232); the names are checked as ROS 2 names
# by Ros2Options, after the parse
DOMAIN_ID = arguments.Number(int, 0, 232, name="ROS 2 domain id", note=" (a ROS 2 domain id)")


def add_ros2_arguments(parser: argparse.ArgumentParser, bridge: bool = True,
                       when: str = "", domain: bool = True) -> None:
    """The ROS 2 options (defaults: ``Ros2Options``); ``bridge``: also ``/tf`` and ``/clock``
    (what ``rhbl ros2`` publishes); ``domain``: ``--domain`` (not for a file); ``when`` is said
    after each help text (``with --ros2``)."""
    d = Ros2Options()
    w = f" ({when})" if when else ""
    g = parser.add_argument_group("ROS 2 (docs/ros2.md)")
    if domain:
        g.add_argument("--domain", type=DOMAIN_ID, default=None, metavar="ID",
                       help=f"ROS 2 domain id, as ROS_DOMAIN_ID (default {d.domain}){w}")
    g.add_argument("--ros-namespace", type=arguments.text, default=None, metavar="NS",
                   help=f"ROS 2 namespace of the robots' topics: <NS>/<robot>/scan (default "
                        f"{d.namespace}; not the zenoh --namespace){w}")
    topics = [("scan", "LaserScan"), ("odom", "Odometry"), ("cmd_vel", "Twist")]
    if bridge:
        topics += [("tf", "TFMessage, odom -> base_link"), ("clock", "Clock (sim time)")]
    for name, what in topics:
        g.add_argument(f"--{name.replace('_', '-')}-topic", type=arguments.text, default=None,
                       metavar="NAME",
                       help=f"topic of the {what} (default {getattr(d, name)}: a relative name "
                            f"goes under <NS>/<robot>){w}")


# ---- the graph: nodes, publishers, subscriptions ---------------------------------------------
class Cdr:
    """A ROS 2 type for ``protocol.decoding.Decoder``: ``decoder.decode(Cdr(TWIST, "cmd_vel"),
    payload)`` is the message or None (dropped, counted under ``what``, logged)."""

    def __init__(self, typename: str, what: str):
        self.typename, self.WHAT = typename, what

    def decode(self, data: Any) -> Any:
        return cdr.deserialize(data, self.typename)


class Ros2Graph:
    """rmw_zenoh's context on one zenoh ``session``: the ``domain``, the session's ``zid``,
    the ids of its nodes and entities, and everything it declared (:meth:`close`)."""

    def __init__(self, session: zenoh.Session, domain: int = 0, enclave: str = "/"):
        self.session, self.domain, self.enclave = session, int(domain), enclave
        self.zid = str(session.info.zid())
        self._ids = itertools.count()
        self._declared: list[Any] = []
        self._lock = threading.Lock()

    def next_id(self) -> int:
        with self._lock:
            return next(self._ids)

    def keep(self, thing: Any) -> Any:
        """Undeclare ``thing`` (a token, publisher, subscriber) at :meth:`close`."""
        with self._lock:
            self._declared.append(thing)
        return thing

    def token(self, token: LivelinessToken) -> Any:
        return self.keep(self.session.liveliness().declare_token(token.key()))

    def node(self, name: str, namespace: str = "/") -> Ros2Node:
        """A node, announced at once (its ``NN`` token)."""
        return Ros2Node(self, Node(name, namespace, self.domain, self.enclave), self.next_id())

    def close(self) -> None:
        """Undeclare every token, publisher and subscriber, the last declared first."""
        with self._lock:
            declared, self._declared = self._declared, []
        for thing in reversed(declared):
            with contextlib.suppress(Exception):  # the session may be closed already
                thing.undeclare()


class Ros2Node:
    """One ROS 2 node of a :class:`Ros2Graph`: publishers and subscriptions with tokens."""

    def __init__(self, graph: Ros2Graph, node: Node, node_id: int):
        self.graph, self.info, self.id = graph, node, node_id
        self.token = LivelinessToken.for_node(graph.zid, node_id, node)
        graph.token(self.token)

    def _entity(self, kind: EntityKind, topic: Topic) -> LivelinessToken:
        return LivelinessToken.for_topic(self.graph.zid, self.id, self.graph.next_id(), kind,
                                         self.info, topic)

    def publisher(self, topic: Topic, express: bool = True) -> Ros2Publisher:
        """A publisher (and its ``MP`` token) on ``topic``'s key in the graph's domain."""
        return Ros2Publisher(self.graph, self._entity(EntityKind.PUBLISHER, topic), express)

    def subscription(self, topic: Topic, handler: Any) -> Any:
        """A zenoh subscriber on ``topic``'s key (``handler``: a callback or a zenoh handler)
        and its ``MS`` token; the zenoh subscriber is returned."""
        token = self._entity(EntityKind.SUBSCRIPTION, topic)
        sub = self.graph.keep(self.graph.session.declare_subscriber(
            topic.key(self.graph.domain), handler))
        self.graph.token(token)
        return sub


class Ros2Publisher:
    """Puts CDR samples on a topic's key with rmw_zenoh's attachment: the sequence number (from
    1), the wall-clock time and the publisher's GID. Congestion control as rmw_zenoh sets it:
    dropped under congestion unless reliable with keep-all history; sent at once (express)."""

    def __init__(self, graph: Ros2Graph, token: LivelinessToken, express: bool = True):
        topic = token.topic
        self.topic, self.token, self.gid = topic, token, token.gid()
        self.key = topic.key(graph.domain)
        reliable = topic.qos.reliability == QosReliability.RELIABLE
        block = reliable and topic.qos.history == QosHistory.KEEP_ALL
        self._pub = graph.keep(graph.session.declare_publisher(
            self.key, express=express,
            reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
            congestion_control=(zenoh.CongestionControl.BLOCK if block
                                else zenoh.CongestionControl.DROP)))
        graph.token(token)
        self._seq = itertools.count(1)
        self._lock = threading.Lock()
        self.sent = 0

    def put(self, msg: Any) -> None:
        """A rosbags message of the topic's type, serialised to CDR."""
        self.put_cdr(cdr.serialize(msg))

    def put_cdr(self, data: bytes) -> None:
        with self._lock:  # one sequence, in order, whichever thread publishes
            seq = next(self._seq)
            att = Attachment(seq, time.time_ns(), self.gid).encode()
            self._pub.put(data, attachment=att)
            self.sent = seq


# ---- a ROS 2 robot, as the controller sees a robot -------------------------------------------
class Ros2Robot:
    """A ROS 2 robot ``robot`` seen as ``client.player.PlayerClient`` shows an rhbl one to the
    controller: :meth:`scans` (its ``LaserScan`` with the pose of its latest ``Odometry``, in
    the layout the tree's features read: ``spec()``, resampled by
    ``client.behaviour.resample.LaserResampler``), :meth:`answer` (a ``Twist`` on ``cmd_vel``),
    ``decoder`` (what was dropped) and :meth:`close`. Its node ``node_name`` in
    ``<namespace>/<robot>`` subscribes to scan and odom and publishes cmd_vel (tokens NN, MS,
    MS, MP) in a graph of its own on ``session`` (:meth:`close` undeclares it)."""

    def __init__(self, session: zenoh.Session, robot: str, options: Ros2Options,
                 spec: Callable[[], FeatureSpec], node_name: str = "rhbl_controller",
                 role: str = "controller"):
        self.graph = Ros2Graph(session, options.domain)
        self.robot, self.role, self.spec = robot, role, spec
        self.topics = options.topics(robot)
        self.node = self.graph.node(node_name, options.node_namespace(robot))
        self.decoder = Decoder(log)  # malformed LaserScans and Odometries: dropped, counted
        self.pose: tuple[float, float, float] | None = None  # of the latest Odometry
        self.without_odom = 0  # scans that came before any odometry (pose 0, 0, 0)
        self._odom_type = Cdr(cdr.ODOMETRY, "odom")
        self.node.subscription(self.topics.odom, self._on_odom)
        self._cmd = self.node.publisher(self.topics.cmd_vel)
        self._channels: list[Ros2ScanChannel] = []

    def _on_odom(self, sample: zenoh.Sample) -> None:
        msg = self.decoder.decode(self._odom_type, sample.payload)
        if msg is None:
            return
        try:
            self.pose = pose_from_odometry(msg)
        except DecodeError as exc:
            self.decoder.drop("odom", str(exc))

    def scans(self, depth: int = 1) -> Ros2ScanChannel:
        channel = Ros2ScanChannel(self, depth)
        self._channels.append(channel)
        return channel

    def answer(self, scan: Scan, vx: float, va: float) -> None:
        """Command ``(vx, va)`` for ``scan``: a ``Twist`` (ROS 2 has no scan ids to answer)."""
        if not (math.isfinite(vx) and math.isfinite(va)):
            raise ValueError(f"speeds must be finite, got vx={vx!r}, va={va!r}")
        self._cmd.put(twist_from_velcmd(VelCmd(vx=vx, va=va)))

    @property
    def commands(self) -> int:
        return self._cmd.sent

    def close(self) -> None:
        self.graph.close()


class Ros2ScanChannel:
    """The robot's ``LaserScan``s through a zenoh ring channel of ``depth`` (the latest only at
    1), each turned in the reader's thread into an rhbl ``Scan`` of ``TAUGHT_BEAMS`` beams over
    the tree's field of view, its ``pose`` the latest odometry, ``id`` counted from 1. ``recv``
    and ``try_recv`` as ``client.player.ScanChannel``'s (None: a malformed scan, dropped and
    counted); a laser that cannot give the tree's features raises ``ProcessError`` (exit 2)."""

    def __init__(self, robot: Ros2Robot, depth: int = 1):
        if int(depth) < 1:
            raise ValueError(f"a scan channel holds at least one scan, got depth {depth}")
        self.robot = robot
        self.key = robot.topics.scan.key(robot.graph.domain)
        self.needs = (f"a ROS 2 robot publishing {cdr.LASER_SCAN} on {robot.topics.scan.name} "
                      f"(domain {robot.graph.domain})")
        self._sub = robot.node.subscription(robot.topics.scan,
                                            zenoh.handlers.RingChannel(int(depth)))
        self._recv, self._try = self._sub.handler.recv, self._sub.handler.try_recv
        self._type = Cdr(cdr.LASER_SCAN, "scan")
        self._fit: LaserResampler | None = None
        self._ids = itertools.count(1)

    def recv(self) -> Scan | None:
        return self._convert(self._recv())

    def try_recv(self) -> Scan | None:
        sample = self._try()
        return None if sample is None else self._convert(sample)

    def latest(self) -> Scan | None:
        last = None
        while (sample := self._try()) is not None:
            last = sample
        return None if last is None else self._convert(last)

    def _convert(self, sample: zenoh.Sample) -> Scan | None:
        r = self.robot
        msg = r.decoder.decode(self._type, sample.payload)
        if msg is None:
            return None
        pose = r.pose
        if pose is None:
            r.without_odom += 1
            pose = (0.0, 0.0, 0.0)
        try:
            scan = scan_from_laserscan(msg, next(self._ids), pose)
        except DecodeError as exc:
            r.decoder.drop("scan", str(exc))
            return None
        fit = self._resampler(scan)
        ranges = fit.resample(scan.ranges)
        half = math.radians(fit.spec.fov) / 2.0
        return Scan(ts=scan.ts, id=scan.id, ranges=ranges, pose=pose, min_angle=-half,
                    max_angle=half, resolution=2.0 * half / (fit.beams - 1),
                    max_range=scan.max_range)

    def _resampler(self, scan: Scan) -> LaserResampler:
        spec, fit = self.robot.spec(), self._fit
        if fit is None or fit.spec != spec or not fit.fits(scan):
            try:
                fit = self._fit = LaserResampler.for_scan(spec, scan, TAUGHT_BEAMS)
            except CoverageError as exc:
                raise ProcessError(f"{self.robot.role}: the laser on {self.robot.topics.scan.name}"
                                   f": {exc}", EXIT_USAGE) from exc
            log.info("%s: %d-beam laser over %.1f deg on %s, resampled to the tree's %d beams "
                     "over %g deg", self.robot.role, scan.count,
                     math.degrees(scan.resolution * (scan.count - 1)),
                     self.robot.topics.scan.name, fit.beams, spec.fov)
        return fit

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()
