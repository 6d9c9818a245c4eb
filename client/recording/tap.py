"""The bus tap: one zenoh subscription to the robots' keys feeding every sink that wants the bus.

    tap = BusTap(session, [writer, feed], robots=["r0"])    # every robot's keys by default
    ...
    tap.sync()                 # everything received so far has reached the sinks
    errors = tap.close()       # stop subscribing, deliver what arrived, close the sinks

The subscribers' callbacks only timestamp and queue the payload (a few microseconds: a slow sink
never stalls the session); one thread hands each message to every sink, in the order received,
and gives them ``maybe_flush`` when the bus is quiet. Liveliness tokens come as ``write_alive``;
with ``world`` the world of each robot seen (``sim/req/get_world``) is fetched once and handed
over like a message on that key.

A sink (``Sink``): ``client.recording.mcap_file.RecordingWriter`` (``rhbl record``, ``--record``),
``client.recording.bridge.FoxgloveSink`` (``rhbl foxglove``), ``lab.episode.EpisodeCollector``
(``rhbl demo``'s episodes). A sink that raises ``RecordingError`` is left out from then on (its
error kept: ``errors``); the others go on.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from typing import Protocol

from client.recording.mcap_file import RecordingError, classify
from protocol import keys

__all__ = ["BACKLOG_WARN", "BusTap", "Sink"]

log = logging.getLogger(__name__)

BACKLOG_WARN = 2000  # received messages waiting to be delivered beyond which it says so
_TOKENS = keys.every_token().removesuffix("**")  # a key under it is a liveliness token's


class Sink(Protocol):
    def write(self, key: str, data: bytes, recv_ns: int, kind: str | None = None,
              robot: str | None = None, sim_time: float | None = None) -> None:
        """One bus message, its payload as received, ``recv_ns`` ns since the epoch."""

    def write_alive(self, key: str, alive: bool, recv_ns: int) -> None:
        """A liveliness token appeared (``alive``) or disappeared."""

    def maybe_flush(self, now: float | None = None) -> None:
        """Called when the bus is quiet (at least every 0.2 s): time-based work."""

    def close(self) -> None:
        """The end: finish what the sink keeps."""


class BusTap:
    """Feeds a session's view of the robots' keys (``robots`` None: every robot) to ``sinks``."""

    def __init__(self, session, sinks: Sink | list[Sink], robots: list[str] | None = None,
                 world: bool = True):
        self.session = session
        self.sinks: list[Sink] = list(sinks) if isinstance(sinks, list | tuple) else [sinks]
        self.robots = list(robots) if robots else None
        self.errors: dict[int, RecordingError] = {}  # id(sink) -> the error that stopped it
        self.seen_robots: set[str] = set()
        self._world = world
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self.max_backlog = 0
        self._warned = 0.0
        exprs = [keys.robot_keys(r) for r in self.robots] if self.robots else [keys.robot_keys()]
        self._subs = [session.declare_subscriber(e, self._on_sample) for e in exprs]
        self._subs.append(session.liveliness().declare_subscriber(
            keys.every_token(), self._on_alive, history=True))
        self._thread = threading.Thread(target=self._loop, name="bus-tap", daemon=True)
        self._thread.start()

    # -- zenoh threads --
    def _on_sample(self, sample) -> None:
        key = str(sample.key_expr)
        if key.startswith(_TOKENS):
            return
        self._q.put((key, sample.payload.to_bytes(), time.time_ns(), None))

    def _on_alive(self, sample) -> None:
        import zenoh

        self._q.put((str(sample.key_expr), None, time.time_ns(),
                     sample.kind == zenoh.SampleKind.PUT))

    def _fetch_world(self, robot: str) -> None:
        key = keys.sim_request_key(robot, "get_world")
        try:
            for reply in self.session.get(key, timeout=2.0):
                if reply.ok is not None:
                    self._q.put((key, reply.ok.payload.to_bytes(), time.time_ns(), None))
                    return
        except Exception as exc:  # noqa: BLE001 - not a simulator, or the session closing
            log.debug("no world for robot %s: %s", robot, exc)

    # -- the delivering thread --
    def _loop(self) -> None:
        while True:
            try:
                item = self._q.get(timeout=0.2)
            except queue.Empty:
                if self._stop.is_set():
                    return
                self._each(lambda s: s.maybe_flush())
                continue
            if isinstance(item, threading.Event):  # sync(): everything before it delivered
                item.set()
                continue
            self._deliver(*item)
            n = self._q.qsize()
            self.max_backlog = max(self.max_backlog, n)
            if n > BACKLOG_WARN and time.monotonic() - self._warned >= 10.0:
                self._warned = time.monotonic()
                log.warning("the bus tap falls behind: %d messages wait to be delivered (all "
                            "kept, in memory)", n)

    def _deliver(self, key: str, data: bytes | None, t: int, alive: bool | None) -> None:
        if data is None:
            self._each(lambda s: s.write_alive(key, alive, t))
            return
        kind, robot = classify(key)
        if self._world and robot and kind != "world" and robot not in self.seen_robots:
            self.seen_robots.add(robot)
            threading.Thread(target=self._fetch_world, args=(robot,), daemon=True).start()
        self._each(lambda s: s.write(key, data, t, kind, robot))

    def _each(self, call) -> None:
        for sink in self.sinks:
            if id(sink) in self.errors:
                continue
            try:
                call(sink)
            except RecordingError as exc:
                self.errors[id(sink)] = exc
                log.error("%s", exc)

    # -- the owner --
    def sync(self, timeout: float = 5.0) -> bool:
        """Wait until every message received so far reached the sinks (False after
        ``timeout`` s)."""
        done = threading.Event()
        self._q.put(done)
        return done.wait(timeout)

    def error(self, sink: Sink) -> RecordingError | None:
        """What stopped ``sink``, if anything did."""
        return self.errors.get(id(sink))

    @property
    def failed(self) -> bool:
        """Every sink stopped on an error: nothing is fed any more."""
        return len(self.errors) == len(self.sinks)

    def close(self) -> dict[int, RecordingError]:
        """Stop subscribing, deliver what arrived, close every sink; the errors
        (``error(sink)`` says a sink's)."""
        for s in self._subs:
            with contextlib.suppress(Exception):
                s.undeclare()
        self._stop.set()
        self._thread.join()
        self._each(lambda s: s.close())
        return self.errors
