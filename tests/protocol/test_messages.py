"""protocol: keys, messages and the codec's validation."""

from __future__ import annotations

import contextlib
import math

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import PROTOCOL_VERSION, DecodeError, ProtocolError, keys
from protocol.messages import (
    Ack,
    DriverState,
    Geometry,
    LaserConfig,
    MotorPower,
    Nack,
    Scan,
    SetOdom,
    SetPose,
    SimPose,
    State,
    TeacherAction,
    TreeNotice,
    VelCmd,
    WorldInfo,
)


def test_keys_are_the_public_contract():
    assert keys.state_key("r0") == "rhbl/r0/position2d/0/data/state"
    assert keys.scan_key("r1") == "rhbl/r1/laser/0/data/scan"
    assert keys.cmd_vel_key() == "rhbl/r0/position2d/0/cmd/vel"
    assert keys.cmd_vel_key("r0", source="teacher") == "rhbl/r0/position2d/0/cmd/vel/teacher"
    assert keys.source_of_cmd_key("rhbl/r0/position2d/0/cmd/vel/teacher") == "teacher"
    assert keys.source_of_cmd_key("rhbl/r0/position2d/0/cmd/vel") is None
    assert keys.driver_key("r0") == "rhbl/r0/position2d/0/data/driver"
    assert keys.request_key("r0", "laser", "get_config") == "rhbl/r0/laser/0/req/get_config"
    assert keys.teacher_action_key("r0") == "rhbl/r0/teacher/action"
    assert keys.learner_notice_key("r0") == "rhbl/r0/learner/notice"
    assert keys.learner_snapshot_key("r0") == "rhbl/r0/learner/snapshot"
    assert keys.alive_key("teacher", "t1") == "rhbl/alive/teacher/t1"
    assert keys.alive_key("server", "*") == "rhbl/alive/server/*"
    assert keys.robot_name(3) == "r3"
    for bad in ["", "a/b", "*", "r 0", "x?"]:
        with pytest.raises(ValueError, match="robot"):
            keys.state_key(bad)


def _roundtrip(msg):
    out = type(msg).decode(msg.encode())
    assert msgpack.unpackb(msg.encode())["v"] == PROTOCOL_VERSION
    return out


def test_roundtrips():
    s = State(
        ts=1.5,
        seq=3,
        pos=(1.0, 2.0, 0.5),
        vel=(0.1, 0.0, -0.2),
        stall=True,
        driver="teacher",
        truth=(1.0, 2.0, 0.5),
    )
    assert _roundtrip(s) == s
    r = np.linspace(0, 8, 360).astype(np.float32)
    sc = _roundtrip(Scan(ts=2.0, id=7, ranges=r, pose=(1.0, 2.0, 3.0)))
    assert sc.ranges.dtype == np.float32 and np.array_equal(sc.ranges, r) and sc.count == 360
    assert sc.bearings()[0] == pytest.approx(-math.pi / 2)
    raw = msgpack.unpackb(Scan(ts=0.0, id=1, ranges=r).encode())
    assert raw["ranges"] == r.astype("<f4").tobytes()  # little-endian float32 bytes
    c = VelCmd(vx=0.3, va=-0.1, source="controller", scan_id=9, ts=1.0)
    assert _roundtrip(c) == c
    assert msgpack.unpackb(c.encode())["vel"] == [0.3, 0.0, -0.1]
    for m in [
        DriverState(source="teacher", ts=1.0, priority=2),
        TeacherAction(scan_id=4, action="fwd-left", source="teacher", ts=0.4, executed="fwd"),
        TreeNotice(seq=1, nodes=53, height=12, vectors=900, snapshot_id="abc:900", ts=1.0),
        Geometry(pose=(0.0, 0.0, 0.0), size=(0.511, 0.4), radius=0.25),
        LaserConfig(min_angle=-1.5, max_angle=1.5, resolution=0.01, max_range=8.0, count=301),
        SetOdom(pose=(1.0, 2.0, 3.0)),
        MotorPower(state=False),
        Ack(info="ok"),
        Nack(reason="no"),
        WorldInfo(name="room", task="wall-following", walls=((0.0, 0.0, 1.0, 0.0),),
                  goal=(1.0, 2.0, 0.5), starts=((0.5, 0.5, 0.0),)),
        WorldInfo(name="open", task="maze"),
    ]:
        assert _roundtrip(m) == m


def test_world_info_names_a_bad_wall():
    good = {"v": PROTOCOL_VERSION, "name": "w", "task": "maze", "walls": [[0, 0, 1, 1]]}
    assert WorldInfo.decode(msgpack.packb(good)).walls == ((0.0, 0.0, 1.0, 1.0),)
    for walls in ([[0, 0, 1]], [[0, 0, 1, float("nan")]], "walls", [["a", 0, 1, 1]]):
        with pytest.raises(DecodeError, match="walls"):
            WorldInfo.decode(msgpack.packb({**good, "walls": walls}))


def test_extra_fields_allowed_and_optional_fields_default():
    m = msgpack.packb({"v": 1, "vel": [0.1, 0, 0.2], "state": True, "whatever": [1, 2]})
    c = VelCmd.decode(m)
    assert (c.vx, c.va, c.source, c.scan_id) == (0.1, 0.2, "", None)


@pytest.mark.parametrize(
    "payload, field",
    [
        ({"vel": [0.1, 0, 0], "state": True}, "'v'"),
        ({"v": 2, "vel": [0.1, 0, 0], "state": True}, "version"),
        ({"v": 1, "state": True}, "'vel'"),
        ({"v": 1, "vel": [0.1, 0], "state": True}, "'vel'"),
        ({"v": 1, "vel": [math.nan, 0, 0], "state": True}, "'vel'"),
        ({"v": 1, "vel": [0, math.inf, 0], "state": True}, "'vel'"),
        ({"v": 1, "vel": [0, "x", 0], "state": True}, "'vel'"),
        ({"v": 1, "vel": [0, 0, 0], "state": 1}, "'state'"),
        ({"v": 1, "vel": [0, 0, 0], "state": True, "scan_id": -1}, "'scan_id'"),
        ({"v": 1, "vel": [0, 0, 0], "state": True, "scan_id": 1.5}, "'scan_id'"),
        ({"v": 1, "vel": [0, 0, 0], "state": True, "source": "x" * 1000}, "'source'"),
    ],
)
def test_decode_names_the_bad_field(payload, field):
    with pytest.raises(DecodeError, match=field):
        VelCmd.decode(msgpack.packb(payload))


def test_decode_rejects_garbage_size_and_bad_ranges():
    assert issubclass(DecodeError, ProtocolError)
    with pytest.raises(DecodeError, match="msgpack"):
        VelCmd.decode(b"\xc1\xc1")
    with pytest.raises(DecodeError, match="map"):
        VelCmd.decode(msgpack.packb([1, 2]))
    with pytest.raises(DecodeError, match="limit"):
        VelCmd.decode(b"\x00" * 100_000)
    with pytest.raises(DecodeError, match="bytes"):
        VelCmd.decode("text")
    good = msgpack.unpackb(Scan(ts=0.0, id=1, ranges=np.ones(10, np.float32)).encode())
    for bad in [b"abc", b"", np.array([np.nan], "<f4").tobytes(), [1.0, 2.0]]:
        m = dict(good, ranges=bad)
        with pytest.raises(DecodeError, match="ranges"):
            Scan.decode(msgpack.packb(m, use_bin_type=True))


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_only_ever_raise_decode_error(data):
    for cls in (VelCmd, State, Scan, TeacherAction, SetOdom):
        with contextlib.suppress(DecodeError):
            cls.decode(data)


values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=5)
    | st.binary(max_size=8),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=4),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from(["v", "vel", "state", "source", "scan_id", "ts"]), values))
def test_random_maps_only_ever_raise_decode_error(m):
    try:
        c = VelCmd.decode(msgpack.packb(m, use_bin_type=True))
    except DecodeError:
        return
    assert all(math.isfinite(x) for x in (c.vx, c.vy, c.va))


def test_sim_requests_keys_and_set_pose_validation():
    assert keys.sim_request_key("r0", "set_pose") == "rhbl/r0/sim/req/set_pose"
    assert keys.sim_request_key("r1", "get_pose") == "rhbl/r1/sim/req/get_pose"
    with pytest.raises(ValueError):
        keys.sim_request_key("r0", "a/b")
    m = SetPose.decode(SetPose((1.0, 2.0, 0.5), reset_odom=False).encode())
    assert m.pose == (1.0, 2.0, 0.5) and m.reset_odom is False
    assert SetPose.decode(msgpack.packb({"v": 1, "pose": [1, 2, 3]})).reset_odom is True
    for bad in ([1, 2], [1, 2, 3, 4], [float("nan"), 0, 0], [0, float("inf"), 0], ["1", 0, 0],
                [True, 0, 0], None):
        with pytest.raises(DecodeError, match="pose"):
            SetPose.decode(msgpack.packb({"v": 1, "pose": bad}))
    with pytest.raises(DecodeError, match="reset_odom"):
        SetPose.decode(msgpack.packb({"v": 1, "pose": [1, 2, 3], "reset_odom": "yes"}))
    p = SimPose.decode(SimPose((1.0, 2.0, 3.0), odom=(0.0, 0.0, 0.0), ts=4.5).encode())
    assert (p.pose, p.odom, p.ts) == ((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), 4.5)


def test_label_identity_resend_and_ack_messages():
    from protocol.messages import LabeledScan, LearnerAck

    assert keys.teacher_labeled_key("r0") == "rhbl/r0/teacher/labeled"
    assert keys.learner_ack_key("r0") == "rhbl/r0/learner/ack"
    act = TeacherAction(scan_id=4, action="fwd", ts=0.4, executed="rot-left", origin="ab12",
                        seq=7)
    assert _roundtrip(act) == act
    old = TeacherAction(scan_id=4, action="fwd")  # without identity: as before
    assert _roundtrip(old) == old and "origin" not in msgpack.unpackb(old.encode())
    r = np.linspace(0.1, 8, 360).astype(np.float32)
    lab = _roundtrip(LabeledScan.of(act, r, 1.25))
    assert np.array_equal(lab.ranges, r) and lab.yaw == 1.25
    assert lab.action_message() == act
    ack = LearnerAck(origin="ab12", upto=10, seqs=(12, 15), ts=3.0)
    assert _roundtrip(ack) == ack
    base = {"v": 1, "scan_id": 4, "action": "fwd"}
    for bad, field in [({"seq": 3}, "'origin'"), ({"origin": "a"}, "'seq'"),
                       ({"origin": "", "seq": 1}, "'origin'"),
                       ({"origin": "a" * 65, "seq": 1}, "'origin'"),
                       ({"origin": 5, "seq": 1}, "'origin'"),
                       ({"origin": "a", "seq": -1}, "'seq'"),
                       ({"origin": "a", "seq": 1.5}, "'seq'")]:
        with pytest.raises(DecodeError, match=field):
            TeacherAction.decode(msgpack.packb({**base, **bad}))
    good = msgpack.unpackb(lab.encode())
    for bad, field in [({"origin": None}, "'origin'"), ({"seq": None}, "'seq'"),
                       ({"ranges": b"\x00\x00\xc0\x7f"}, "'ranges'"),  # NaN
                       ({"ranges": b"abc"}, "'ranges'"), ({"yaw": math.inf}, "'yaw'"),
                       ({"yaw": None}, "'yaw'")]:
        with pytest.raises(DecodeError, match=field):
            LabeledScan.decode(msgpack.packb({**good, **bad}))
    ok = {"v": 1, "origin": "a", "upto": 3, "seqs": [5]}
    for bad, field in [({"upto": -1}, "'upto'"), ({"seqs": [2]}, "'seqs'"),
                       ({"seqs": "x"}, "'seqs'"), ({"seqs": list(range(3, 5000))}, "'seqs'"),
                       ({"seqs": [True]}, "'seqs'"), ({"origin": ""}, "'origin'")]:
        with pytest.raises(DecodeError, match=field):
            LearnerAck.decode(msgpack.packb({**ok, **bad}))


def test_withdrawal_message_and_the_ack_of_withdrawals():
    from protocol.messages import MAX_WITHDRAWN, LearnerAck, Withdrawal

    assert keys.teacher_withdraw_key("r0") == "rhbl/r0/teacher/withdraw"
    assert keys.parse("rhbl/r0/teacher/withdraw").kind == "withdraw"
    w = Withdrawal(origin="ab12", id=3, first=100, upto=150, ts=2.0, reason="undo 5 s")
    assert _roundtrip(w) == w
    ack = LearnerAck(origin="ab12", upto=150, withdrawn=4)
    assert _roundtrip(ack) == ack
    assert LearnerAck.decode(LearnerAck(origin="a", upto=1).encode()).withdrawn is None
    ok = msgpack.unpackb(w.encode())
    for bad, field in [({"first": 150}, "'first', 'upto'"),  # an empty range
                       ({"upto": 99}, "'first', 'upto'"),
                       ({"upto": 100 + MAX_WITHDRAWN + 1}, "'first', 'upto'"),
                       ({"first": -1}, "'first'"), ({"id": -2}, "'id'"),
                       ({"origin": ""}, "'origin'"), ({"origin": "x" * 65}, "'origin'"),
                       ({"reason": 5}, "'reason'"), ({"id": None}, "'id'")]:
        with pytest.raises(DecodeError, match=field):
            Withdrawal.decode(msgpack.packb({**ok, **bad}))
    with pytest.raises(DecodeError, match="'withdrawn'"):
        LearnerAck.decode(msgpack.packb({"v": 1, "origin": "a", "upto": 1, "withdrawn": -1}))


def _same_scan(a: Scan, b: Scan) -> bool:
    return (a.ranges.dtype == b.ranges.dtype == np.float32 and a.ranges.flags.writeable
            and np.array_equal(a.ranges, b.ranges)
            and {k: v for k, v in vars(a).items() if k != "ranges"}
            == {k: v for k, v in vars(b).items() if k != "ranges"})


scan_numbers = st.one_of(st.floats(), st.integers(-(2**63), 2**64 - 1), st.booleans(), st.none(),
                         st.text(max_size=2))
scan_ranges = st.one_of(
    st.lists(st.floats(width=32), min_size=0, max_size=12).map(
        lambda v: np.array(v, "<f4").tobytes()),
    st.binary(max_size=9), st.lists(st.floats(), max_size=3))


@settings(max_examples=400, deadline=None)
@given(st.fixed_dictionaries(
    {k: scan_numbers for k in ("ts", "min_angle", "max_angle", "resolution", "max_range")}
    | {"id": scan_numbers, "ranges": scan_ranges,
       "pose": st.one_of(st.lists(scan_numbers, min_size=2, max_size=4), scan_numbers)},
    optional={"truth": st.one_of(st.lists(scan_numbers, min_size=3, max_size=3), st.none(),
                                 scan_numbers)}))
def test_scan_checked_in_bulk_accepts_and_gives_what_the_field_checks_do(m):
    """The bulk path (a scan as senders write it) is only a shortcut: what it accepts the
    field-by-field checks accept with the same values; what it declines they judge (refusing
    with the field's name, or accepting, e.g. an integer time)."""
    from protocol.messages import _scan_in_bulk

    bulk = _scan_in_bulk(Scan, m)
    try:
        checked = Scan._from_map_by_field(m)
    except DecodeError:
        assert bulk is None
        with pytest.raises(DecodeError):
            Scan.decode(msgpack.packb({"v": PROTOCOL_VERSION, **m}, use_bin_type=True))
        return
    assert bulk is None or _same_scan(bulk, checked)
    assert _same_scan(Scan.decode(msgpack.packb({"v": PROTOCOL_VERSION, **m},
                                                use_bin_type=True)), checked)


def test_a_sent_scan_takes_the_bulk_path():
    from protocol.messages import _scan_in_bulk

    r = np.linspace(0.1, 8, 360).astype(np.float32)
    for truth in (None, (1.0, 2.0, 0.5)):
        m = msgpack.unpackb(Scan(ts=2.5, id=7, ranges=r, pose=(1.0, 2.0, 3.0),
                                 truth=truth).encode())
        bulk = _scan_in_bulk(Scan, m)
        assert bulk is not None and _same_scan(bulk, Scan._from_map_by_field(m))
    for bad in ([np.nan], [np.inf], [1.0, -np.inf]):
        m["ranges"] = np.array(bad, "<f4").tobytes()
        assert _scan_in_bulk(Scan, m) is None
        with pytest.raises(DecodeError, match="'ranges': expected finite"):
            Scan.from_map(m)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=40), st.floats(allow_nan=False, allow_infinity=False),
       st.floats(allow_nan=False, allow_infinity=False), st.booleans(),
       st.none() | st.integers(0, 2**64 - 1), st.none() | st.floats(allow_nan=False))
def test_velcmd_packer_gives_the_encoded_command_byte_for_byte(source, vx, va, state, sid, ts):
    from protocol.messages import VelCmdPacker

    data = VelCmdPacker(source).pack(vx, va, state, sid, ts)
    cmd = VelCmd(vx=vx, va=va, state=state, source=source, scan_id=sid, ts=ts)
    assert data == cmd.encode()
    if ts is None or math.isfinite(ts):
        assert VelCmd.decode(data) == cmd


def test_a_goal_behaviours_label_says_the_goal_pursued_reached_and_seen():
    """A label of a behaviour with goals carries the beacon pursued, the one reached at that
    scan and what the fiducial finder saw; a resend carries them too; bad ones are refused by
    name; a label without them is the same bytes as before."""
    from protocol.messages import FiducialItem, LabeledScan

    act = TeacherAction(scan_id=4, action="fwd", origin="ab12", seq=7, goal=2, reached=1,
                        seen=(FiducialItem(1, 0.5, 0.1), FiducialItem(2, 4.0, -0.3)))
    assert _roundtrip(act) == act
    lab = _roundtrip(LabeledScan.of(act, np.ones(5, np.float32), 0.5))
    assert (lab.goal, lab.reached, lab.seen) == (2, 1, act.seen)
    assert lab.action_message() == act
    plain = TeacherAction(scan_id=4, action="fwd")
    assert set(msgpack.unpackb(plain.encode())) == {"v", "scan_id", "action", "source", "ts"}
    good = msgpack.unpackb(act.encode())
    for bad, field in [({"goal": -1}, "'goal'"), ({"reached": "x"}, "'reached'"),
                       ({"seen": [{"id": 1, "range": math.nan, "bearing": 0.0}]}, r"'seen\[0\]\.range'"),
                       ({"seen": [{"id": 1}]}, "'seen"), ({"seen": 5}, "'seen'"),
                       ({"seen": [{"id": 1, "range": 1.0, "bearing": 0.0}] * 300}, "'seen'")]:
        with pytest.raises(DecodeError, match=field):
            TeacherAction.decode(msgpack.packb({**good, **bad}))
