"""Hostile recordings: a decompression bomb, a file cut at every offset, a FIFO, records that
claim more than the file holds. Each is a clear ``RecordingError`` (or, for a cut, the messages
of the complete chunks before it and a note), never a ``struct.error``, a hang or a GiB."""

from __future__ import annotations

import os
import struct
import threading

import numpy as np
import pytest

from client.recording.mcap_file import (
    MAX_CHUNK,
    MAX_RECORD,
    RecordingError,
    RecordingReader,
    RecordingWriter,
    read_recording,
)
from protocol import keys
from protocol import messages as m

R = np.full(36, 2.0, dtype=np.float32)


def small_recording(path, n: int = 12, chunk_every: int = 4) -> list[bytes]:
    """A closed recording of ``n`` scans, a chunk closed every ``chunk_every`` messages."""
    payloads = []
    with RecordingWriter(path, viewer=False, chunk_seconds=1e9) as w:
        for k in range(n):
            data = m.Scan(ts=float(k), id=k, ranges=R).encode()
            payloads.append(data)
            w.write(keys.scan_key("r0"), data, 1_000_000_000 + k)
            if (k + 1) % chunk_every == 0:
                w.flush()
    return payloads


def test_a_cut_at_every_offset_reads_a_prefix_or_names_the_file(tmp_path):
    """Cut the file at every byte: the reader yields a prefix of the messages (those in the
    complete chunks before the cut) and a note, or a RecordingError naming the file (the cut is
    inside the magic bytes); never another exception."""
    good = tmp_path / "good.mcap"
    payloads = small_recording(good)
    whole = good.read_bytes()
    assert [r.data for r in read_recording(good)] == payloads
    cut = tmp_path / "cut.mcap"
    prefixes = set()
    for at in range(len(whole)):
        cut.write_bytes(whole[:at])
        reader = RecordingReader(cut)
        try:
            got = [r.data for r in reader.messages()]
        except RecordingError as exc:
            assert str(cut) in str(exc) and at < 8 + 9, (at, exc)  # no magic: not a recording
            continue
        assert got == payloads[:len(got)], at
        assert len(reader.notes) == 1 and "cut" in reader.notes[0], (at, reader.notes)
        prefixes.add(len(got))
    assert prefixes >= {0, 4, 8, 12}  # every complete chunk is read once the cut passes it


def _chunk_record(compression: str, data: bytes, uncompressed_size: int) -> bytes:
    import zlib

    body = (struct.pack("<QQQI", 0, 0, uncompressed_size, 0)
            + struct.pack("<I", len(compression)) + compression.encode()
            + struct.pack("<Q", len(data)) + data)
    assert zlib  # the CRC 0 means "not computed"
    return struct.pack("<BQ", 0x06, len(body)) + body


MAGIC = b"\x89MCAP0\r\n"
HEADER = struct.pack("<BQ", 0x01, 8) + struct.pack("<I", 0) + struct.pack("<I", 0)


def test_a_decompression_bomb_is_refused_without_inflating_it(tmp_path):
    import zstandard

    gib = zstandard.ZstdCompressor(level=19).compress(b"\0" * (MAX_CHUNK + 2**20))
    bomb = tmp_path / "bomb.mcap"
    bomb.write_bytes(MAGIC + HEADER + _chunk_record("zstd", gib, MAX_CHUNK + 2**20))
    with pytest.raises(RecordingError, match="decompression bomb"):
        list(read_recording(bomb))
    # a chunk that lies about its size (declares 100 bytes, holds 64 MiB) is caught after at
    # most 101 bytes are inflated
    liar = tmp_path / "liar.mcap"
    liar.write_bytes(MAGIC + HEADER + _chunk_record("zstd", gib, 100))
    with pytest.raises(RecordingError, match="liar.mcap is damaged.*more than the 100 bytes"):
        list(read_recording(liar))


def test_a_record_claiming_more_than_the_limit_is_refused(tmp_path):
    huge = tmp_path / "huge.mcap"
    huge.write_bytes(MAGIC + HEADER + struct.pack("<BQ", 0x05, MAX_RECORD + 1) + b"\0" * 16)
    with pytest.raises(RecordingError, match="claims .* bytes, more than"):
        list(read_recording(huge))


def test_a_fifo_is_refused_at_once(tmp_path):
    fifo = tmp_path / "r.mcap"
    os.mkfifo(fifo)
    done = threading.Event()
    errors = []

    def read():
        try:
            list(read_recording(fifo))
        except RecordingError as exc:
            errors.append(str(exc))
        done.set()

    threading.Thread(target=read, daemon=True).start()
    if not done.wait(30):  # a blocked open: unblock it by opening the writer side
        fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        pytest.fail("reading a FIFO blocked")
    assert errors and "a FIFO" in errors[0]
