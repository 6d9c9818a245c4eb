"""The fiducial interface in recordings and viewers: the raw channel with its schema, the beacons
in the world scene and what a robot sees on its own viewer channel (``/<robot>/fiducials``),
the same conversion the Foxglove bridge serves."""

from __future__ import annotations

import json

import numpy as np
from mcap.reader import make_reader

import server
from client.recording.bridge import DRAWN
from client.recording.foxglove_schemas import ViewerFeed, viewer_topics
from client.recording.mcap_file import RecordingWriter, read_recording
from protocol import keys
from protocol import messages as m
from server.node import world_info
from server.world import load_world

R = np.full(360, 2.0, dtype=np.float32)
SEEN = m.Fiducial(ts=1.0, seq=1, items=(m.FiducialItem(2, 3.25, 0.25),), pose=(1, 2, 0.5))


def test_a_recording_holds_the_fiducial_channel_and_its_viewer_scene(tmp_path):
    info = world_info(load_world(server.world_path("beacons-room")))
    out = tmp_path / "r.mcap"
    with RecordingWriter(out) as w:
        w.write(keys.sim_request_key("r0", "get_world"), info.encode(), 1_000_000_000)
        w.write(keys.fiducial_key("r0"), SEEN.encode(), 1_100_000_000)
        w.write(keys.scan_key("r0"), m.Scan(ts=1.0, id=1, ranges=R).encode(), 1_200_000_000)
        w.write(keys.fiducial_key("r0"), m.Fiducial(ts=1.1, seq=2).encode(), 1_300_000_000)
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        viewer = {c.topic: [] for c in summary.channels.values()}
        for _schema, channel, message in reader.iter_messages():
            viewer[channel.topic].append(message)
    raw = schemas[keys.fiducial_key("r0")]
    assert raw.name == "rhbl.v1.Fiducial" and json.loads(raw.data) == m.Fiducial.json_schema()
    records = [r for r in read_recording(out) if r.kind == "fiducial"]
    assert [m.Fiducial.decode(r.data) for r in records] == [SEEN, m.Fiducial(ts=1.1, seq=2)]
    assert schemas["/r0/fiducials"].name == "foxglove.SceneUpdate"
    first, second = viewer["/r0/fiducials"]
    assert b"fiducials:r0" in first.data and b"2 3.25 m +14 deg" in first.data
    assert b"3.25" not in second.data  # nothing in view: the entity without primitives
    world = viewer["/world"][0].data
    assert b"beacon:1" in world and b"beacon:2" in world


def test_the_bridge_draws_fiducials_and_names_the_topic():
    assert "fiducial" in DRAWN and "/r0/fiducials" in viewer_topics("r0")
    vms = ViewerFeed().update("fiducial", "r0", SEEN, 5)
    assert [vm.topic for vm in vms] == ["/r0/fiducials"]


def test_a_replay_plays_the_fiducial_channel_too(tmp_path):
    from client.recording.replay import plan_replay

    out = tmp_path / "r.mcap"
    with RecordingWriter(out, viewer=False) as w:
        w.write(keys.fiducial_key("r0"), SEEN.encode(), 1_000_000_000)
        w.write(keys.scan_key("r0"), m.Scan(ts=1.0, id=1, ranges=R).encode(), 1_000_000_001)
    plan = plan_replay(out, None, 5.0)
    assert plan.keys == {keys.fiducial_key("r0"), keys.scan_key("r0")}
