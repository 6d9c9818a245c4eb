"""MCAP files in the ROS 2 profile: what ``ros2 bag`` and Foxglove's ROS 2 view read.

    with Ros2McapWriter("run.mcap") as out:
        out.add_topic(Topic("/r0/scan", LASER_SCAN, SENSOR_DATA_QOS))
        out.write_message("/r0/scan", laserscan_from_scan(scan, "r0/base_link"), log_time_ns)
        out.write("/r0/scan", cdr_bytes, log_time_ns, publish_time_ns)   # bytes already CDR
        out.flush()                      # close the chunk in progress (a killed writer keeps it)

The layout rosbag2's MCAP storage writes and reads: header profile ``ros2``; one schema per
message type, named ``package/msg/Name``, encoding ``ros2msg`` (the type's .msg text with its
dependencies, :func:`protocol.ros2.cdr.msgdef`); one channel per topic, named by the topic,
message encoding ``cdr``, metadata ``offered_qos_profiles`` (the YAML list of the publisher's
profile as rmw_zenoh runs it, rosbag2's version-8 form with enum numbers) and
``topic_type_hash`` (RIHS01); messages in CDR, log time = when recorded, publish time = when
sent (ns since the Unix epoch, or sim time: the caller says). Chunked and zstd-compressed with
a summary and message indexes, like the rest of rhbl's recordings.
"""

from __future__ import annotations

import os
from typing import IO, Any

from mcap import __version__ as _mcap_version
from mcap.writer import Writer
from rosbags.rosbag2.metadata import dump_qos_v8

from protocol.ros2 import cdr
from protocol.ros2.graph import Topic
from protocol.ros2.qos import adapt

__all__ = ["PROFILE", "SCHEMA_ENCODING", "Ros2McapWriter"]

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"


class Ros2McapWriter:
    """Writes one MCAP file in the ROS 2 profile to ``output`` (a path, refused if it exists
    unless ``overwrite``, or a binary stream the caller owns). Register each topic with
    :meth:`add_topic` before writing to it; :meth:`close` (or the ``with`` block) writes the
    summary that makes the file seekable."""

    def __init__(self, output: str | os.PathLike | IO[bytes], *, overwrite: bool = False):
        if isinstance(output, str | os.PathLike):
            self._file = open(output, "wb" if overwrite else "xb")  # noqa: SIM115 - closed in close()
            stream = self._file
        else:
            self._file, stream = None, output
        self._writer = Writer(stream)
        self._writer.start(profile=PROFILE, library=f"rhbl protocol.ros2 (mcap {_mcap_version})")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._sequence: dict[str, int] = {}
        self._closed = False

    def add_topic(self, topic: Topic) -> None:
        """A channel for ``topic`` (and a schema for its type, once per type). A topic already
        added with the same type is kept; with another type it is refused."""
        self._check_open()
        known = self._channels.get(topic.name)
        if known is not None:
            if known[1] != topic.typename:
                raise ValueError(f"topic {topic.name} is recorded as {known[1]}, "
                                 f"not {topic.typename}")
            return
        sid = self._schemas.get(topic.typename)
        if sid is None:
            sid = self._schemas[topic.typename] = self._writer.register_schema(
                topic.typename, SCHEMA_ENCODING, cdr.msgdef(topic.typename).encode())
        metadata = {"offered_qos_profiles": dump_qos_v8([adapt(topic.qos)]),
                    "topic_type_hash": topic.type_hash}
        cid = self._writer.register_channel(topic.name, MESSAGE_ENCODING, sid, metadata)
        self._channels[topic.name] = (cid, topic.typename)
        self._sequence[topic.name] = 0

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """One CDR message on ``topic`` (added before), logged at ``log_time_ns``."""
        self._check_open()
        if topic not in self._channels:
            raise ValueError(f"topic {topic!r} was not added (add_topic) before writing to it")
        times = (log_time_ns, log_time_ns if publish_time_ns is None else publish_time_ns)
        for t in times:
            if isinstance(t, bool) or not isinstance(t, int) or not 0 <= t < 2**64:
                raise ValueError(f"MCAP times are integer ns >= 0, got {t!r}")
        self._sequence[topic] += 1
        self._writer.add_message(self._channels[topic][0], log_time=times[0], data=bytes(data),
                                 publish_time=times[1], sequence=self._sequence[topic])

    def write_message(self, topic: str, msg: Any, log_time_ns: int,
                      publish_time_ns: int | None = None) -> None:
        """A rosbags message on ``topic``, serialised to CDR; its type must be the topic's."""
        known = self._channels.get(topic)
        typename = getattr(msg, "__msgtype__", None)
        if known is not None and typename != known[1]:
            raise ValueError(f"topic {topic} records {known[1]}, got a {typename}")
        self.write(topic, cdr.serialize(msg), log_time_ns, publish_time_ns)

    def flush(self) -> None:
        """Close the chunk in progress and write it out (readable from then on, even if the
        process is killed before :meth:`close`)."""
        self._check_open()
        self._writer.flush()
        if self._file is not None:
            self._file.flush()

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError("the ROS 2 MCAP writer is closed")

    def close(self) -> None:
        """Write the summary and close the file (if the writer opened it). Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            if self._file is not None:
                self._file.close()

    def __enter__(self) -> Ros2McapWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
