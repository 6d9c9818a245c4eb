"""rhbl messages <-> ROS 2 messages (rosbags' classes), pure functions (docs/ros2.md, "Mapping").

From an rhbl robot to ROS 2::

    laserscan_from_scan(scan, frames.laser, scan_time=0.1)  -> sensor_msgs/msg/LaserScan
    odometry_from_state(state, frames)                      -> nav_msgs/msg/Odometry
    tf_from_state(state, frames)                            -> tf2_msgs/msg/TFMessage (odom -> base)
    velcmd_from_twist(twist, max_vx=..., max_va=...)        -> VelCmd (clamped, like the server)
    clock_from_time(ts)                                     -> rosgraph_msgs/msg/Clock
    RobotFeed(topics, frames, scan_time).of_scan(scan) / .of_state(state)
                                                            -> [(Topic, message)]: a robot's tick

From a ROS 2 robot to rhbl::

    scan_from_laserscan(msg, scan_id)                       -> Scan (any beam count and span)
    pose_from_odometry(msg)                                 -> (x, y, yaw)
    twist_from_velcmd(cmd)                                  -> geometry_msgs/msg/Twist

Conventions carried over: both sides put beam 0 at ``angle_min`` and count counter-clockwise
(x forward, y left, REP-103), so angles, increments and ranges are copied as they are. Where
they differ, REP-117 decides: rhbl reports "no echo within range" as ``max_range``, ROS 2 as
``+inf``; a ROS 2 reading that is NaN, infinite or outside ``[range_min, range_max]`` is no
echo for rhbl (``max_range``), except ``-inf`` ("too close to measure"), which becomes
``range_min``. Times: rhbl's sim seconds become the header stamps (ROS 2 nodes then run with
``use_sim_time`` on a ``/clock`` topic). Input from ROS 2 that is not finite or not a scan is a
:class:`DecodeError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from protocol.codec import DecodeError
from protocol.messages import Scan, State, VelCmd
from protocol.ros2.cdr import CLOCK, LASER_SCAN, ODOMETRY, TF_MESSAGE, TWIST, TWIST_STAMPED, types
from protocol.ros2.graph import RobotTopics, Topic

__all__ = [
    "Frames",
    "RobotFeed",
    "clock_from_time",
    "laserscan_from_scan",
    "odometry_from_state",
    "pose_from_odometry",
    "scan_from_laserscan",
    "seconds",
    "stamp",
    "tf_from_state",
    "twist_from_velcmd",
    "velcmd_from_twist",
]

MAX_BEAMS = 100_000  # the largest scan accepted from ROS 2 (as for rhbl's own scans)


@dataclass(frozen=True)
class Frames:
    """The TF frames of one robot: ``odom`` (odometry's fixed frame), ``base`` (the robot) and
    ``laser`` (the scans' frame; the simulated laser sits at the robot's centre facing forward,
    so by default the base frame itself)."""

    odom: str
    base: str
    laser: str = ""

    def __post_init__(self):
        for name in ("odom", "base", "laser"):
            v = getattr(self, name)
            if not isinstance(v, str) or v.startswith("/") or (name != "laser" and not v):
                raise ValueError(f"frame {name!r} must be a non-empty name without a leading "
                                 f"'/', got {v!r}")
        if not self.laser:
            object.__setattr__(self, "laser", self.base)

    @classmethod
    def for_robot(cls, robot: str) -> Frames:
        """``<robot>/odom`` and ``<robot>/base_link``: one ``/tf`` shared by many robots."""
        return cls(f"{robot}/odom", f"{robot}/base_link")


def stamp(t: float):
    """A ``builtin_interfaces/msg/Time`` of ``t`` seconds (nanoseconds rounded)."""
    t = float(t)
    if not math.isfinite(t) or not -2**31 <= t < 2**31:
        raise ValueError(f"a time stamp must be finite seconds within int32, got {t!r}")
    ns = round(t * 1e9)
    sec, nanosec = divmod(ns, 1_000_000_000)
    return types()["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def seconds(time_msg) -> float:
    """The seconds of a ``builtin_interfaces/msg/Time``."""
    return time_msg.sec + time_msg.nanosec * 1e-9


def _header(t: float, frame_id: str):
    return types()["std_msgs/msg/Header"](stamp=stamp(t), frame_id=frame_id)


def _vector3(x=0.0, y=0.0, z=0.0):
    return types()["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def _quaternion(yaw: float):
    return types()["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def clock_from_time(t: float):
    """``rosgraph_msgs/msg/Clock`` at sim time ``t``: what ``use_sim_time`` nodes follow."""
    return types()[CLOCK](clock=stamp(t))


def laserscan_from_scan(scan: Scan, frame_id: str, scan_time: float = 0.0,
                        range_min: float = 0.0):
    """The ROS 2 ``LaserScan`` of an rhbl ``Scan``: same angles, increment and ranges, except
    that a beam at ``max_range`` (no echo) becomes ``+inf``. ``scan_time`` is the time between
    scans (1 / the laser's rate); all beams of a simulated scan are taken at once
    (``time_increment`` 0)."""
    ranges = np.asarray(scan.ranges, dtype=np.float32).copy()
    ranges[ranges >= np.float32(scan.max_range)] = np.inf
    return types()[LASER_SCAN](
        header=_header(scan.ts, frame_id),
        angle_min=float(scan.min_angle),
        angle_max=float(scan.max_angle),
        angle_increment=float(scan.resolution),
        time_increment=0.0,
        scan_time=float(scan_time),
        range_min=float(range_min),
        range_max=float(scan.max_range),
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def _finite(what: str, name: str, value) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise DecodeError(f"{what}: field {name!r}: expected a finite number, got {v!r}")
    return v


def scan_from_laserscan(msg, scan_id: int = 0,
                        pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Scan:
    """An rhbl ``Scan`` of a ROS 2 ``LaserScan`` of any beam count, span and direction (a
    clockwise scan, negative ``angle_increment``, is reversed), its ranges in rhbl's convention
    (REP-117 readings of no echo -> ``range_max``). ``ts`` is the header stamp."""
    w = LASER_SCAN
    a0 = _finite(w, "angle_min", msg.angle_min)
    inc = _finite(w, "angle_increment", msg.angle_increment)
    rmin = _finite(w, "range_min", msg.range_min)
    rmax = _finite(w, "range_max", msg.range_max)
    raw = np.asarray(msg.ranges, dtype=np.float64).reshape(-1)
    n = raw.size
    if not 1 <= n <= MAX_BEAMS:
        raise DecodeError(f"{w}: field 'ranges': expected 1..{MAX_BEAMS} beams, got {n}")
    if inc == 0.0 and n > 1:
        raise DecodeError(f"{w}: field 'angle_increment': 0 with {n} beams")
    if abs(inc) * (n - 1) > 2.0 * math.pi + 1e-6:
        raise DecodeError(f"{w}: {n} beams of {inc!r} rad span more than a full turn")
    if not 0.0 <= rmin < rmax:
        raise DecodeError(f"{w}: fields 'range_min', 'range_max': expected 0 <= range_min < "
                          f"range_max, got {rmin!r}, {rmax!r}")
    if inc < 0.0:
        raw, a0, inc = raw[::-1], a0 + inc * (n - 1), -inc
    with np.errstate(invalid="ignore"):
        echo = np.isfinite(raw) & (raw >= rmin) & (raw <= rmax)
    ranges = np.where(echo, raw, rmax)
    ranges[np.isneginf(raw)] = rmin
    return Scan(
        ts=seconds(msg.header.stamp),
        id=int(scan_id),
        ranges=ranges.astype(np.float32),
        pose=tuple(float(v) for v in pose),
        min_angle=a0,
        max_angle=a0 + inc * (n - 1),
        resolution=inc if n > 1 else 0.0,
        max_range=rmax,
    )


def _pose_msg(state: State):
    x, y, yaw = state.pos
    t = types()
    return t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
        orientation=_quaternion(yaw))


def odometry_from_state(state: State, frames: Frames):
    """``Odometry`` of an rhbl ``State``: the odometry pose in ``frames.odom``, the velocity
    (robot frame) in ``frames.base``; covariances zero (the simulator does not estimate them)."""
    t = types()
    vx, vy, va = state.vel
    zeros = np.zeros(36, dtype=np.float64)
    return t[ODOMETRY](
        header=_header(state.ts, frames.odom),
        child_frame_id=frames.base,
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=_pose_msg(state), covariance=zeros),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t[TWIST](linear=_vector3(vx, vy), angular=_vector3(z=va)),
            covariance=zeros.copy()),
    )


def tf_from_state(state: State, frames: Frames):
    """The ``TFMessage`` with one transform, ``frames.odom`` -> ``frames.base``: the odometry
    pose of an rhbl ``State``."""
    t = types()
    x, y, yaw = state.pos
    tf = t["geometry_msgs/msg/TransformStamped"](
        header=_header(state.ts, frames.odom),
        child_frame_id=frames.base,
        transform=t["geometry_msgs/msg/Transform"](translation=_vector3(x, y),
                                                    rotation=_quaternion(yaw)),
    )
    return t[TF_MESSAGE](transforms=[tf])


def pose_from_odometry(msg) -> tuple[float, float, float]:
    """``(x, y, yaw)`` of an ``Odometry`` (yaw from the orientation quaternion, in (-pi, pi])."""
    w = ODOMETRY
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    x = _finite(w, "pose.pose.position.x", p.x)
    y = _finite(w, "pose.pose.position.y", p.y)
    qx, qy, qz, qw = (_finite(w, f"pose.pose.orientation.{k}", getattr(q, k)) for k in "xyzw")
    if qx * qx + qy * qy + qz * qz + qw * qw < 1e-12:
        raise DecodeError(f"{w}: field 'pose.pose.orientation': a zero quaternion has no yaw")
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return x, y, (math.pi if yaw == -math.pi else yaw)


def velcmd_from_twist(msg, *, max_vx: float, max_va: float, source: str = "ros2",
                      scan_id: int | None = None, ts: float | None = None) -> VelCmd:
    """The rhbl ``VelCmd`` of a ``Twist`` (or ``TwistStamped``): ``linear.x`` -> vx and
    ``angular.z`` -> va, clamped to ``|vx| <= max_vx``, ``|va| <= max_va`` as the server
    clamps; ``linear.y`` is carried as vy (a differential drive ignores it), the other
    components are ignored. A non-finite component refuses the whole command (DecodeError)."""
    for name, limit in (("max_vx", max_vx), ("max_va", max_va)):
        if not (isinstance(limit, int | float) and math.isfinite(limit) and limit >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {limit!r}")
    typename = getattr(msg, "__msgtype__", "")
    if typename == TWIST_STAMPED:
        msg = msg.twist
    elif typename != TWIST:
        raise DecodeError(f"expected a {TWIST} or {TWIST_STAMPED}, got {typename or type(msg).__name__}")
    what = typename
    values = {}
    for part in ("linear", "angular"):
        for k in "xyz":
            values[f"{part}.{k}"] = _finite(what, f"{part}.{k}", getattr(getattr(msg, part), k))
    vx = min(max(values["linear.x"], -max_vx), max_vx)
    va = min(max(values["angular.z"], -max_va), max_va)
    return VelCmd(vx=vx, va=va, vy=values["linear.y"], state=True, source=source,
                  scan_id=scan_id, ts=ts)


def twist_from_velcmd(cmd: VelCmd) -> Any:
    """The ``Twist`` of an rhbl command: vx, vy -> ``linear``, va -> ``angular.z`` (zero for
    a command with the motors off)."""
    if not cmd.state:
        return types()[TWIST](linear=_vector3(), angular=_vector3())
    return types()[TWIST](linear=_vector3(cmd.vx, cmd.vy), angular=_vector3(z=cmd.va))


@dataclass(frozen=True)
class RobotFeed:
    """What one rhbl robot's data become on ROS 2 (docs/ros2.md, "Mapping"): each scan a
    ``LaserScan`` on ``topics.scan`` (``scan_time`` s between scans: 1 / the laser's rate, 0 if
    unknown), each state an ``Odometry`` on ``topics.odom``, a ``TFMessage`` (odom -> base) on
    ``topics.tf`` and, with ``clock``, the sim time on ``topics.clock``. The one mapping that
    ``rhbl ros2`` publishes and ``rhbl record --ros2`` writes."""

    topics: RobotTopics
    frames: Frames
    scan_time: float = 0.0
    clock: bool = True

    def of_scan(self, scan: Scan) -> list[tuple[Topic, Any]]:
        return [(self.topics.scan, laserscan_from_scan(scan, self.frames.laser, self.scan_time))]

    def of_state(self, state: State) -> list[tuple[Topic, Any]]:
        out = [(self.topics.odom, odometry_from_state(state, self.frames)),
               (self.topics.tf, tf_from_state(state, self.frames))]
        if self.clock:
            out.append((self.topics.clock, clock_from_time(state.ts)))
        return out

    @property
    def published(self) -> tuple[Topic, ...]:
        """The topics this feed writes to."""
        t = self.topics
        return t.published if self.clock else (t.scan, t.odom, t.tf)
