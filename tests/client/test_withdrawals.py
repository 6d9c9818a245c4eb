"""Labels a teacher takes back (an undo, a discarded episode): the teacher's outbox keeps and
resends the withdrawal until acknowledged; the learner journals it (a tombstone), never learns
those labels, rebuilds its tree without them, and a restart (from the journal alone, from a
snapshot, or from a snapshot older than the withdrawal) keeps them out."""

from __future__ import annotations

import logging

import msgpack
import numpy as np
import pytest

from client.journal import Journal, JournalWithdrawal, LabelSet, Withdrawals, journal_path
from client.labels import Acknowledgements, Outbox
from client.lineage import Lineage
from protocol.messages import LearnerAck, Scan, Withdrawal

LABELS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def _ranges(k: int) -> np.ndarray:
    return np.random.default_rng(k).uniform(0.2, 3.0, 360).astype(np.float32)


def _label(k: int) -> str:
    return LABELS[k % 5]


def _teach(core: Lineage, origin: str, seqs, base: int = 0) -> list:
    return [core.learn(base + q, 0.1 * q, _ranges(base + q), 0.0, _label(base + q), origin, q)
            for q in seqs]


def _reference(path, items) -> Lineage:
    """A tree learned from ``items`` ((origin, seq, base)) only, in that order."""
    ref = Lineage(path, features="wall")
    for origin, q, base in items:
        ref.learn(base + q, 0.1 * q, _ranges(base + q), 0.0, _label(base + q), origin, q)
    return ref


def _expected():
    return ([("s1", q, 0) for q in range(30) if not 10 <= q < 20]
            + [("s2", q, 1000) for q in range(10)])


def _taught(out) -> Lineage:
    core = Lineage(out, features="wall")
    _teach(core, "s1", range(30))
    _teach(core, "s2", range(10), base=1000)
    return core


W = Withdrawal(origin="s1", id=0, first=10, upto=20, reason="undo 1 s")


# ---- the label and withdrawal sets ------------------------------------------------------------
def test_a_range_of_labels_is_held_at_once():
    ls = LabelSet()
    ls.add("a", 0)
    ls.add("a", 30)
    ls.add_range("a", 5, 12)  # above the watermark: held above it
    assert ("a", 7) in ls and ("a", 3) not in ls and ls.ack("a")[0] == 1
    ls.add_range("a", 1, 5)  # fills the gap: the watermark moves past the range
    assert ls.ack("a") == (12, (30,))
    ls.add_range("a", 10, 40)
    assert ls.ack("a") == (40, ())


def test_withdrawals_merge_ranges_and_count_their_ids():
    ws = Withdrawals()
    assert ws.acked("a") is None
    assert ws.add("a", 0, 10, 20) and ws.add("a", 2, 18, 25) and not ws.add("a", 0, 10, 20)
    assert ws.ranges("a") == [(10, 25)] and ws.acked("a") == 1  # id 1 not come yet
    assert ("a", 10) in ws and ("a", 24) in ws and ("a", 25) not in ws and ("b", 12) not in ws
    assert ws.add("a", 1, 40, 41) and ws.acked("a") == 3 and len(ws) == 3 and ws.labels() == 16
    again = Withdrawals.from_dict(msgpack.unpackb(msgpack.packb(ws.to_dict())))
    assert again.to_dict() == ws.to_dict() and ("a", 40) in again


@pytest.mark.parametrize("bad", ["x", {"a": 1}, {"a": {"ranges": [[3, 2]], "ids": [0, []]}},
                                 {"a": {"ranges": [[1, 2]], "ids": [0]}},
                                 {"a": {"ranges": [[1, "x"]], "ids": [0, []]}},
                                 {"a": {"ranges": [], "ids": [-1, []]}}])
def test_withdrawals_from_a_hostile_map_are_a_value_error(bad):
    with pytest.raises(ValueError, match="withdrawals"):
        Withdrawals.from_dict(bad)


# ---- the teacher's end --------------------------------------------------------------------
def _scan(k: int) -> Scan:
    return Scan(ts=0.1 * k, id=k, ranges=_ranges(k))


def test_the_outbox_keeps_a_withdrawal_until_acknowledged_and_drops_its_labels():
    now = [0.0]
    box = Outbox(resend_after=1.0, clock=lambda: now[0])
    for k in range(10):
        box.label(_scan(k), "fwd", "fwd")
    box.ack(4)  # 0..3 acknowledged, 4..9 not
    w = box.withdraw(2, 8, "undo")
    assert (w.first, w.upto, w.id, w.origin) == (2, 8, 0, box.origin)
    assert sorted(e.seq for e in box.everything()) == [8, 9]  # 4..7 are never sent again
    assert box.due_withdrawals() == [] and box.unacknowledged_withdrawals == 1
    now[0] = 1.5
    assert box.due_withdrawals() == [w]  # resent after resend_after, then less often
    assert box.due_withdrawals() == []
    assert box.withdrawals() == [w]  # a learner that (re)started gets it at once
    box.ack(10, withdrawn=0)
    assert box.unacknowledged_withdrawals == 1
    box.ack(10, withdrawn=1)
    assert box.unacknowledged_withdrawals == 0 and box.stats["withdrawn"] == 6
    with pytest.raises(ValueError, match="no label"):
        box.withdraw(10, 20)  # nothing published there yet
    assert box.withdraw(9, 99).upto == 10  # clipped to what was published


def test_acknowledgements_say_which_withdrawals_are_held():
    sent = []
    ls, ws = LabelSet(), Withdrawals()
    acks = Acknowledgements(sent.append, ls, withdrawals=ws)
    ls.add_range("s1", 0, 20)
    ws.add("s1", 0, 10, 20)
    acks.withdrawn("s1")
    assert acks.due(now=1e9)
    acks.publish()
    ack = LearnerAck.decode(sent[-1])
    assert (ack.origin, ack.upto, ack.withdrawn) == ("s1", 20, 1)


# ---- the learner's end --------------------------------------------------------------------
def test_withdrawn_labels_leave_the_tree_and_never_come_back(tmp_path):
    out = tmp_path / "t.rhbl"
    core = _taught(out)
    assert core.withdraw(W) is True  # the tree holds some of them
    assert core.rebuild() and core.standing == 30 and core.applied == 41
    ref = _reference(tmp_path / "ref.rhbl", _expected())
    assert core.learner.classifier.tree_equal(ref.learner.classifier)
    assert _teach(core, "s1", [12]) == [None]  # a resend of a withdrawn label: never learned
    assert core.withdraw(W) is None and len(core.journal) == 41  # held already: not again
    with Journal.open(journal_path(out), readonly=True) as j:
        kinds = [type(r).__name__ for r in j.records()]
        standing = [(r.origin, r.seq) for r in j.standing()]
    assert kinds.count("JournalWithdrawal") == 1
    assert standing == [(o, q) for o, q, _ in _expected()]
    core.journal.sync()
    # "crash" before any snapshot: recovery from the journal alone rebuilds without them
    again = Lineage(out, features="wall")
    assert again.learner.classifier.tree_equal(ref.learner.classifier)
    assert again.holds("s1", 15) and again.withdrawals.holds("s1", 0) and again.standing == 30
    again.snapshot()
    again.close()
    # from the snapshot written after the withdrawal
    third = Lineage(out, features="wall")
    assert third.learner.classifier.tree_equal(ref.learner.classifier)
    assert third.withdrawals.acked("s1") == 1 and third.holds("s1", 19) and third.standing == 30
    for c in (core, third, ref):
        c.close()


def test_a_withdrawal_after_the_last_snapshot_is_applied_on_recovery(tmp_path):
    out = tmp_path / "t.rhbl"
    core = _taught(out)
    core.snapshot()  # holds s1 10..19
    assert core.withdraw(W)
    core.journal.sync()  # killed before rebuilding or snapshotting
    again = Lineage(out, features="wall")
    ref = _reference(tmp_path / "ref.rhbl", _expected())
    assert again.learner.classifier.tree_equal(ref.learner.classifier)
    assert again.rebuilds == 1 and again.replayed == 1
    for c in (core, again, ref):
        c.close()


def test_withdrawing_labels_the_learner_never_journaled_needs_no_rebuild(tmp_path):
    core = _taught(tmp_path / "t.rhbl")
    nodes = core.learner.nodes
    assert core.withdraw(Withdrawal(origin="s1", id=0, first=100, upto=150)) is False
    assert core.withdraw(Withdrawal(origin="s9", id=0, first=0, upto=5)) is False
    assert _teach(core, "s1", [120]) == [None] and core.learner.nodes == nodes
    core.close()


def test_a_folded_journal_cannot_take_withdrawn_labels_out_of_the_tree(tmp_path, caplog):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall", fold_journal=True)
    _teach(core, "s1", range(30))
    core.snapshot()  # folds records 0..29
    assert core.withdraw(W)
    with caplog.at_level(logging.ERROR):
        assert core.rebuild() is False
    assert "fold" in caplog.text and _teach(core, "s1", [15]) == [None]
    core.close()


def test_compaction_data_are_the_vectors_that_stand(tmp_path):
    from client.behaviour.features import FEATURES
    from lab.compact import load_data

    out = tmp_path / "t.rhbl"
    core = _taught(out)
    core.withdraw(W)
    core.close()
    X, y = load_data(journal_path(out), FEATURES["wall"])
    assert len(X) == 30 and list(y) == [_label(b + q) for _, q, b in _expected()]


def test_a_tombstone_record_reads_back(tmp_path):
    p = tmp_path / "t.journal"
    with Journal.create(p, fsync_interval=0.0) as j:
        j.append(0, 0.0, "fwd", _ranges(0), 0.0, np.ones(5, np.float32), "s1", 0)
        assert j.append_withdrawal("s1", 0, 0, 1, 2.5, "discard episode 1") == 1
    with Journal.open(p) as j:
        recs = list(j.records())
        assert recs[1] == JournalWithdrawal(1, "s1", 0, 0, 1, 2.5, "discard episode 1")
        assert list(j.standing()) == [] and len(list(j.standing(stop=1))) == 1


def test_a_withdrawal_far_past_the_labels_held_is_refused_and_the_later_labels_learned(
        tmp_path):
    """Issue 36.4: a withdrawal with ``first`` = 10^9 from a session that gave labels 0-9 made
    the learner give up on seqs 10..999999999: every later label was acknowledged, never
    learned. It is refused (nothing journaled, not held), and labels 10-19 are journaled."""
    from client.lineage import AHEAD, Refused

    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall")
    _teach(core, "s1", range(10))
    far = Withdrawal(origin="s1", id=0, first=10**9, upto=10**9 + 5000)
    with pytest.raises(Refused, match="s1 names labels 1000000000..1000004999") as refused:
        core.withdraw(far)
    assert refused.value.kind == "withdrawal_ahead"
    assert not core.withdrawals.holds("s1", 0) and core.labels.ack("s1") == (10, ())
    assert all(_teach(core, "s1", range(10, 20)))  # learned, not taken as held
    # a withdrawal of labels still on their way (within the teacher's outbox) is held
    assert core.withdraw(Withdrawal(origin="s1", id=1, first=25, upto=20 + AHEAD)) is False
    core.close()
    recs = list(Journal.open(journal_path(out)).records())
    assert sum(not isinstance(r, JournalWithdrawal) for r in recs) == 20
    assert [(r.first, r.upto) for r in recs if isinstance(r, JournalWithdrawal)] == [
        (25, 20 + AHEAD)]
