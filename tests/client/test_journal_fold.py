"""Folding a journal into a snapshot: records before ``base`` are dropped, indices kept, the
file stays a valid journal (reopened, appended to, recovered by a learner killed after it)."""

from __future__ import annotations

import numpy as np
import pytest

from client.journal import Journal, JournalCorruptError, JournalError


def _append(j: Journal, n: int) -> None:
    for _ in range(n):
        i = len(j)
        j.append(i, 0.1 * i, "fwd", np.full(360, i, np.float32), 0.0, np.full(5, i, np.float32))


def test_fold_drops_the_records_before_and_keeps_indices(tmp_path):
    path = tmp_path / "t.rhbl.journal"
    j = Journal.create(path, fsync_interval=0.0)
    _append(j, 50)
    size = path.stat().st_size
    saved = j.fold(40)
    assert saved > 0 and path.stat().st_size < size / 3
    assert len(j) == 50 and j.base == 40
    assert [r.index for r in j.records(40)] == list(range(40, 50))
    with pytest.raises(JournalError, match="folded"):
        next(iter(j.records(10)))
    _append(j, 5)  # appends continue after the fold, at index 50
    assert [r.scan_id for r in j.records(48)] == [48, 49, 50, 51, 52, 53, 54]
    lineage = j.lineage
    j.close()
    with Journal.open(path) as again:  # the folded file is a whole journal
        assert len(again) == 55 and again.base == 40 and again.lineage == lineage
        assert float(next(iter(again.records(52))).features[0]) == 52.0
        assert again.fold(10) == 0  # nothing below base to fold
        again.fold(55)
        assert len(again) == 55 and list(again.records(55)) == []


def test_a_hostile_base_is_a_corrupt_journal(tmp_path):
    import msgpack

    from client.journal import _frame

    path = tmp_path / "bad.journal"
    path.write_bytes(_frame(msgpack.packb({"kind": "rhbl-journal", "format": 1, "base": "x"})))
    with pytest.raises(JournalCorruptError, match="base"):
        Journal.open(path)
