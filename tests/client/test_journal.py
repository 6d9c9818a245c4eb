"""The learner's append-only journal: nothing labeled is lost, damage is never silent."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest

from client.journal import (
    Journal,
    JournalCorruptError,
    JournalError,
    journal_path,
)


def _fill(j: Journal, n: int, start: int = 0) -> None:
    for k in range(start, start + n):
        j.append(scan_id=1000 + k, ts=0.1 * k, label=("fwd", "rot-left")[k % 2],
                 ranges=np.full(8, k, dtype=np.float32), yaw=0.5,
                 features=np.linspace(0, 1, 5, dtype=np.float32) * (k % 3))


def test_journal_path_is_beside_the_snapshot(tmp_path):
    assert journal_path(tmp_path / "tree.rhbl") == tmp_path / "tree.rhbl.journal"


def test_roundtrip_and_reopen_appends(tmp_path):
    p = tmp_path / "t.journal"
    with Journal.create(p, {"task": "wall", "parent": None}) as j:
        _fill(j, 5)
        lineage = j.lineage
        assert len(j) == 5
    with Journal.open(p) as j:
        assert j.header["task"] == "wall" and j.lineage == lineage
        assert len(j) == 5 and j.truncated_bytes == 0
        _fill(j, 3, start=5)
    with Journal.open(p, readonly=True) as j:
        recs = list(j.records())
        assert [r.index for r in recs] == list(range(8))
        assert [r.scan_id for r in recs] == [1000 + k for k in range(8)]
        assert recs[3].label == "rot-left"
        np.testing.assert_array_equal(recs[7].ranges, np.full(8, 7, dtype=np.float32))
        assert recs[5].features.dtype == np.float32 and recs[5].features.shape == (5,)
        assert [r.index for r in j.records(6)] == [6, 7]
        assert list(j.records(8)) == []
        with pytest.raises(JournalError, match="cannot start at record 9"):
            list(j.records(9))


def test_create_refuses_an_existing_journal(tmp_path):
    p = tmp_path / "t.journal"
    Journal.create(p).close()
    with pytest.raises(JournalError, match="already exists"):
        Journal.create(p)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]


def test_open_missing(tmp_path):
    with pytest.raises(JournalError, match="does not exist"):
        Journal.open(tmp_path / "nope.journal")


@pytest.mark.parametrize("cut", [1, 5, 8, 20])
def test_torn_last_record_is_truncated_and_appending_continues(tmp_path, cut):
    p = tmp_path / "t.journal"
    with Journal.create(p) as j:
        _fill(j, 4)
    whole = p.stat().st_size
    with open(p, "ab") as f:  # a write cut off by a crash: a partial frame at the end
        frame_head = struct.pack("<II", 200, 12345)
        f.write((frame_head + b"x" * 200)[:cut])
    with Journal.open(p) as j:
        assert len(j) == 4 and j.truncated_bytes == cut
        _fill(j, 1, start=4)
    with Journal.open(p) as j:
        assert [r.index for r in j.records()] == [0, 1, 2, 3, 4]
    assert p.stat().st_size > whole


def test_corruption_in_the_middle_is_a_clear_error(tmp_path):
    p = tmp_path / "t.journal"
    with Journal.create(p) as j:
        _fill(j, 6)
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0xFF
    p.write_bytes(bytes(data))
    with pytest.raises(JournalCorruptError, match="fails its CRC check"):
        Journal.open(p)
    assert p.read_bytes() == bytes(data)  # nothing truncated or rewritten


def test_damaged_last_whole_frame_is_corruption_not_a_torn_tail(tmp_path):
    p = tmp_path / "t.journal"
    with Journal.create(p) as j:
        _fill(j, 3)
    data = bytearray(p.read_bytes())
    data[-1] ^= 0x01
    p.write_bytes(bytes(data))
    with pytest.raises(JournalCorruptError, match="offset"):
        Journal.open(p)


def test_not_a_journal(tmp_path):
    p = tmp_path / "t.journal"
    p.write_bytes(b"hello world, this is not a journal at all")
    with pytest.raises(JournalCorruptError):
        Journal.open(p)


def test_records_survive_a_killed_writer(tmp_path):
    """Appends are in the kernel when append() returns: a SIGKILLed writer loses nothing."""
    import multiprocessing as mp
    import signal

    p = tmp_path / "t.journal"
    Journal.create(p).close()
    ctx = mp.get_context("spawn")
    ready = ctx.Event()
    proc = ctx.Process(target=_writer, args=(str(p), 50, ready))
    proc.start()
    assert ready.wait(30)
    os.kill(proc.pid, signal.SIGKILL)
    proc.join(10)
    with Journal.open(p) as j:
        assert len(j) >= 50
        assert [r.index for r in j.records()] == list(range(len(j)))


def _writer(path: str, n: int, ready) -> None:  # pragma: no cover - runs in a child
    import time

    j = Journal.open(path, fsync_interval=3600.0)
    _fill(j, n)
    ready.set()
    k = n
    while True:  # keep writing until killed
        _fill(j, 1, start=k)
        k += 1
        time.sleep(0.0005)


def test_disk_full_mid_append_leaves_no_partial_record(tmp_path):
    """A write cut short by ENOSPC is cut back out: the append can be retried and the journal
    still opens with every record (before: a partial frame stayed in the middle -> corrupt).
    The failing disk comes through the journal's seam, ``write``."""
    import errno

    p = tmp_path / "t.journal"
    disk = {"full": False, "calls": 0}

    def write(fd, data):
        if not disk["full"]:
            return os.write(fd, data)
        disk["calls"] += 1
        if disk["calls"] == 1:
            return os.write(fd, bytes(data)[:7])  # a short write...
        raise OSError(errno.ENOSPC, "No space left on device")  # ...then the disk is full

    j = Journal.create(p, write=write)
    _fill(j, 2)
    disk["full"] = True
    with pytest.raises(JournalError, match="No space left"):
        _fill(j, 1, start=2)
    disk["full"] = False
    assert len(j) == 2 and disk["calls"] == 2
    _fill(j, 1, start=2)  # the retry (space freed)
    assert [r.index for r in j.records()] == [0, 1, 2]
    j.close()
    with Journal.open(p) as again:
        assert [r.index for r in again.records()] == [0, 1, 2] and again.truncated_bytes == 0


def test_failed_fsync_after_a_written_record_does_not_fail_the_append(tmp_path, monkeypatch):
    """The record is in the file: raising would make a caller append it a second time."""
    from client import journal as jmod

    p = tmp_path / "t.journal"
    j = Journal.create(p, fsync_interval=0.0)

    def bad_fsync(fd):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(jmod.os, "fsync", bad_fsync)
    assert j.append(1, 0.0, "fwd", np.zeros(4, np.float32), 0.0, np.zeros(2, np.float32)) == 0
    monkeypatch.undo()
    j.close()
    with Journal.open(p) as again:
        assert len(again) == 1
