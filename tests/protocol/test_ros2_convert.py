"""protocol.ros2.convert: rhbl Scan/State/VelCmd <-> LaserScan, Odometry, TFMessage, Twist."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol import DecodeError
from protocol.messages import Scan, State, VelCmd
from protocol.ros2 import cdr
from protocol.ros2.convert import (
    Frames,
    laserscan_from_scan,
    odometry_from_state,
    pose_from_odometry,
    scan_from_laserscan,
    seconds,
    stamp,
    tf_from_state,
    twist_from_velcmd,
    velcmd_from_twist,
)
from server import world_path
from server.world import LASER, ROBOT, World, load_world

T = cdr.types()


def _sim_scan() -> Scan:
    """A scan of the simulator's own laser in the room world (what the bridge will carry)."""
    world = World(load_world(world_path("room")), seed=0)
    ranges = world.scan(0)
    assert (ranges == LASER.max_range).any() and (ranges < LASER.max_range).any()
    return Scan(ts=0.1, id=2, ranges=ranges, pose=world.odom(0), min_angle=LASER.min_angle,
                max_angle=LASER.max_angle, resolution=LASER.resolution,
                max_range=LASER.max_range)


def test_scan_to_laserscan_keeps_the_lasers_angles_ranges_and_limits():
    scan = _sim_scan()
    msg = cdr.deserialize(cdr.serialize(laserscan_from_scan(scan, "r0/base_link", 0.1)),
                          cdr.LASER_SCAN)
    assert len(msg.ranges) == LASER.count
    bearings = msg.angle_min + np.arange(LASER.count) * msg.angle_increment
    assert np.allclose(bearings, LASER.bearings(), atol=1e-6)
    assert msg.angle_max == pytest.approx(LASER.max_angle, abs=1e-6)
    assert (msg.range_min, msg.range_max, msg.time_increment) == (0.0, LASER.max_range, 0.0)
    assert msg.scan_time == pytest.approx(0.1)
    echo = scan.ranges < LASER.max_range
    assert np.array_equal(msg.ranges[echo], scan.ranges[echo])
    assert np.isposinf(msg.ranges[~echo]).all()  # REP-117: no echo is +inf
    back = scan_from_laserscan(msg, scan_id=2, pose=scan.pose)
    assert np.array_equal(back.ranges, scan.ranges)  # and comes back as max_range
    assert back.count == scan.count and back.ts == pytest.approx(0.1)
    assert back.resolution == pytest.approx(scan.resolution, abs=1e-7)


_DEG120 = math.radians(120)


def _laserscan(ranges, angle_min=-_DEG120, span=2 * _DEG120, rmin=0.05, rmax=10.0, t=3.25):
    ranges = np.asarray(ranges, dtype=np.float32)
    n = len(ranges)
    return T[cdr.LASER_SCAN](
        header=T["std_msgs/msg/Header"](stamp=stamp(t), frame_id="laser"),
        angle_min=angle_min, angle_max=angle_min + span,
        angle_increment=span / (n - 1) if n > 1 else 0.0, time_increment=1e-5, scan_time=0.1,
        range_min=rmin, range_max=rmax, ranges=ranges, intensities=np.zeros(0, np.float32))


def test_a_ros2_laser_of_any_layout_becomes_an_rhbl_scan():
    ranges = np.full(640, 3.0, dtype=np.float32)
    ranges[:5] = [np.nan, np.inf, -np.inf, 0.01, 12.0]  # REP-117 and out-of-range readings
    scan = scan_from_laserscan(_laserscan(ranges), scan_id=9, pose=(1.0, 2.0, 0.3))
    assert (scan.count, scan.id, scan.pose, scan.ts) == (640, 9, (1.0, 2.0, 0.3), 3.25)
    assert scan.min_angle == pytest.approx(-math.radians(120), abs=1e-6)
    assert scan.max_angle == pytest.approx(math.radians(120), abs=1e-5)
    assert scan.max_range == pytest.approx(10.0)
    assert list(scan.ranges[:5]) == pytest.approx([10.0, 10.0, 0.05, 10.0, 10.0])
    assert (scan.ranges[5:] == 3.0).all()
    Scan.decode(scan.encode())  # a valid rhbl message


def test_a_clockwise_laser_is_turned_counter_clockwise():
    n = 11
    cw = _laserscan(np.arange(1, n + 1), angle_min=math.radians(50), span=-math.radians(100),
                   rmax=20.0)
    scan = scan_from_laserscan(cw)
    assert scan.min_angle == pytest.approx(-math.radians(50), abs=1e-6)
    assert scan.resolution == pytest.approx(math.radians(10), abs=1e-6)
    assert list(scan.ranges) == list(range(n, 0, -1))  # the beam at -50 deg was the last


@pytest.mark.parametrize(("field", "value", "match"), [
    ("angle_increment", float("nan"), "'angle_increment': expected a finite number"),
    ("angle_increment", 0.0, "'angle_increment': 0 with 640 beams"),
    ("angle_increment", 0.1, "span more than a full turn"),
    ("range_max", float("inf"), "'range_max': expected a finite number"),
    ("range_min", 20.0, "range_min < range_max"),
    ("ranges", np.zeros(0, np.float32), "expected 1..100000 beams, got 0"),
])
def test_laserscans_that_are_not_scans_are_decode_errors(field, value, match):
    msg = _laserscan(np.ones(640))
    setattr(msg, field, value)
    with pytest.raises(DecodeError, match=f"sensor_msgs/msg/LaserScan: .*{match}"):
        scan_from_laserscan(msg)


def test_state_to_odometry_and_tf():
    frames = Frames.for_robot("r0")
    state = State(ts=4.5, seq=45, pos=(2.0, -1.0, 3.0), vel=(0.3, 0.01, -0.2))
    odom = cdr.deserialize(cdr.serialize(odometry_from_state(state, frames)), cdr.ODOMETRY)
    assert (odom.header.frame_id, odom.child_frame_id) == ("r0/odom", "r0/base_link")
    assert (odom.header.stamp.sec, odom.header.stamp.nanosec) == (4, 500_000_000)
    p = odom.pose.pose
    assert (p.position.x, p.position.y, p.position.z) == (2.0, -1.0, 0.0)
    assert pose_from_odometry(odom) == pytest.approx((2.0, -1.0, 3.0))
    tw = odom.twist.twist
    assert (tw.linear.x, tw.linear.y, tw.angular.z) == (0.3, 0.01, -0.2)
    tf = cdr.deserialize(cdr.serialize(tf_from_state(state, frames)), cdr.TF_MESSAGE)
    (t,) = tf.transforms
    assert (t.header.frame_id, t.child_frame_id) == ("r0/odom", "r0/base_link")
    assert (t.transform.translation.x, t.transform.translation.y) == (2.0, -1.0)
    assert (t.transform.rotation.z, t.transform.rotation.w) == pytest.approx(
        (math.sin(1.5), math.cos(1.5)))
    assert Frames("odom", "base_link").laser == "base_link"
    with pytest.raises(ValueError, match="leading '/'"):
        Frames("/odom", "base_link")


@given(st.floats(-math.pi, math.pi, exclude_min=True))
def test_yaw_roundtrips_through_the_quaternion(yaw):
    odom = odometry_from_state(State(ts=0.0, seq=0, pos=(0.0, 0.0, yaw)), Frames("o", "b"))
    got = pose_from_odometry(odom)[2]
    assert -math.pi < got <= math.pi
    assert math.isclose(math.remainder(got - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)


def test_bad_odometry_is_a_decode_error():
    odom = odometry_from_state(State(ts=0.0, seq=0, pos=(0.0, 0.0, 0.0)), Frames("o", "b"))
    odom.pose.pose.orientation.w = 0.0
    with pytest.raises(DecodeError, match="zero quaternion"):
        pose_from_odometry(odom)
    odom.pose.pose.position.x = float("nan")
    with pytest.raises(DecodeError, match="'pose.pose.position.x': expected a finite"):
        pose_from_odometry(odom)


def _twist(lx=0.0, ly=0.0, az=0.0, **other):
    v = T["geometry_msgs/msg/Vector3"]
    return T[cdr.TWIST](linear=v(x=lx, y=ly, z=other.get("lz", 0.0)),
                        angular=v(x=other.get("ax", 0.0), y=0.0, z=az))


@given(st.floats(-5, 5), st.floats(-10, 10))
def test_twist_is_clamped_as_the_server_clamps(lx, az):
    cmd = velcmd_from_twist(_twist(lx, 0.0, az), max_vx=ROBOT.max_vx, max_va=ROBOT.max_va)
    world = World(load_world(world_path("corridor")))
    world.set_command(0, lx, az)
    assert (cmd.vx, cmd.va) == world.command(0)
    assert (cmd.source, cmd.state) == ("ros2", True)
    VelCmd.decode(cmd.encode())


def test_twist_stamped_lateral_and_the_rest():
    stamped = T[cdr.TWIST_STAMPED](header=T["std_msgs/msg/Header"](stamp=stamp(1.0), frame_id=""),
                                   twist=_twist(0.2, 0.05, -0.3, lz=9.0, ax=9.0))
    cmd = velcmd_from_twist(stamped, max_vx=0.5, max_va=1.0, source="ros2-nav", scan_id=7, ts=0.7)
    assert (cmd.vx, cmd.vy, cmd.va, cmd.source, cmd.scan_id, cmd.ts) == (
        0.2, 0.05, -0.3, "ros2-nav", 7, 0.7)
    back = twist_from_velcmd(cmd)
    assert (back.linear.x, back.linear.y, back.angular.z) == (0.2, 0.05, -0.3)
    off = twist_from_velcmd(VelCmd(vx=0.2, va=0.3, state=False))
    assert (off.linear.x, off.angular.z) == (0.0, 0.0)


@pytest.mark.parametrize("bad", [dict(lx=float("nan")), dict(az=float("inf")),
                                 dict(lz=float("-inf"))])
def test_non_finite_twists_are_refused(bad):
    with pytest.raises(DecodeError, match="geometry_msgs/msg/Twist: field '.*': expected a finite"):
        velcmd_from_twist(_twist(**bad), max_vx=0.5, max_va=1.0)


def test_not_a_twist_or_bad_limits():
    with pytest.raises(DecodeError, match="expected a geometry_msgs/msg/Twist or"):
        velcmd_from_twist(T[cdr.CLOCK](clock=stamp(0)), max_vx=0.5, max_va=1.0)
    with pytest.raises(ValueError, match="max_va"):
        velcmd_from_twist(_twist(), max_vx=0.5, max_va=float("nan"))


def test_stamps():
    assert (stamp(0.1).sec, stamp(0.1).nanosec) == (0, 100_000_000)
    assert (stamp(2.9999999999).sec, stamp(2.9999999999).nanosec) == (3, 0)  # carried
    assert seconds(stamp(12.3)) == pytest.approx(12.3)
    with pytest.raises(ValueError, match="finite seconds"):
        stamp(float("nan"))
