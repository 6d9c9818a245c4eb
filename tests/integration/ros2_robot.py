"""A ROS 2-style robot for the tests and benchmarks, written without our ROS 2 layer.

Its messages and CDR bytes come from ``rosbags`` (the ROS 2 Jazzy typestore) directly; its keys
and sample attachments are formatted here after rmw_zenoh's layout (``<domain>/<topic>/<DDS
type>/<RIHS01 hash>``; sequence number, timestamp, a 16-byte GID); nothing of
``protocol.ros2`` is used, so what ``rhbl controller --ros2`` reads from it was written by code
nobody here wrote. It moves in the simulator's world and physics (``server.world.World``) and
carries a laser of its own layout (640 beams over 240 degrees by default, 10 m), cast with the
simulator's own kernels (``server.laser.Laser``): a cast covers at most 180 degrees, so the
laser is two casts of half its beams, the second turned by half the span.

It steps in lock-step with its driver: publish an ``Odometry`` and a ``LaserScan``, wait for the
``Twist`` that answers them, apply it, step the world 0.1 s. The episode it records is a
``lab.episode.Episode`` like ``lab.harness.drive``'s (the true pose after each step, stalls, the
action each Twist names, the distance to the followed wall from the simulator's own 360-beam
laser), so ``lab.evaluate``'s success rule judges both alike.

    with zenoh.open(router_config) as session:
        robot = Ros2StyleRobot(session, spec, start, actions)
        episode = robot.run(steps=1200)
"""

from __future__ import annotations

import math
import os
import struct
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore
from waiting import Timeout, eventually

from client.behaviour.spec import for_world
from lab import metrics
from lab.episode import DT, Episode
from server.laser import Laser
from server.world import ROBOT, World, WorldSpec, wrap_angle

STORE = get_typestore(Stores.ROS2_JAZZY)
T = STORE.types
LASER_SCAN, ODOMETRY, TWIST = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", \
    "geometry_msgs/msg/Twist"


def ros2_key(domain: int, topic: str, typename: str) -> str:
    """rmw_zenoh's data key of ``topic`` (``/r0/scan``) of type ``pkg/msg/Name``."""
    pkg, _, name = typename.split("/")
    return (f"{domain}/{topic.lstrip('/')}/{pkg}::msg::dds_::{name}_/"
            f"{STORE.hash_rihs01(typename)}")


class _Publisher:
    """A zenoh publisher that attaches what rmw_zenoh attaches to every sample. It blocks
    rather than drop a sample under congestion (a loaded machine): a lock-step robot that lost
    a scan would wait for an answer that never comes."""

    def __init__(self, session, key: str):
        self.pub = session.declare_publisher(key, express=True,
                                             congestion_control=zenoh.CongestionControl.BLOCK)
        self.gid = os.urandom(16)
        self.seq = 0

    def put(self, msg, typename: str) -> None:
        self.seq += 1
        att = struct.pack("<qqB", self.seq, time.time_ns(), 16) + self.gid
        self.pub.put(bytes(STORE.serialize_cdr(msg, typename)), attachment=att)

    def undeclare(self) -> None:
        self.pub.undeclare()


class OtherLaser:
    """``count`` beams over ``fov_deg`` degrees centred ahead, counter-clockwise from the
    robot's right, ``max_range`` m, cast with the simulator's kernels against ``spec``'s walls."""

    def __init__(self, spec: WorldSpec, count: int = 640, fov_deg: float = 240.0,
                 max_range: float = 10.0):
        self.count, self.max_range = count, max_range
        span = math.radians(fov_deg)
        self.min_angle, self.increment = -span / 2.0, span / (count - 1)
        self.half = (count + 1) // 2
        bearings = self.min_angle + np.arange(self.half) * self.increment
        self.laser = Laser(spec.segments(), bearings, max_range, ROBOT.radius, robots=2)
        self.rows = np.arange(2, dtype=np.intp)

    def cast(self, pose) -> np.ndarray:
        x, y, yaw = pose
        yaws = np.array([yaw, wrap_angle(yaw + self.half * self.increment)])
        out = self.laser.cast(np.array([[x, y], [x, y]]), yaws, self.rows, np.zeros((0, 2)))
        return np.concatenate([out[0], out[1][: self.count - self.half]])


class Ros2StyleRobot:
    """One robot in ``spec`` at ``start`` on ROS 2 keys: ``/<robot>/scan``, ``/<robot>/odom``
    out, ``/<robot>/cmd_vel`` in (domain ``domain``); ``actions`` names the Twists it gets."""

    def __init__(self, session, spec: WorldSpec, start, actions, *, robot: str = "r0",
                 domain: int = 0, laser: OtherLaser | None = None, seed: int = 0):
        self.spec, self.actions = spec, actions
        self.world = World(spec, robots=1, seed=seed)
        self.start = tuple(float(v) for v in start)
        self.world.reset(poses=[self.start])
        self.laser = laser or OtherLaser(spec)
        self.frame, self.odom_frame = f"{robot}/base_link", f"{robot}/odom"
        self.names = {tuple(v): k for k, v in actions.items()}
        self.scan_pub = _Publisher(session, ros2_key(domain, f"/{robot}/scan", LASER_SCAN))
        self.odom_pub = _Publisher(session, ros2_key(domain, f"/{robot}/odom", ODOMETRY))
        self._cond = threading.Condition()
        self._twists: list = []
        self.sub = session.declare_subscriber(ros2_key(domain, f"/{robot}/cmd_vel", TWIST),
                                              self._on_twist)
        self.resent = 0

    def _on_twist(self, sample) -> None:
        msg = STORE.deserialize_cdr(sample.payload.to_bytes(), TWIST)
        with self._cond:
            self._twists.append(msg)
            self._cond.notify_all()

    def close(self) -> None:
        for thing in (self.sub, self.scan_pub, self.odom_pub):
            thing.undeclare()

    def _stamp(self):
        ns = round(self.world.time * 1e9)
        return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000,
                                                nanosec=ns % 1_000_000_000)

    def publish(self) -> None:
        """The odometry, then the scan of now."""
        stamp = self._stamp()
        x, y, yaw = self.world.odom(0)
        vx, vy, va = self.world.velocity(0)
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=self.odom_frame)
        vec = T["geometry_msgs/msg/Vector3"]
        odom = T[ODOMETRY](
            header=header, child_frame_id=self.frame,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))),
                covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T[TWIST](linear=vec(x=vx, y=vy, z=0.0), angular=vec(x=0.0, y=0.0, z=va)),
                covariance=np.zeros(36)))
        self.odom_pub.put(odom, ODOMETRY)
        ranges = self.laser.cast(self.world.pose(0)).astype(np.float32)
        ranges[ranges >= self.laser.max_range] = np.inf  # REP-117: no echo
        scan = T[LASER_SCAN](
            header=T["std_msgs/msg/Header"](stamp=stamp, frame_id=self.frame),
            angle_min=self.laser.min_angle,
            angle_max=self.laser.min_angle + (self.laser.count - 1) * self.laser.increment,
            angle_increment=self.laser.increment, time_increment=0.0, scan_time=DT,
            range_min=0.05, range_max=self.laser.max_range, ranges=ranges,
            intensities=np.zeros(0, dtype=np.float32))
        self.scan_pub.put(scan, LASER_SCAN)

    def next_twist(self, timeout: float):
        """The next Twist to arrive (None after ``timeout`` s)."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._twists, timeout):
                return None
            return self._twists.pop(0)

    def _answer(self, timeout: float):
        """The Twist answering the scan just published; the scan is published again every 2 s
        until one comes (the driver's Twist may be dropped under congestion: rmw_zenoh's
        reliable keep-last publishers drop rather than block, and a real robot keeps
        publishing); None after ``timeout`` s."""
        twist = self.next_twist(min(2.0, timeout))
        if twist is not None:
            return twist

        def again():
            self.resent += 1
            self.publish()
            return self.next_twist(2.0)

        try:
            return eventually(again, timeout, "a Twist answering the scan", every=0.001)
        except Timeout:
            return None

    def run(self, steps: int, first_timeout: float = 60.0, timeout: float = 30.0) -> Episode:
        """``steps`` lock-step steps of 0.1 s; the episode recorded. The first scan is sent
        again every second until a Twist answers (the driver may not be subscribed yet);
        after that a step waits ``timeout`` s for its Twist, sending its scan again every 2 s
        (``resent`` counts them; AssertionError if none comes)."""
        ep = Episode(start=self.start, dt=DT, kind="ros2")
        side = for_world(self.spec.name, self.spec.path).band_side  # its behaviour's band side
        self.publish()
        twist = self.next_twist(1.0)
        if twist is None:
            def again():
                self.resent += 1
                self.publish()
                return self.next_twist(1.0)

            twist = eventually(again, first_timeout, "a Twist answering the first scan",
                               every=0.001)
        with self._cond:
            self._twists.clear()  # answers to the scans sent again, if any
        for k in range(steps):
            if k:
                self.publish()
                twist = self._answer(timeout)
                assert twist is not None, f"no Twist answered scan {k} within {timeout:g} s"
            vx, va = twist.linear.x, twist.angular.z
            native = self.world.scan(0)  # the simulator's laser: the metric's wall distance
            self.world.set_command(0, vx, va)
            self.world.step(DT)
            ep.actions.append(self.names.get((vx, va), "other"))
            ep.poses.append(self.world.pose(0))
            ep.stalls.append(self.world.stall(0))
            if side is not None:
                ep.side.append(metrics.side_distance(native, side))
            if self.spec.goal is not None and self.world.at_goal(0):
                break
        return ep
