"""The MCAP format: every kind of key gets the schema derived from its message (decisions, acks
and resent labels were "rhbl.v1.Message"), written once per type; the reader and inspect say
what the file holds."""

from __future__ import annotations

import json

import numpy as np
from mcap.reader import make_reader

from client.recording.inspect import format_summary, recording_summary
from client.recording.mcap_file import RecordingWriter, read_recording
from protocol import keys
from protocol import messages as m

R = np.full(360, 2.0, dtype=np.float32)
BUS = [
    (keys.scan_key("r0"), m.Scan(ts=1.0, id=1, ranges=R)),
    (keys.state_key("r0"), m.State(ts=1.0, seq=1, pos=(0, 0, 0))),
    (keys.cmd_vel_key("r0", source="controller"), m.VelCmd(vx=0.3, source="controller",
                                                           scan_id=1, ts=1.0)),
    (keys.controller_decision_key("r0"), m.Decision(scan_id=1, action="fwd")),
    (keys.learner_ack_key("r0"), m.LearnerAck(origin="o", upto=3)),
    (keys.teacher_labeled_key("r0"), m.LabeledScan(scan_id=1, action="fwd", origin="o", seq=0,
                                                   ranges=R)),
    (keys.teacher_action_key("r0"), m.TeacherAction(scan_id=1, action="fwd", origin="o", seq=0)),
    (keys.learner_notice_key("r0"), m.TreeNotice(seq=1, nodes=3, height=1)),
]


def test_every_key_gets_its_messages_schema(tmp_path):
    out = tmp_path / "r.mcap"
    with RecordingWriter(out, viewer=False) as w:
        for k, (key, msg) in enumerate(BUS):
            w.write(key, msg.encode(), 1_000_000_000 + k)
        w.write("rhbl/r0/mystery/thing", b"\x80", 2_000_000_000)
    with open(out, "rb") as f:
        reader = make_reader(f)
        got = {c.topic: reader.get_summary().schemas[c.schema_id]
               for c in reader.get_summary().channels.values()}
    for key, msg in BUS:
        schema = got[key]
        assert schema.name == type(msg).schema_name() and schema.encoding == "jsonschema", key
        assert json.loads(schema.data) == type(msg).json_schema()
    assert got["rhbl/r0/mystery/thing"].name == "rhbl.v1.Message"
    kinds = {r.key: r.kind for r in read_recording(out)}
    assert kinds[keys.controller_decision_key("r0")] == "decision"
    assert kinds[keys.learner_ack_key("r0")] == "ack"
    text = format_summary(recording_summary(out))
    assert "rhbl.v1.Decision" in text and "rhbl.v1.LearnerAck" in text
    assert "rhbl.v1.LabeledScan" in text and "teacher labels: 1 (fwd 1)" in text


def test_a_file_that_is_no_recording_is_named(tmp_path):
    import pytest

    from client.recording.mcap_file import RecordingError

    bad = tmp_path / "tree.rhbl"
    bad.write_bytes(b"\x82\xa1v\x01")  # four bytes of msgpack
    with pytest.raises(RecordingError, match="tree.rhbl is not an MCAP recording"):
        list(read_recording(bad))


def test_a_decision_with_a_goal_is_recorded_with_it(tmp_path):
    """A controller driving a tree with goals: its decisions keep the goal pursued and why the
    last one changed in a recording, and the recording's schema describes both."""
    out = tmp_path / "g.mcap"
    d = m.Decision(scan_id=4, action="fwd", goal=m.DecisionGoal(1, 2, 2),
                   goal_why="goal 1/2 (beacon 1) done at 2.5 s: completion tree: sphere 3")
    with RecordingWriter(out, viewer=False) as w:
        w.write(keys.controller_decision_key("r0"), d.encode(), 1_000_000_000)
    (rec,) = [r for r in read_recording(out) if r.kind == "decision"]
    assert m.Decision.decode(rec.data) == d
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    (schema,) = [s for s in summary.schemas.values() if s.name == m.Decision.schema_name()]
    props = json.loads(schema.data)["properties"]
    assert {"goal", "goal_why"} <= set(props) and "beacon" in props["goal"]["properties"]
