"""ROS 2 recordings: MCAP files of the ROS 2 profile (what ``ros2 bag`` and Foxglove's ROS 2
view open; docs/ros2.md, "Recordings"), and ``rhbl record --ros2``'s sink that writes them.

**The file** (``Ros2McapWriter``)::

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

**The sink** (``Ros2Recording``): A sink of the bus tap (``client.recording.tap.Sink``): each robot's scans and states become the
messages ``rhbl ros2`` publishes for them (``protocol.ros2.convert.RobotFeed``: ``/<r>/scan``,
``/<r>/odom``, ``/tf`` and, from the first robot seen, ``/clock``), written with
``Ros2McapWriter``; log and publish time = when the tap received the
message (ns since the Unix epoch; the header stamps carry the sim time). Commands, labels and
the learner's messages have no ROS 2 counterpart here and are left out; a robot whose name is
not a ROS 2 name is left out and counted.
"""

from __future__ import annotations

import logging
import os
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from mcap import __version__ as _mcap_version
from mcap.writer import Writer
from rosbags.rosbag2.metadata import dump_qos_v8

from client.recording.mcap_file import (
    CHUNK_SECONDS,
    RecordingError,
    not_created,
    why_not_written,
)
from client.ros2.nodes import Ros2Options
from process import files
from protocol.decoding import Decoder
from protocol.messages import Scan, State
from protocol.ros2 import cdr
from protocol.ros2.convert import Frames, RobotFeed
from protocol.ros2.graph import Topic
from protocol.ros2.qos import adapt

__all__ = ["PROFILE", "SCHEMA_ENCODING", "Ros2McapWriter", "Ros2Recording"]

log = logging.getLogger(__name__)

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
            # a regular file or a new one only (process.files): never a device or FIFO
            self._file = os.fdopen(files.open_output(output, overwrite=overwrite), "wb")
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


class Ros2Recording:
    """Writes the robots' scans and states to ``path`` as ROS 2 messages. ``scan_time(robot)``
    gives the seconds between that robot's scans (asked once per robot, at its first scan: 1 /
    its laser's rate, 0 when unknown). A failure to write (a full disk) is a
    ``RecordingError``: the tap then stops feeding this sink."""

    def __init__(self, path: str | os.PathLike, options: Ros2Options,
                 scan_time: Callable[[str], float], *, overwrite: bool = False,
                 chunk_seconds: float = CHUNK_SECONDS):
        self.path = Path(path)
        self.options, self.scan_time = options, scan_time
        self.chunk_seconds = float(chunk_seconds)
        try:
            self.writer = Ros2McapWriter(self.path, overwrite=overwrite)
        except files.FileRuleError as exc:
            raise RecordingError(str(exc)) from None
        except OSError as exc:
            raise not_created(self.path, exc) from exc
        self.feeds: dict[str, RobotFeed | None] = {}  # None: a robot without a ROS 2 name
        self.messages = 0
        self.counts: dict[str, int] = defaultdict(int)  # per ROS 2 topic
        self.decoder = Decoder(log)
        self.closed = False
        self._last_flush = time.monotonic()

    def _feed(self, robot: str) -> RobotFeed | None:
        if robot not in self.feeds:
            try:
                topics = self.options.topics(robot)
            except ValueError as exc:
                log.warning("not recording robot %r: %s", robot, exc)
                self.feeds[robot] = None
                return None
            feed = RobotFeed(topics, Frames.for_robot(robot), self.scan_time(robot),
                             clock=not any(self.feeds.values()))  # the first robot's
            for topic in feed.published:
                self._guard(self.writer.add_topic, topic)
            self.feeds[robot] = feed
        return self.feeds[robot]

    def write(self, key: str, data: bytes, recv_ns: int, kind: str | None = None,
              robot: str | None = None, sim_time: float | None = None) -> None:
        if kind not in ("scan", "state") or not robot:
            return
        msg = self.decoder.decode(Scan if kind == "scan" else State, data, where=key)
        feed = None if msg is None else self._feed(robot)
        if feed is None:
            return
        for topic, ros in (feed.of_scan(msg) if kind == "scan" else feed.of_state(msg)):
            self._guard(self.writer.write_message, topic.name, ros, recv_ns, recv_ns)
            self.counts[topic.name] += 1
            self.messages += 1
        self.maybe_flush()

    def write_alive(self, key: str, alive: bool, recv_ns: int) -> None:
        pass  # liveliness has no place in a ROS 2 bag

    def maybe_flush(self, now: float | None = None) -> None:
        """Close the chunk in progress every ``chunk_seconds`` (what a SIGKILL can lose)."""
        now = time.monotonic() if now is None else now
        if not self.closed and now - self._last_flush >= self.chunk_seconds:
            self._guard(self.writer.flush)
            self._last_flush = now

    @property
    def skipped(self) -> list[str]:
        """Robots left out: their names are not ROS 2 names."""
        return sorted(r for r, f in self.feeds.items() if f is None)

    def close(self) -> None:
        if not self.closed:
            self._guard(self.writer.close)
            self.closed = True

    def _guard(self, fn, *args) -> None:
        try:
            fn(*args)
        except OSError as exc:
            self.closed = True
            raise RecordingError(f"cannot write the recording {self.path}: "
                                 f"{why_not_written(exc)} ({exc}); "
                                 f"recording stopped after {self.messages} ROS 2 messages") \
                from exc
