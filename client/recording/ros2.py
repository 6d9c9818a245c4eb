"""``rhbl record --ros2``: the robots' data as ROS 2 messages in an MCAP file of the ROS 2 profile
(what ``ros2 bag`` and Foxglove's ROS 2 view open; docs/ros2.md, "Recordings").

A sink of the bus tap (``client.recording.tap.Sink``): each robot's scans and states become the
messages ``rhbl ros2`` publishes for them (``protocol.ros2.convert.RobotFeed``: ``/<r>/scan``,
``/<r>/odom``, ``/tf`` and, from the first robot seen, ``/clock``), written with
``protocol.ros2.recording.Ros2McapWriter``; log and publish time = when the tap received the
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

from client.recording.mcap_file import (
    CHUNK_SECONDS,
    RecordingError,
    not_created,
    why_not_written,
)
from client.ros2 import Ros2Options
from protocol.decoding import Decoder
from protocol.messages import Scan, State
from protocol.ros2.convert import Frames, RobotFeed
from protocol.ros2.recording import Ros2McapWriter

__all__ = ["Ros2Recording"]

log = logging.getLogger(__name__)


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
