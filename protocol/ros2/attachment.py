"""The attachment rmw_zenoh puts on every sample: sequence number, source timestamp, GID.

Current layout (rmw_zenoh 0.2.4+ Jazzy, 0.1.2+ Humble, 0.6.0+ Kilted/Rolling; 33 bytes, the
zenoh-ext serialisation of ``(int64, int64, std::array<uint8_t, 16>)``)::

    offset 0   8 bytes  sequence number, int64 little-endian (per publisher, the first is 1)
    offset 8   8 bytes  source timestamp, int64 little-endian, ns since the Unix epoch
    offset 16  1 byte   0x10, the GID's length (a LEB128 varint)
    offset 17 16 bytes  the publisher's GID (protocol.ros2.graph: XXH3-128 of its token key)

Older releases on zenoh 1.x (0.2.0-0.2.3 Jazzy, 0.1.0-0.1.1 Humble, 0.3.0-0.5.0 Rolling) put
a key before each value: the zenoh-ext strings ``sequence_number``, ``source_timestamp`` and
``source_gid`` (a varint length and UTF-8). :meth:`Attachment.decode` reads both layouts;
:meth:`Attachment.encode` writes the current one, which those older releases refuse. A receiver
should not need the attachment to use a sample's payload.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from protocol.codec import DecodeError

__all__ = ["GID_SIZE", "Attachment"]

GID_SIZE = 16  # bytes (RMW_GID_STORAGE_SIZE since ROS 2 Iron)
_INT64 = struct.Struct("<q")
_KEYS = ("sequence_number", "source_timestamp", "source_gid")
_WHAT = "rmw_zenoh attachment"


class _Reader:
    """zenoh-ext's deserialiser, for the three kinds of values an attachment holds."""

    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def _take(self, n: int, what: str) -> bytes:
        if self.pos + n > len(self.data):
            raise DecodeError(f"{_WHAT}: {what}: needs {n} bytes at offset {self.pos}, "
                              f"the attachment has {len(self.data)}")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def int64(self, what: str) -> int:
        return _INT64.unpack(self._take(8, what))[0]

    def length(self, what: str) -> int:
        value = shift = 0
        while True:
            byte = self._take(1, what)[0]
            value |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return value
            shift += 7
            if shift > 63:
                raise DecodeError(f"{_WHAT}: {what}: a length longer than 64 bits")

    def sequence(self, what: str) -> bytes:
        n = self.length(what)
        if n > len(self.data):
            raise DecodeError(f"{_WHAT}: {what}: length {n} exceeds the attachment")
        return self._take(n, what)

    def done(self) -> None:
        if self.pos != len(self.data):
            raise DecodeError(f"{_WHAT}: {len(self.data) - self.pos} bytes left over after "
                              f"the GID (of {len(self.data)})")


@dataclass(frozen=True)
class Attachment:
    """``sequence_number`` (int64), ``source_timestamp`` (int64 ns since the Unix epoch, the
    publisher's wall clock) and the publisher's 16-byte ``gid``."""

    sequence_number: int
    source_timestamp: int
    gid: bytes

    def __post_init__(self):
        for name in ("sequence_number", "source_timestamp"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not -2**63 <= v < 2**63:
                raise ValueError(f"{name} must be an int64, got {v!r}")
        if not isinstance(self.gid, bytes) or len(self.gid) != GID_SIZE:
            raise ValueError(f"gid must be {GID_SIZE} bytes, got {self.gid!r}")

    def encode(self) -> bytes:
        return (_INT64.pack(self.sequence_number) + _INT64.pack(self.source_timestamp)
                + bytes([GID_SIZE]) + self.gid)

    @classmethod
    def decode(cls, data: Any) -> Attachment:
        """An attachment in either layout (bytes, or a zenoh ``ZBytes``); anything else raises
        :class:`DecodeError` saying where it went wrong."""
        if hasattr(data, "to_bytes"):
            data = data.to_bytes()
        if not isinstance(data, bytes | bytearray | memoryview):
            raise DecodeError(f"{_WHAT}: expected bytes, got {type(data).__name__}")
        r = _Reader(bytes(data))
        keyed = data[:1] == bytes([len(_KEYS[0])]) and data[1:1 + len(_KEYS[0])] == _KEYS[0].encode()
        values = []
        for key in _KEYS:
            if keyed:
                got = r.sequence(f"key {key!r}")
                if got != key.encode():
                    raise DecodeError(f"{_WHAT}: expected the key {key!r}, got {got[:40]!r}")
            values.append(r.sequence(key) if key == "source_gid" else r.int64(key))
        r.done()
        seq, stamp, gid = values
        if len(gid) != GID_SIZE:
            raise DecodeError(f"{_WHAT}: source_gid: expected {GID_SIZE} bytes, got {len(gid)}")
        return cls(seq, stamp, gid)
