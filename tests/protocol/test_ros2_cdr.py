"""protocol.ros2.cdr: our CDR read by a decoder nobody here wrote (mcap-ros2-support, which
parses the .msg text itself), that decoder's CDR read by ours, type hashes, malformed input."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

from protocol import DecodeError
from protocol.messages import Scan, State, VelCmd
from protocol.ros2 import cdr
from protocol.ros2.convert import (
    Frames,
    clock_from_time,
    laserscan_from_scan,
    odometry_from_state,
    tf_from_state,
    twist_from_velcmd,
)

# Data: the RIHS01 hashes ROS 2 Jazzy's rosidl generates for these types (as they appear in
# the type support of Jazzy builds and in rmw_zenoh keys on a Jazzy robot).
HASHES = {
    cdr.LASER_SCAN: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    cdr.ODOMETRY: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    cdr.TF_MESSAGE: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    cdr.TWIST: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
}
FRAMES = Frames.for_robot("r0")


def _scan() -> Scan:
    ranges = np.linspace(0.3, 8.0, 360, dtype=np.float32)
    ranges[::7] = 8.0  # no echo (52 beams, and the last one at 8.0)
    return Scan(ts=12.3, id=124, ranges=ranges, pose=(1.0, 2.0, 0.5))


def _state() -> State:
    return State(ts=12.3, seq=124, pos=(1.5, -2.25, 2.9), vel=(0.4, 0.0, -0.7))


def _messages():
    return {
        cdr.LASER_SCAN: laserscan_from_scan(_scan(), FRAMES.laser, scan_time=0.1),
        cdr.ODOMETRY: odometry_from_state(_state(), FRAMES),
        cdr.TF_MESSAGE: tf_from_state(_state(), FRAMES),
        cdr.TWIST: twist_from_velcmd(VelCmd(vx=0.3, va=-0.5)),
        cdr.CLOCK: clock_from_time(12.3),
    }


def _plain(msg):
    """A rosbags message as nested dicts and lists (what the other decoder is compared with)."""
    if hasattr(msg, "__dataclass_fields__"):
        return {k: _plain(getattr(msg, k)) for k in msg.__dataclass_fields__ if k != "__msgtype__"}
    if isinstance(msg, np.ndarray):
        return [float(x) for x in msg]
    if isinstance(msg, list | tuple):
        return [_plain(x) for x in msg]
    return msg


def _other(obj, like):
    """The other decoder's object read through the field names of ``like`` (its plain form)."""
    if isinstance(like, dict):
        return {k: _other(getattr(obj, k), v) for k, v in like.items()}
    if isinstance(like, list):
        return [_other(o, v) for o, v in zip(list(obj), like, strict=True)]
    return obj


def _same(a, b):
    """Equal, a float also when ``a`` rounded to float32 (a float32 field set from a double)
    equals ``b``."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return (math.isnan(a) and math.isnan(b)) or a == b or float(np.float32(a)) == b
    return a == b


@pytest.mark.parametrize("typename", list(HASHES) + [cdr.CLOCK])
def test_our_cdr_read_by_mcap_ros2(typename):
    msg = _messages()[typename]
    data = cdr.serialize(msg)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation
    schema = Schema(id=1, name=typename, encoding="ros2msg", data=cdr.msgdef(typename).encode())
    decoded = DecoderFactory().decoder_for("cdr", schema)(data)
    ours = _plain(cdr.deserialize(data, typename))
    assert _same(ours, _other(decoded, ours))
    assert _same(_plain(msg), ours)


def test_the_decoded_scan_is_the_rhbl_scan():
    scan = _scan()
    data = cdr.serialize(laserscan_from_scan(scan, "r0/base_link", scan_time=0.1))
    schema = Schema(id=1, name=cdr.LASER_SCAN, encoding="ros2msg",
                    data=cdr.msgdef(cdr.LASER_SCAN).encode())
    m = DecoderFactory().decoder_for("cdr", schema)(data)
    ranges = np.asarray(m.ranges, dtype=np.float32)
    echo = scan.ranges < scan.max_range
    assert np.array_equal(ranges[echo], scan.ranges[echo])
    assert np.isinf(ranges[~echo]).all() and (~echo).sum() == 53
    bearings = m.angle_min + np.arange(len(ranges)) * m.angle_increment
    assert np.allclose(bearings, scan.bearings(), atol=1e-6)  # float32 angles on the wire
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (12, 300_000_000)
    assert (m.header.frame_id, m.range_max, m.scan_time) == ("r0/base_link", 8.0,
                                                              np.float32(0.1))


def _mcap_ros2_bytes(typename: str, message: dict) -> bytes:
    """CDR written by mcap-ros2-support's own encoder (from the .msg text), read back raw."""
    buf = io.BytesIO()
    w = Ros2Writer(buf)
    schema = w.register_msgdef(typename, cdr.msgdef(typename))
    w.write_message("/t", schema, message, log_time=1, publish_time=1)
    w.finish()
    buf.seek(0)
    (_, _, m), = make_reader(buf).iter_messages()
    return m.data


def test_mcap_ros2s_cdr_read_by_ours():
    twist = cdr.deserialize(_mcap_ros2_bytes(cdr.TWIST, {
        "linear": {"x": 0.25, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": -1.5}}),
        cdr.TWIST)
    assert (twist.linear.x, twist.angular.z) == (0.25, -1.5)
    header = {"stamp": {"sec": 3, "nanosec": 5}, "frame_id": "laser"}
    scan = cdr.deserialize(_mcap_ros2_bytes(cdr.LASER_SCAN, {
        "header": header, "angle_min": -2.0, "angle_max": 2.0, "angle_increment": 0.5,
        "time_increment": 0.0, "scan_time": 0.1, "range_min": 0.1, "range_max": 10.0,
        "ranges": [1.0, 2.0, 3.0, float("inf"), 5.0, 6.0, 7.0, 8.0, 9.0], "intensities": []}),
        cdr.LASER_SCAN)
    assert scan.header.frame_id == "laser" and scan.header.stamp.nanosec == 5
    assert list(scan.ranges[:3]) == [1.0, 2.0, 3.0] and np.isinf(scan.ranges[3])
    odom = cdr.deserialize(_mcap_ros2_bytes(cdr.ODOMETRY, {
        "header": header, "child_frame_id": "base_link",
        "pose": {"pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0},
                          "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                 "covariance": [0.0] * 36},
        "twist": {"twist": {"linear": {"x": 0.1, "y": 0.0, "z": 0.0},
                            "angular": {"x": 0.0, "y": 0.0, "z": 0.2}},
                  "covariance": [0.0] * 36}}), cdr.ODOMETRY)
    assert (odom.pose.pose.position.y, odom.twist.twist.angular.z) == (2.0, 0.2)
    tf = cdr.deserialize(_mcap_ros2_bytes(cdr.TF_MESSAGE, {"transforms": [
        {"header": header, "child_frame_id": "a",
         "transform": {"translation": {"x": 1.0, "y": 0.0, "z": 0.0},
                       "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}},
        {"header": header, "child_frame_id": "b",
         "transform": {"translation": {"x": 0.0, "y": 1.0, "z": 0.0},
                       "rotation": {"x": 0.0, "y": 0.0, "z": 1.0, "w": 0.0}}}]}), cdr.TF_MESSAGE)
    assert [t.child_frame_id for t in tf.transforms] == ["a", "b"]


def test_big_endian_cdr_is_read_too():
    msg = twist_from_velcmd(VelCmd(vx=0.3, va=0.1))
    big = bytes(cdr._store().serialize_cdr(msg, cdr.TWIST, little_endian=False))
    assert big[:2] == b"\x00\x00"
    assert cdr.deserialize(big, cdr.TWIST).linear.x == 0.3


def test_type_hashes_are_ros2s():
    for typename, h in HASHES.items():
        assert cdr.type_hash(typename) == h
    with pytest.raises(ValueError, match="not a ROS 2 ROS2_JAZZY message type"):
        cdr.type_hash("nope_msgs/msg/Nothing")


def test_msgdef_is_the_ros2msg_text():
    text = cdr.msgdef(cdr.TWIST)
    assert text.splitlines()[0] == "geometry_msgs/Vector3 linear"
    assert "=" * 80 + "\nMSG: geometry_msgs/Vector3\nfloat64 x" in text


@pytest.mark.parametrize(("data", "match"), [
    (b"", "not valid CDR"),
    (b"\x00\x07\x00\x00" + bytes(48), "not valid CDR"),        # unknown encapsulation
    (cdr.serialize(twist_from_velcmd(VelCmd()))[:-5], "not valid CDR"),   # truncated
    (cdr.serialize(twist_from_velcmd(VelCmd())) + bytes(4), "not valid CDR"),  # trailing
    ("text", "expected CDR bytes"),
    (bytes(5 * 1024 * 1024), "payload of 5242880 bytes exceeds"),
])
def test_malformed_cdr_is_a_decode_error(data, match):
    with pytest.raises(DecodeError, match=f"geometry_msgs/msg/Twist: {match}"):
        cdr.deserialize(data, cdr.TWIST)


def test_padding_up_to_three_bytes_is_accepted():
    data = cdr.serialize(twist_from_velcmd(VelCmd(vx=0.1)))
    for pad in range(4):
        assert cdr.deserialize(data + bytes(pad), cdr.TWIST).linear.x == 0.1


_SCAN_CDR = cdr.serialize(laserscan_from_scan(_scan(), "r0/base_link"))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(_SCAN_CDR) - 1), st.integers(0, 255)), max_size=6),
       st.integers(0, len(_SCAN_CDR)))
def test_corrupted_cdr_decodes_or_raises_decode_error_only(flips, cut):
    data = bytearray(_SCAN_CDR)
    for i, v in flips:
        data[i] = v
    for typename in (cdr.LASER_SCAN, cdr.TWIST, cdr.ODOMETRY, cdr.TF_MESSAGE):
        with contextlib.suppress(DecodeError):
            cdr.deserialize(bytes(data[:cut]), typename)
