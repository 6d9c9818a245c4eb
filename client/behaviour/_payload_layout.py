"""What the payload kernel (``client.behaviour._payload_kernels``) reads and fills, numba-free:
the scan map's keys in the order ``Scan.to_map`` writes them, the slots of its outputs, and the
checksum of the kernel's source (the kernel compiled ahead of time,
``client.behaviour._payload_aot``, built by ``setup.py``, is used only while it was compiled
from this checkout's files)."""

from __future__ import annotations

import zlib
from pathlib import Path

__all__ = ["HEAD", "INTS", "KEYS", "TEMPLATE", "source_hash"]

# the map's keys in the order Scan.to_map writes them; truth, the last, is optional
KEYS = ("v", "ts", "id", "min_angle", "max_angle", "resolution", "max_range", "ranges", "pose",
        "truth")
# the head (float64) the kernel fills: the scan's numbers (the truth's when it has one)
TS, MIN_ANGLE, MAX_ANGLE, RESOLUTION, MAX_RANGE, X, Y, YAW, TRUTH = range(9)
HEAD = TRUTH + 3
# the ints (int64) it fills: the scan's id, where its ranges start in the payload, its beams,
# its fields (9, or 10 with the truth)
ID, OFFSET, BEAMS, FIELDS = range(4)
INTS = 4

SOURCES = ("_payload_kernels.py", "_payload_layout.py")


def _template() -> tuple[int, ...]:
    """The keys of :data:`KEYS` as msgpack writes them (fixstr), one after another."""
    out = bytearray()
    for key in KEYS:
        out += bytes((0xA0 | len(key),)) + key.encode("ascii")
    return tuple(out)


TEMPLATE = _template()
# protocol.codec.PROTOCOL_VERSION and protocol.messages.MAX_BEAMS (this module imports no
# protocol: setup.py compiles the kernel without the package's dependencies);
# tests/client/behaviour/test_payload.py holds them equal
VERSION = 1
MAX_BEAMS = 100_000


def source_hash() -> int:
    """A checksum (CRC-32) of the kernel's source files, as the ahead-of-time build records it."""
    here = Path(__file__).parent
    crc = 0
    for name in SOURCES:
        crc = zlib.crc32((here / name).read_bytes(), crc)
    return crc
