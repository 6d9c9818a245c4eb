"""Each message's map is described once (``FIELDS``, ``REQUIRED``); the recordings' JSON schemas
are derived from it. Held here against what ``to_map`` writes and ``from_map`` demands, so the
description cannot drift from the code (the recording's label schema once lacked ``origin``
and ``seq``)."""

from __future__ import annotations

import jsonschema
import msgpack
import numpy as np
import pytest

from protocol import messages as m
from protocol.codec import DecodeError

R = np.full(4, 2.5, dtype=np.float32)
# every message with every optional field set, and with none
FULL = [
    m.State(ts=1.0, seq=2, pos=(1, 2, 0.1), vel=(0.2, 0, 0.1), stall=True, driver="teacher",
            truth=(1, 2, 0.1)),
    m.Scan(ts=1.0, id=3, ranges=R, pose=(1, 2, 0.1), truth=(1, 2, 0.1)),
    m.Fiducial(ts=1.0, seq=3, items=(m.FiducialItem(1, 2.5, -0.5), m.FiducialItem(0, 7.9, 1.5)),
               pose=(1, 2, 0.1), truth=(1, 2, 0.1)),
    m.VelCmd(vx=0.3, va=0.1, source="controller", scan_id=3, ts=1.0),
    m.DriverState(source="teacher", ts=1.0, priority=2),
    m.TeacherAction(scan_id=3, action="fwd", ts=1.0, executed="rot-left", origin="o1", seq=4,
                    goal=2, reached=1, seen=(m.FiducialItem(1, 0.5, 0.1),)),
    m.LabeledScan(scan_id=3, action="fwd", origin="o1", seq=4, ranges=R, yaw=0.1, ts=1.0,
                  executed="fwd", goal=2, reached=1, seen=(m.FiducialItem(1, 0.5, 0.1),)),
    m.LearnerAck(origin="o1", upto=4, seqs=(6, 7), ts=1.0, withdrawn=2, refused=1),
    m.Withdrawal(origin="o1", id=0, first=10, upto=60, ts=1.0, reason="undo 5 s"),
    m.TreeNotice(seq=1, nodes=7, height=3, vectors=12, snapshot_id="l:12", ts=1.0),
    m.Decision(scan_id=3, action="fwd", path=((0, 0, 1.5, "fwd"),), ts=1.0, snapshot_id="l:1",
               nodes=7, executed="rot-left", looping=True, goal=m.DecisionGoal(1, 2, 7),
               goal_why="goal 1/2 (beacon 3) done at 4.5 s"),
    m.Geometry(pose=(0, 0, 0), size=(0.5, 0.4), radius=0.25),
    m.LaserConfig(min_angle=-1.5, max_angle=1.5, resolution=0.01, max_range=8.0, count=360),
    m.FiducialGeometry(pose=(0, 0, 0), size=(0.1, 0.1), min_range=0.0, max_range=8.0,
                       max_range_id=5.0, fov=3.14, rate=10.0),
    m.SetOdom(pose=(0, 0, 0)),
    m.SetPose(pose=(1, 1, 0), reset_odom=False),
    m.SimPose(pose=(1, 1, 0), odom=(0, 0, 0), ts=1.0),
    m.WorldInfo(name="room", task="maze", walls=((0, 0, 1, 0),), goal=(1, 1, 0.5),
                starts=((1, 1, 0),), beacons=(m.BeaconInfo(1, (1.0, 2.0), "#dc2828", 0.2),)),
    m.MotorPower(state=True),
    m.Ack(info="ok"),
    m.Nack(reason="no"),
]
MINIMAL = [
    m.State(ts=1.0, seq=2, pos=(1, 2, 0.1)),
    m.Scan(ts=1.0, id=3, ranges=R),
    m.Fiducial(ts=1.0, seq=3),
    m.VelCmd(),
    m.TeacherAction(scan_id=3, action="fwd"),
    m.LearnerAck(origin="o1", upto=0),
    m.TreeNotice(seq=1, nodes=7, height=3),
    m.Decision(scan_id=3, action="fwd"),
    m.Geometry(pose=(0, 0, 0), size=(0.5, 0.4)),
    m.WorldInfo(name="room", task="maze"),
    m.Ack(),
]
CLASSES = sorted({type(x) for x in FULL}, key=lambda c: c.__name__)


def _wire(msg) -> dict:
    return msgpack.unpackb(msg.encode(), raw=False)


def test_every_message_class_is_held_here():
    every = {c for c in vars(m).values()
             if isinstance(c, type) and issubclass(c, m._Message) and c is not m._Message}
    assert every == set(CLASSES)


@pytest.mark.parametrize("msg", FULL, ids=lambda x: type(x).__name__)
def test_the_description_names_exactly_the_fields_written(msg):
    """With every optional field set, the map holds exactly ``FIELDS`` (and ``v``)."""
    assert set(_wire(msg)) == {"v", *type(msg).FIELDS}


@pytest.mark.parametrize("msg", FULL + MINIMAL, ids=lambda x: type(x).__name__)
def test_what_is_written_validates_against_the_derived_schema(msg):
    schema = type(msg).json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(_wire(msg), schema)
    assert set(type(msg).REQUIRED) <= set(_wire(msg))


@pytest.mark.parametrize("msg", FULL, ids=lambda x: type(x).__name__)
def test_each_required_field_is_required_by_the_decoder(msg):
    cls = type(msg)
    for name in cls.REQUIRED:
        wire = _wire(msg)
        del wire[name]
        with pytest.raises(DecodeError, match=f"'{name}'"):
            cls.decode(msgpack.packb(wire, use_bin_type=True))


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_the_optional_fields_are_optional_to_the_decoder(cls):
    full = next(x for x in FULL if type(x) is cls)
    wire = {k: v for k, v in _wire(full).items() if k == "v" or k in cls.REQUIRED}
    cls.decode(msgpack.packb(wire, use_bin_type=True))  # no DecodeError


def test_a_schema_names_the_version_and_the_type():
    s = m.TeacherAction.json_schema()
    assert s["title"] == "rhbl.v1.TeacherAction" and s["properties"]["v"] == {"const": 1}
    assert {"origin", "seq"} <= set(s["properties"])  # what the hand-written one lacked
    assert m.DriverState.schema_name() == "rhbl.v1.Driver"  # the recordings' name of it
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"v": 1, "scan_id": -1, "action": "fwd"}, s)


@pytest.mark.parametrize("key,kind", [
    ("rhbl/r0/laser/0/data/scan", "scan"), ("rhbl/r0/fiducial/0/data/fiducials", "fiducial"),
    ("rhbl/r0/position2d/0/cmd/vel/teacher", "cmd"),
    ("rhbl/r0/learner/ack", "ack"), ("rhbl/r0/controller/decision", "decision"),
    ("rhbl/r0/teacher/labeled", "labeled"), ("rhbl/r0/teacher/withdraw", "withdraw"),
    ("rhbl/r0/sim/req/get_world", "world"),
    ("rhbl/r0/sim/req/get_pose", "other"), ("rhbl/r0/learner/snapshot", "other"),
    ("rhbl/alive/learner/r0-12", "alive")])
def test_each_key_kind_carries_its_message(key, kind):
    assert m.kind_of(key) == (kind, "r0")
