"""Recordings: every message of a run kept as an MCAP file (docs/recording.md).

The format (written with the official ``mcap`` package's writer, read back record by record by
``RecordingReader``: streamed, with limits on record and chunk sizes, CRCs checked, a file cut
anywhere read up to its last complete chunk):

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
import io
import json
import logging
import os
import struct
import time
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import msgpack
from mcap.opcode import Opcode

from process import files
from protocol.codec import PROTOCOL_VERSION
from protocol.decoding import Decoder
from protocol.messages import CARRIES, kind_of

__all__ = [
    "CHUNK_SECONDS",
    "KINDS",
    "MAX_CHUNK",
    "MAX_RECORD",
    "RecordedMessage",
    "RecordingError",
    "RecordingReader",
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
        try:  # a regular file or a new one only (process.files), its folder made
            fd = files.open_output(self.path, overwrite=overwrite)
        except files.FileRuleError as exc:
            raise RecordingError(str(exc)) from None
        except OSError as exc:  # FileExistsError included
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
            ts = getattr(msg, "ts", None) if kind in ("state", "scan", "fiducial", "driver",
                                                      "cmd", "label") else None
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
# a reader never allocates more than these for one record: a hostile file claiming a chunk of
# a GiB (a few KiB of zstd) is refused instead of inflated. Our writer's chunks hold 256 KiB.
MAX_RECORD = 64 * 2**20  # bytes of one record as stored (a chunk's compressed data included)
MAX_CHUNK = 64 * 2**20  # bytes of one chunk once decompressed


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


_MESSAGE = struct.Struct("<HIQQ")  # a message record's fixed fields


class _Damaged(Exception):
    """A complete record that does not parse (the file is damaged there)."""


class _Cut(Exception):
    """The file ends inside a record (it was cut there)."""


class RecordingReader:
    """An MCAP recording read record by record (memory: one chunk at most, ``MAX_CHUNK``),
    checked as it goes: the data section's and each chunk's CRCs, a limit on every record's
    and chunk's size, every length against what the file holds.

    ``messages(viewer=False)`` yields the messages in file order (= the order received). A file
    cut anywhere (a recorder killed, a full disk, a partial copy) yields every message before
    the cut that sits in a complete record (chunk), then ends with a line in ``notes``; anything
    else wrong is ``RecordingError`` naming the file, the byte and what is wrong. ``metadata``:
    the metadata records read so far (name -> map). The file must be a regular file
    (``process.files``: a FIFO or a device is refused, never read)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.notes: list[str] = []
        self.metadata: dict[str, dict[str, str]] = {}
        self.messages_read = 0
        self._schemas: dict[int, str] = {}
        # id -> (topic, encoding, schema, kind, robot): classified once per channel
        self._channels: dict[int, tuple[str, str, str, str, str]] = {}
        self._complete = False  # the data section's end was read: every message is

    def messages(self, viewer: bool = False) -> Iterator[RecordedMessage]:
        try:
            f = files.open_input(self.path, "recording")
        except files.FileRuleError as exc:
            raise RecordingError(str(exc)) from None
        with f:
            size = os.fstat(f.fileno()).st_size
            if size == 0:
                raise RecordingError(f"{self.path} is empty: not an MCAP recording")
            if f.read(len(MAGIC)) != MAGIC:
                raise RecordingError(f"{self.path} is not an MCAP recording (it does not begin "
                                     f"with MCAP's magic bytes)")
            try:
                yield from self._records(f, size, viewer)
            except _Cut as cut:
                if self._complete:
                    line = (f"{self.path} is cut {cut}, after its data: all its "
                            f"{self.messages_read} messages were read (a partial copy?)")
                else:
                    line = (f"{self.path} ends after {self.messages_read} messages, cut {cut}: "
                            f"it was not closed (a recorder killed, a full disk, a partial "
                            f"copy?); read up to its last complete chunk")
                log.warning("%s", line)
                self.notes.append(line)

    # -- records --
    def _records(self, f, size: int, viewer: bool) -> Iterator[RecordedMessage]:
        import zlib

        crc = zlib.crc32(MAGIC)
        data_end = False
        while True:
            at = f.tell()
            header = f.read(9)
            if len(header) < 9:
                where = "at its end" if not header else f"in a record header at byte {at}"
                raise _Cut(f"{where} (no footer)" if not header else where)
            opcode, length = struct.unpack("<BQ", header)
            if length > MAX_RECORD:
                raise RecordingError(f"{self.path}: the record at byte {at} claims {length} "
                                     f"bytes, more than the {MAX_RECORD} a recording's record "
                                     f"may hold: refused (damaged or crafted)")
            if at + 9 + length > size:
                raise _Cut(f"inside the record that begins at byte {at} ({length} bytes, "
                           f"{size - at - 9} left)")
            body = f.read(length)
            if opcode == Opcode.DATA_END:
                data_end = self._complete = True
                self._check_data_crc(body, crc, at)
            elif not data_end:
                crc = zlib.crc32(body, zlib.crc32(header, crc))
            try:
                if opcode == Opcode.FOOTER:
                    if f.read(len(MAGIC)) != MAGIC:
                        raise _Cut("in its closing magic bytes (after the footer)")
                    return
                if opcode == Opcode.CHUNK and not data_end:
                    yield from self._chunk(body, at, viewer)
                elif not data_end or opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                    yield from self._record(opcode, body, at, viewer)
            except _Damaged as exc:
                raise RecordingError(f"{self.path} is damaged after {self.messages_read} "
                                     f"messages (in the record at byte {at}): {exc}") from None

    def _check_data_crc(self, body: bytes, crc: int, at: int) -> None:
        if len(body) >= 4:
            (expected,) = struct.unpack_from("<I", body)
            if expected not in (0, crc):
                raise RecordingError(f"{self.path} is damaged: the data section's CRC "
                                     f"({crc:#010x}) is not the one its end record holds "
                                     f"({expected:#010x}, byte {at})")

    def _record(self, opcode: int, body: bytes, at: int, viewer: bool
                ) -> Iterator[RecordedMessage]:
        """One record outside or inside a chunk; the message it is, if any."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Metadata, Schema

        stream = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == Opcode.SCHEMA:
                sc = Schema.read(stream)
                self._schemas[sc.id] = sc.name
            elif opcode == Opcode.CHANNEL:
                ch = Channel.read(stream)
                if ch.schema_id and ch.schema_id not in self._schemas:
                    raise _Damaged(f"channel {ch.id} names schema {ch.schema_id}, never "
                                   f"declared")
                kind, robot = (classify(ch.topic) if ch.message_encoding == ENCODING
                               else ("viewer", ""))
                self._channels[ch.id] = (ch.topic, ch.message_encoding,
                                         self._schemas.get(ch.schema_id, ""), kind, robot)
            elif opcode == Opcode.METADATA:
                md = Metadata.read(stream)
                self.metadata[md.name] = dict(md.metadata)
            elif opcode == Opcode.MESSAGE:
                m = self._message(body, 0, len(body), viewer)
                if m is not None:
                    yield m
        except _Damaged:
            raise
        except Exception as exc:  # noqa: BLE001 - struct.error, EndOfFile, UnicodeDecodeError
            raise _Damaged(f"{type(exc).__name__}: {exc}") from None

    def _message(self, buf: bytes, start: int, end: int, viewer: bool
                 ) -> RecordedMessage | None:
        """The message record in ``buf[start:end]`` (channel u16, sequence u32, log and publish
        times u64, then the payload); None for a viewer message when not ``viewer``."""
        if end - start < _MESSAGE.size:
            raise _Damaged(f"a message record of {end - start} bytes (at least "
                           f"{_MESSAGE.size})")
        channel, _seq, log_time, publish_time = _MESSAGE.unpack_from(buf, start)
        ch = self._channels.get(channel)
        if ch is None:
            raise _Damaged(f"a message on channel {channel}, never declared")
        topic, encoding, schema, kind, robot = ch
        if kind == "viewer" and not viewer:
            return None
        self.messages_read += 1
        return RecordedMessage(topic, kind, robot, buf[start + _MESSAGE.size:end], log_time,
                               publish_time, encoding, schema)

    def _chunk(self, body: bytes, at: int, viewer: bool) -> Iterator[RecordedMessage]:
        """The records of a chunk, decompressed at most to its declared size (``MAX_CHUNK``)."""
        import zlib

        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk

        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
        except Exception as exc:  # noqa: BLE001 - struct.error, EndOfFile, UnicodeDecodeError
            raise _Damaged(f"{type(exc).__name__}: {exc}") from None
        if chunk.uncompressed_size > MAX_CHUNK:
            raise RecordingError(f"{self.path}: the chunk at byte {at} claims "
                                 f"{chunk.uncompressed_size} bytes uncompressed, more than the "
                                 f"{MAX_CHUNK} a recording's chunk may hold: refused (a "
                                 f"decompression bomb, or damaged)")
        data = _inflate(chunk)
        if len(data) > chunk.uncompressed_size:
            raise _Damaged(f"its chunk decompresses to more than the "
                           f"{chunk.uncompressed_size} bytes it declares")
        if len(data) < chunk.uncompressed_size:
            raise _Damaged(f"its chunk decompresses to {len(data)} bytes, not the "
                           f"{chunk.uncompressed_size} it declares")
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            raise _Damaged("its chunk's CRC does not match its contents")
        pos = 0
        while pos < len(data):
            if pos + 9 > len(data):
                raise _Damaged(f"a record header cut at byte {pos} of its chunk")
            opcode, length = struct.unpack_from("<BQ", data, pos)
            if pos + 9 + length > len(data):
                raise _Damaged(f"a record of {length} bytes at byte {pos} of its chunk runs "
                               f"past the chunk's end")
            if opcode == Opcode.MESSAGE:  # the common case, without copying the record
                m = self._message(data, pos + 9, pos + 9 + length, viewer)
                if m is not None:
                    yield m
            else:
                yield from self._record(opcode, data[pos + 9:pos + 9 + length], at, viewer)
            pos += 9 + length


def _inflate(chunk) -> bytes:
    """A chunk's data decompressed: at most one byte more than it declares (so a chunk that
    holds more than it says is caught, never inflated whole)."""
    cap = chunk.uncompressed_size + 1
    try:
        if chunk.compression == "":
            return chunk.data
        if chunk.compression == "zstd":
            import zstandard

            reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data))
            out = bytearray()
            while len(out) < cap:
                part = reader.read(min(cap - len(out), 1 << 20))
                if not part:
                    break
                out += part
            return bytes(out)
        if chunk.compression == "lz4":
            import lz4.frame

            return lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=cap)
    except Exception as exc:  # noqa: BLE001 - zstd/lz4 errors: corrupt compressed data
        raise _Damaged(f"its chunk does not decompress ({type(exc).__name__}: {exc})") from None
    raise _Damaged(f"its chunk is compressed with {chunk.compression!r} (zstd, lz4 or none)")


def read_recording(path: str | os.PathLike, viewer: bool = False,
                   notes: list | None = None) -> Iterator[RecordedMessage]:
    """The messages of a recording in file order (= the order they were received), streamed
    (``RecordingReader``). A file that was not closed (a recorder killed) or was cut anywhere
    is read up to its last complete chunk; ``notes`` gets a line saying so. Raises
    ``RecordingError`` naming the file for anything else."""
    reader = RecordingReader(path)
    try:
        yield from reader.messages(viewer)
    finally:
        if notes is not None:
            notes.extend(reader.notes)
