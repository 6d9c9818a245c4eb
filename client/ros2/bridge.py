"""``rhbl ros2``: an rhbl robot that ROS 2 nodes see and drive, over rmw_zenoh's keys.

For each robot (``--robot``, repeatable) a ROS 2 node ``rhbl_bridge`` in ``<ns>/<robot>``
publishes, at every tick of the server, ``<ns>/<robot>/scan`` (``sensor_msgs/msg/LaserScan``),
``<ns>/<robot>/odom`` (``nav_msgs/msg/Odometry``), ``/tf`` (odom -> base_link) and, from the
first robot's node, ``/clock`` (the sim time: ROS 2 nodes run with ``use_sim_time``). It
subscribes to ``<ns>/<robot>/cmd_vel`` (``geometry_msgs/msg/Twist``; ``TwistStamped`` is read
too): each Twist becomes one command on ``rhbl/<robot>/position2d/0/cmd/vel/ros2``, clamped to
the robot's limits, so the server's arbitration decides (``ros2`` has priority 0, below the
controller and the teacher) and its watchdog stops the robot when the Twists stop (0.5 s of
sim time by default: ``rhbl server --watchdog``). A Twist that is not valid CDR, or not finite,
is dropped and counted (``--stats``: ``cmd_vel_rejected``) and moves nothing.

    rhbl ros2 --robot r0                                  # domain 0, topics /r0/scan, ...
    rhbl ros2 --robot r0 --robot r1 --ros-namespace /fleet --domain 7

The session must see the ROS 2 side's keys as they are: no zenoh ``--namespace`` (it would
prefix ROS 2's keys too). docs/ros2.md: the mapping, QoS, the versions of rmw_zenoh followed.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import threading

from client.player import PlayerClient, RequestError
from client.roles.common import wait_for_server
from client.ros2.nodes import Cdr, Ros2Graph, Ros2Options, add_ros2_arguments
from process import arguments
from process.runtime import (
    EXIT_NO_SERVER,
    Context,
    ProcessError,
    add_report_arguments,
    run_process,
)
from process.session import add_zenoh_arguments
from protocol.codec import DecodeError
from protocol.decoding import Decoder
from protocol.messages import MAX_VA, MAX_VX
from protocol.ros2 import cdr
from protocol.ros2.convert import Frames, RobotFeed, velcmd_from_twist

__all__ = ["NODE", "SOURCE", "BridgeProcess", "RobotBridge", "add_arguments", "main"]

log = logging.getLogger(__name__)

SOURCE = "ros2"  # the command source (priority 0 in the server's arbitration)
NODE = "rhbl_bridge"  # the ROS 2 node of each robot


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        type=arguments.key_chunk, help="bridge this robot (repeatable; default: r0); a ROS 2 name: "
                             "letters, digits and '_'")
    add_ros2_arguments(parser, bridge=True)
    parser.add_argument("--wait-server", type=arguments.seconds_or_zero, default=10.0,
                        metavar="SECONDS",
                        help="how long to wait for each robot's first scan before giving up "
                             "(0 = wait forever, logging every few seconds; default: 10)")
    add_report_arguments(parser)


def _check(args: argparse.Namespace) -> tuple[list[str], Ros2Options]:
    """The robots and ROS 2 options, or a ValueError naming what is wrong (before connecting)."""
    robots = args.robots or ["r0"]
    options = Ros2Options.from_args(args)
    for r in robots:  # each a key chunk already (its argument type)
        options.topics(r)
    if len(set(robots)) != len(robots):
        raise ValueError(f"--robot: each robot once, got {robots}")
    return robots, options


def main(args: argparse.Namespace) -> int:
    robots, options = _check(args)  # a ValueError is one line, exit 2, before connecting
    ident = f"{robots[0]}-{os.getpid()}" if len(robots) == 1 else f"fleet-{os.getpid()}"
    return run_process(SOURCE, args, lambda ctx: BridgeProcess(ctx, robots, options).run(),
                       ident=ident)


class RobotBridge:
    """One robot: its ticks (a state and a scan) out as ROS 2 messages from its node, its
    ``cmd_vel`` in as commands of source ``ros2``."""

    def __init__(self, ctx: Context, graph: Ros2Graph, robot: str, options: Ros2Options,
                 clock: bool):
        self.ctx, self.robot = ctx, robot
        self.topics = options.topics(robot)
        self.clock = clock
        # commands on .../cmd/vel/ros2, sent at once; dropped rather than block a zenoh callback
        self.client = PlayerClient(session=ctx.session, robot=robot, source=SOURCE, express=True)
        ctx.scope.callback(self.client.close)
        self.pos, self.laser = self.client.position2d, self.client.laser  # state and scan
        self.node = graph.node(NODE, options.node_namespace(robot))
        self.feed: RobotFeed | None = None  # once the laser's rate is known
        self.pubs = {}
        for topic in self.topics.published:
            if topic is not self.topics.clock or clock:
                self.pubs[topic.name] = self.node.publisher(topic)
        self.rejected = Decoder(log)  # cmd_vel that moves nothing: malformed CDR, not finite
        self.twists = 0
        self._twist = Cdr(cdr.TWIST, "cmd_vel")
        self._stamped = Cdr(cdr.TWIST_STAMPED, "cmd_vel")
        self.node.subscription(self.topics.cmd_vel, lambda s: self.on_twist(s, self._twist))
        self.node.subscription(self.topics.cmd_vel_stamped,
                               lambda s: self.on_twist(s, self._stamped))
        self.ticks = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"ros2-{robot}", daemon=True)

    def start(self) -> None:
        """Wait for the robot's first scan, read its laser's rate, then bridge its ticks."""
        wait_for_server(dataclasses.replace(self.ctx, robot=self.robot))
        try:
            rate = self.laser.get_config().rate
        except RequestError as exc:
            raise ProcessError(f"ros2: robot {self.robot!r}: no laser configuration ({exc})",
                               EXIT_NO_SERVER) from exc
        self.feed = RobotFeed(self.topics, Frames.for_robot(self.robot),
                              scan_time=1.0 / rate if rate > 0 else 0.0, clock=self.clock)
        log.info("robot %s: %s on domain %d (%g Hz); commands from %s", self.robot,
                 ", ".join(t.name for t in self.feed.published), self.node.graph.domain, rate,
                 self.topics.cmd_vel.name)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self.client.read(timeout=0.5):
                self.publish()

    def publish(self) -> None:
        """The tick just read: the scan first (what waits on it most), then odometry, tf, clock."""
        try:
            out = self.feed.of_scan(self.laser.scan) + self.feed.of_state(self.pos.state)
            for topic, msg in out:
                self.pubs[topic.name].put(msg)
            self.ticks += 1
        except Exception as exc:  # noqa: BLE001 - the session closing under us, or a bad value
            if not self._stop.is_set():
                log.warning("robot %s: tick not published: %s: %s", self.robot,
                            type(exc).__name__, exc)

    def on_twist(self, sample, typ: Cdr) -> None:
        """A Twist (or TwistStamped) on cmd_vel: one command, or dropped and counted."""
        msg = self.rejected.decode(typ, sample.payload, where=self.topics.cmd_vel.name)
        if msg is None:
            return
        scan = self.laser.scan  # the latest the loop read: what the command is sent against
        try:
            cmd = velcmd_from_twist(msg, max_vx=MAX_VX, max_va=MAX_VA, source=SOURCE)
        except DecodeError as exc:
            self.rejected.drop("cmd_vel", f"{self.topics.cmd_vel.name}: {exc}")
            return
        self.client.send_command(cmd.vx, cmd.va, True, None if scan is None else scan.id,
                                 None if scan is None else scan.ts)
        self.twists += 1

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)

    def counters(self) -> dict:
        return {"ticks": self.ticks, "published": {n: p.sent for n, p in self.pubs.items()},
                "cmd_vel": self.twists, "cmd_vel_rejected": self.rejected.total,
                "dropped": dict(self.client.decoder.counts)}


class BridgeProcess:
    """Every robot's :class:`RobotBridge` on one session (one ROS 2 graph: node and entity ids
    unique within it); the main thread waits for a stop signal."""

    def __init__(self, ctx: Context, robots: list[str], options: Ros2Options):
        self.ctx = ctx
        if getattr(ctx.args, "namespace", None):
            log.warning("zenoh --namespace %r prefixes ROS 2's keys too: only ROS 2 nodes in the "
                        "same zenoh namespace see the bridge", ctx.args.namespace)
        self.graph = Ros2Graph(ctx.session, options.domain)
        ctx.scope.callback(self.graph.close)
        self.robots = [RobotBridge(ctx, self.graph, r, options, clock=(k == 0))
                       for k, r in enumerate(robots)]
        self._stop = threading.Event()
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)

    def run(self) -> int:
        for rb in self.robots:
            rb.start()
        log.info("bridging %d robot(s) to ROS 2 as node(s) %s (zid %s)", len(self.robots),
                 ", ".join(rb.node.info.fully_qualified_name for rb in self.robots),
                 self.graph.zid)
        while not self._stop.wait(0.5):  # a stop signal raises SystemExit here
            pass
        return 0

    def close(self) -> None:
        self._stop.set()
        for rb in self.robots:
            rb.stop()
        log.info("ros2 bridge stopped: %s", ", ".join(
            f"{rb.robot} {rb.ticks} ticks, {rb.twists} Twists ({rb.rejected.total} rejected)"
            for rb in self.robots))

    def counters(self) -> dict:
        per = {rb.robot: rb.counters() for rb in self.robots}
        return {"robots": per,
                "ticks": sum(c["ticks"] for c in per.values()),
                "cmd_vel": sum(c["cmd_vel"] for c in per.values()),
                "cmd_vel_rejected": sum(c["cmd_vel_rejected"] for c in per.values())}
