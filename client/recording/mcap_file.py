"""Recordings: every message of a run kept as an MCAP file (docs/recording.md).

The format (written with the official ``mcap`` package, read back with ``mcap.reader``):

- one channel per bus key (topic = the zenoh key, e.g. ``rhbl/r0/laser/0/data/scan``),
  ``message_encoding`` ``msgpack``; each message is the original payload, bit for bit. A schema
  per message type (encoding ``jsonschema``, name ``rhbl.v<protocol version>.<Type>``, e.g.
  ``rhbl.v1.Scan``) describes the map and names the protocol version.
- log time = when the message was received (ns since the Unix epoch; in-process runs, which have
  no bus: the run's start plus the sim time), publish time = the message's own sim time stamp
  ``ts`` (messages without one: the robot's latest sim time).
- liveliness tokens (``rhbl/alive/<role>/<id>``) appear as their key's channel with a
  ``rhbl.v1.Liveliness`` message ``{v, key, alive}`` when they appear and disappear; the sim
  world (``sim/req/get_world``'s ``WorldInfo`` reply) on ``rhbl/<robot>/sim/req/get_world``.
- viewer channels beside them (``client.recording.foxglove_schemas``: laser, pose, path, world scene, status in
  Foxglove's well-known schemas), so Foxglove and Lichtblick show a recording without a plugin.
- chunked (zstd), indexed, with a summary; a chunk is closed at least every ``chunk_seconds``
  (1 s), so a recorder killed with SIGKILL leaves every message up to its last chunk readable.
- a metadata record ``rhbl`` (protocol version, what recorded it, when).

    with RecordingWriter("run.mcap") as w:
        w.write(key, payload, recv_ns)
    for m in read_recording("run.mcap"):         # RecordedMessage(key, kind, robot, data, ...)
        ...
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import json
import logging
import os
import time
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import msgpack

from protocol.codec import PROTOCOL_VERSION
from protocol.decoding import Decoder
from protocol.messages import CARRIES, kind_of

__all__ = [
    "CHUNK_SECONDS",
    "KINDS",
    "RecordedMessage",
    "RecordingError",
    "RecordingWriter",
    "classify",
    "decode",
    "not_created",
    "read_recording",
    "why_not_written",
]

log = logging.getLogger(__name__)

CHUNK_SECONDS = 1.0  # a chunk is closed (written, readable) at least this often
CHUNK_SIZE = 256 * 1024  # ... or when it holds this many uncompressed bytes
ENCODING = "msgpack"
MAGIC = b"\x89MCAP0\r\n"  # how every MCAP file begins (the MCAP specification)

# kind -> message class: what each key carries (``protocol.messages.CARRIES``, whose
# descriptions give the schemas), plus the recording's own kinds: "alive" (a liveliness token's
# change, the small map ``{v, key, alive}``) and "other" (a key of ours we do not know: kept,
# undecoded)
KINDS: dict[str, type | None] = {**CARRIES, "alive": None, "other": None}
_OWN = {
    "alive": ("Liveliness", "a liveliness token appeared (alive) or disappeared",
              {"key": {"type": "string"}, "alive": {"type": "boolean"}}, ["key", "alive"]),
    "other": ("Message", "a message on a key this version does not know", {}, []),
}


def schema_name(kind: str) -> str:
    cls = KINDS[kind]
    return cls.schema_name() if cls is not None else f"rhbl.v{PROTOCOL_VERSION}.{_OWN[kind][0]}"


def _schema_data(kind: str) -> bytes:
    cls = KINDS[kind]
    if cls is not None:
        return json.dumps(cls.json_schema()).encode()
    _name, what, fields, required = _OWN[kind]
    return json.dumps({
        "title": schema_name(kind),
        "description": f"rhbl recording (protocol version {PROTOCOL_VERSION}): {what}",
        "type": "object", "properties": {"v": {"const": PROTOCOL_VERSION}, **fields},
        "required": ["v", *required]}).encode()


class RecordingError(Exception):
    """A recording that cannot be written or read: the message names the file and the reason."""


def classify(key: str) -> tuple[str, str]:
    """(kind, robot) of a bus key (``protocol.messages.kind_of``); robot "" for keys of no
    robot."""
    return kind_of(key)


def decode(kind: str, data: bytes):
    """The protocol message of a payload (``protocol.messages``), or raise its DecodeError;
    for ``alive``: the map ``{v, key, alive}``."""
    cls = KINDS[kind]
    if cls is None:
        return msgpack.unpackb(data)
    return cls.decode(data)


def alive_payload(key: str, alive: bool) -> bytes:
    return msgpack.packb({"v": PROTOCOL_VERSION, "key": str(key), "alive": bool(alive)})


# ---- writing ------------------------------------------------------------------------------
def why_not_written(exc: OSError) -> str:
    """Why a recording could not be written, in words (a full disk, a quota, a size limit)."""
    return {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is used up",
            errno.EFBIG: "the file reached its size limit"}.get(exc.errno,
                                                                exc.strerror or str(exc))


def not_created(path: Path, exc: OSError) -> RecordingError:
    """Why the recording ``path`` could not be created, for the user (one line)."""
    if isinstance(exc, FileExistsError):
        return RecordingError(f"{path} exists: choose another file or pass --overwrite "
                              f"(a recording is never replaced silently)")
    return RecordingError(f"cannot create the recording {path}: {exc.strerror or exc}")


class RecordingWriter:
    """An MCAP file being written: raw bus messages plus viewer channels.

    Not thread-safe: one thread writes (``client.recording.tap.BusTap`` funnels the zenoh
    callbacks into one).
    Any error writing (a full disk) stops the writer with ``RecordingError``; the file is cut
    back to the end of its last complete chunk, which standard readers read.
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False, viewer: bool = True,
                 recorder: str = "rhbl record", chunk_seconds: float = CHUNK_SECONDS,
                 chunk_size: int = CHUNK_SIZE, metadata: dict | None = None):
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.chunk_seconds = float(chunk_seconds)
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
        try:
            if self.path.parent and not self.path.parent.exists():
                self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            raise not_created(self.path, exc) from exc
        self._file = _Out(fd)
        self._writer = Writer(self._file, chunk_size=chunk_size,
                              compression=CompressionType.ZSTD)
        self.failed: RecordingError | None = None
        self.closed = False
        self.messages = 0
        self.counts: dict[str, int] = defaultdict(int)
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sim: dict[str, float] = {}  # robot -> latest sim time
        self._good = 0  # file offset after the last complete chunk
        self._good_messages = 0
        self._last_flush = time.monotonic()
        self.decoder = Decoder(log, level=logging.DEBUG)
        self.feed = None
        if viewer:
            from client.recording.foxglove_schemas import ViewerFeed

            self.feed = ViewerFeed()
        self._guard(self._start, recorder, metadata or {})

    def _start(self, recorder: str, metadata: dict) -> None:
        self._writer.start(profile="", library=f"rhbl protocol v{PROTOCOL_VERSION} (python mcap)")
        meta = {"protocol_version": str(PROTOCOL_VERSION), "recorder": recorder,
                "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                "message_encoding": ENCODING, "viewer_channels": str(self.feed is not None)}
        meta.update({str(k): str(v) for k, v in metadata.items()})
        self._writer.add_metadata("rhbl", meta)
        self._writer.flush()
        self._good = self._file.tell()

    # -- errors --
    def _guard(self, fn, *a):
        if self.failed is not None:
            raise self.failed
        try:
            return fn(*a)
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: OSError):
        why = why_not_written(exc)
        with contextlib.suppress(OSError):
            os.ftruncate(self._file.fd, self._good)
        self._file.close()
        self.failed = RecordingError(
            f"cannot write the recording {self.path}: {why} ({exc}). Recording stopped; the file "
            f"keeps the {self._good_messages} bus messages up to its last complete chunk "
            f"({self._good} bytes), readable by MCAP readers (it has no summary: readers scan it)")
        self.closed = True
        raise self.failed from exc

    # -- channels --
    def _channel(self, topic: str, sname: str, sencoding: str, sdata: bytes,
                 encoding: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(sname)
            if sid is None:
                sid = self._schemas[sname] = self._writer.register_schema(sname, sencoding, sdata)
            cid = self._channels[topic] = self._writer.register_channel(topic, encoding, sid)
        return cid

    # -- messages --
    def write(self, key: str, data: bytes, recv_ns: int, kind: str | None = None,
              robot: str | None = None, sim_time: float | None = None) -> None:
        """Record one bus message (the payload as received) and its viewer messages."""
        self._guard(self._write, key, bytes(data), int(recv_ns), kind, robot, sim_time)

    def _write(self, key, data, recv_ns, kind, robot, sim_time):
        if kind is None:
            kind, robot = classify(key)
        msg = None  # a malformed message is still recorded, raw (and counted)
        if KINDS.get(kind) is not None:
            msg = self.decoder.decode(KINDS[kind], data, where=key)
        if sim_time is None:
            ts = getattr(msg, "ts", None) if kind in ("state", "scan", "driver", "cmd",
                                                      "label") else None
            if ts is not None:
                sim_time = float(ts)
                if kind in ("state", "scan"):
                    self._sim[robot] = sim_time
            else:
                sim_time = self._sim.get(robot, 0.0)
        cid = self._channels.get(key)
        if cid is None:
            cid = self._channel(key, schema_name(kind), "jsonschema", _schema_data(kind),
                                ENCODING)
        self._writer.add_message(cid, log_time=recv_ns, data=data,
                                 publish_time=max(0, int(round(sim_time * 1e9))),
                                 sequence=self.counts[key] + 1)
        self.counts[key] += 1
        self.messages += 1
        if self.feed is not None and msg is not None:
            try:
                vms = self.feed.update(kind, robot, msg, recv_ns)
            except Exception as exc:  # noqa: BLE001 - a viewer glitch never stops a recording
                log.debug("viewer conversion of %s failed: %s", key, exc)
                vms = []
            for vm in vms:
                vc = self._channels.get(vm.topic) or self._channel(vm.topic, vm.schema_name, vm.schema_encoding, vm.schema_data,
                                   vm.encoding)
                self._writer.add_message(vc, log_time=vm.time_ns, data=vm.data,
                                         publish_time=max(0, int(round(sim_time * 1e9))))
        self.maybe_flush()

    def write_alive(self, key: str, alive: bool, recv_ns: int) -> None:
        self.write(key, alive_payload(key, alive), recv_ns, "alive", classify(key)[1])

    def maybe_flush(self, now: float | None = None) -> None:
        """Close the chunk in progress when it is ``chunk_seconds`` old (called by ``write``;
        call it when idle too)."""
        now = time.monotonic() if now is None else now
        if now - self._last_flush >= self.chunk_seconds:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and hand it to the kernel (SIGKILL-safe from then)."""
        if self.closed:
            return

        def go():
            self._writer.flush()
            self._good = self._file.tell()
            self._good_messages = self.messages

        self._guard(go)
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the file (summary, indexes, footer) and close it."""
        if self.closed:
            return

        def go():
            self._writer.finish()
            os.fsync(self._file.fd)
            self._file.close()

        self._guard(go)
        self.closed = True

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Out:
    """The file the MCAP writer writes to, unbuffered: every write the writer makes (a whole
    chunk, a record group) is in the kernel when it returns, so a SIGKILL loses nothing the
    writer wrote, and after a failed write nothing buffered here can land in the file later."""

    def __init__(self, fd: int):
        self.fd = fd
        self.pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)
            self.pos += n
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def close(self) -> None:
        if self.fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self.fd)
            self.fd = -1


# ---- reading ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecordedMessage:
    key: str  # the topic: the bus key (or a viewer topic)
    kind: str  # classify(key)[0]; "viewer" for viewer channels
    robot: str
    data: bytes
    log_time: int  # ns: receive time
    publish_time: int  # ns: sim time
    encoding: str
    schema: str

    @property
    def sim_time(self) -> float:
        return self.publish_time / 1e9

    def message(self):
        return decode(self.kind, self.data)


def read_recording(path: str | os.PathLike, viewer: bool = False,
                   notes: list | None = None) -> Iterator[RecordedMessage]:
    """The messages of a recording in file order (= the order they were received). A file
    that was not closed (a recorder killed) is read up to its last complete chunk; ``notes``
    gets a line saying so. Raises ``RecordingError`` naming the file for anything else."""
    from mcap.reader import NonSeekingReader

    path = Path(path)
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise RecordingError(f"cannot open the recording {path}: {exc.strerror or exc}") from exc
    n = 0
    with f:
        if os.fstat(f.fileno()).st_size == 0:
            raise RecordingError(f"{path} is empty: not an MCAP recording")
        if f.read(len(MAGIC)) != MAGIC:
            raise RecordingError(f"{path} is not an MCAP recording (it does not begin with "
                                 f"MCAP's magic bytes)")
        f.seek(0)
        try:
            reader = NonSeekingReader(f, validate_crcs=True)
            for schema, channel, m in reader.iter_messages(log_time_order=False):
                if channel.message_encoding != ENCODING:
                    if not viewer:
                        continue
                    kind, robot = "viewer", ""
                else:
                    kind, robot = classify(channel.topic)
                n += 1
                yield RecordedMessage(channel.topic, kind, robot, m.data, m.log_time,
                                      m.publish_time, channel.message_encoding,
                                      schema.name if schema else "")
        except Exception as exc:  # noqa: BLE001 - McapError, zstd/lz4 errors, EOF, ...
            name = type(exc).__name__
            if "InvalidMagic" in name:
                raise RecordingError(f"{path} is not an MCAP recording ({name}: {exc})") from exc
            if "EndOfFile" in name or isinstance(exc, EOFError):
                line = (f"{path} ends after {n} messages without its summary: it was not closed "
                        f"(a recorder killed, a full disk?); read up to its last complete chunk")
                log.warning("%s", line)
                if notes is not None:
                    notes.append(line)
                return
            raise RecordingError(f"{path} is damaged after {n} messages (at byte {f.tell()}): "
                                 f"{name}: {exc}") from exc
