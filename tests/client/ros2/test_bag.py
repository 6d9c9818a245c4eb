"""client.ros2.bag (Ros2McapWriter): an MCAP file in the ROS 2 profile, read back by readers nobody here
wrote: mcap-ros2-support (decodes with the file's own schemas) and rosbags' rosbag2 reader (the
checks rosbag2's MCAP storage makes: profile, schemas, QoS metadata, type hashes)."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from client.ros2.bag import Ros2McapWriter
from protocol.messages import Scan, State
from protocol.ros2 import cdr
from protocol.ros2.convert import (
    Frames,
    laserscan_from_scan,
    odometry_from_state,
    tf_from_state,
)
from protocol.ros2.graph import RobotTopics, Topic
from protocol.ros2.qos import DEFAULT_QOS, adapt

FRAMES = Frames.for_robot("r0")
_R0 = RobotTopics.of("r0")
TOPICS = [_R0.scan, _R0.odom, _R0.tf]
T0 = 1_733_000_000_000_000_000  # ns since the Unix epoch


def _record(path, ticks=5):
    with Ros2McapWriter(path) as out:
        for t in TOPICS:
            out.add_topic(t)
        out.add_topic(TOPICS[0])  # again: kept
        for k in range(ticks):
            ts = 0.1 * k
            state = State(ts=ts, seq=k, pos=(1.0 + 0.05 * k, 2.0, 0.1 * k), vel=(0.5, 0.0, 1.0))
            scan = Scan(ts=ts, id=k, ranges=np.full(360, 1.0 + k, dtype=np.float32))
            log = T0 + int(ts * 1e9)
            out.write_message("/r0/odom", odometry_from_state(state, FRAMES), log)
            out.write_message("/tf", tf_from_state(state, FRAMES), log)
            out.write("/r0/scan", cdr.serialize(laserscan_from_scan(scan, FRAMES.laser, 0.1)),
                      log, publish_time_ns=int(ts * 1e9))


def test_the_file_is_in_the_ros2_profile(tmp_path):
    path = tmp_path / "run.mcap"
    _record(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert sorted((s.name, s.encoding) for s in summary.schemas.values()) == sorted(
            (t.typename, "ros2msg") for t in TOPICS)
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {t.name for t in TOPICS}
        for t in TOPICS:
            c = channels[t.name]
            assert c.message_encoding == "cdr"
            assert c.metadata["topic_type_hash"] == cdr.type_hash(t.typename)
        assert summary.statistics.message_count == 15 and summary.chunk_indexes


def test_mcap_ros2_decodes_what_was_written(tmp_path):
    path = tmp_path / "run.mcap"
    _record(path)
    got = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append((message, decoded))
    assert {k: len(v) for k, v in got.items()} == {"/r0/scan": 5, "/r0/odom": 5, "/tf": 5}
    scans = got["/r0/scan"]
    assert [list(d.ranges[:2]) for _, d in scans] == [[1.0 + k] * 2 for k in range(5)]
    assert [m.log_time - T0 for m, _ in scans] == [int(0.1 * k * 1e9) for k in range(5)]
    assert [m.publish_time for m, _ in scans] == [int(0.1 * k * 1e9) for k in range(5)]
    odom = got["/r0/odom"][3][1]
    assert odom.pose.pose.position.x == pytest.approx(1.15) and odom.child_frame_id == "r0/base_link"
    assert got["/tf"][4][1].transforms[0].header.frame_id == "r0/odom"


def test_rosbags_reads_it_as_a_rosbag2_file(tmp_path):
    path = tmp_path / "run.mcap"
    _record(path)
    with Reader(path) as bag:
        conns = {c.topic: c for c in bag.connections}
        assert set(conns) == {t.name for t in TOPICS}
        for t in TOPICS:
            c = conns[t.name]
            assert c.msgtype == t.typename and c.msgcount == 5
            assert c.ext.offered_qos_profiles == [adapt(t.qos)]
            assert c.ext.serialization_format == "cdr"
        n = 0
        for conn, timestamp, data in bag.messages():
            msg = cdr.deserialize(data, conn.msgtype)
            assert timestamp >= T0
            n += 1
        assert n == 15 and msg.__msgtype__ in {t.typename for t in TOPICS}


def test_misuse_is_refused(tmp_path):
    path = tmp_path / "run.mcap"
    _record(path, ticks=1)
    with pytest.raises(FileExistsError):
        Ros2McapWriter(path)
    with Ros2McapWriter(path, overwrite=True) as out:
        out.add_topic(TOPICS[0])
        with pytest.raises(ValueError, match="not added"):
            out.write("/r0/odom", b"", T0)
        with pytest.raises(ValueError, match="records sensor_msgs/msg/LaserScan, got a "
                                             "nav_msgs/msg/Odometry"):
            out.write_message("/r0/scan", odometry_from_state(State(0.0, 0, (0, 0, 0)), FRAMES),
                              T0)
        with pytest.raises(ValueError, match="is recorded as sensor_msgs/msg/LaserScan"):
            out.add_topic(Topic("/r0/scan", cdr.ODOMETRY, DEFAULT_QOS))
        with pytest.raises(ValueError, match="integer ns >= 0"):
            out.write("/r0/scan", b"", -1)
    with pytest.raises(ValueError, match="closed"):
        out.add_topic(TOPICS[1])
