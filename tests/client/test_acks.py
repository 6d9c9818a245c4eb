"""Labels delivered exactly once into the journal: the teacher's outbox (kept until acknowledged,
resent after a timeout, bounded), the learner's deduplication (``LabelSet``: journal records,
recovery, snapshot provenance across folding) and the pairing of resent labels."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from client.journal import Journal, LabelSet, _frame, journal_path
from client.labels import Acknowledgements, Outbox, Pairing
from client.lineage import Lineage
from protocol.messages import LabeledScan, Scan, TeacherAction


def _ranges(k: int) -> np.ndarray:
    return np.random.default_rng(k).uniform(0.2, 3.0, 360).astype(np.float32)


# ---- the label set ------------------------------------------------------------------------
def test_label_set_keeps_a_watermark_and_the_few_above_it():
    ls = LabelSet()
    assert ls.add("a", 0) and ls.add("a", 1) and ls.add("a", 3)
    assert not ls.add("a", 1)  # held already
    assert ("a", 2) not in ls and ("a", 3) in ls and ("b", 0) not in ls
    assert ls.ack("a") == (2, (3,))
    assert ls.add("a", 2) and ls.ack("a") == (4, ())  # the gap filled: the watermark moves
    assert len(ls) == 4
    again = LabelSet.from_dict(msgpack.unpackb(msgpack.packb(ls.to_dict())))
    assert again.ack("a") == (4, ()) and ("a", 3) in again and ("a", 4) not in again


def test_label_set_is_bounded():
    ls = LabelSet(max_above=10, max_origins=3)
    ls.add("a", 0)
    for q in range(2, 14):  # seq 1 never comes (its teacher died): the gap is given up
        ls.add("a", q)
    upto, above = ls.ack("a")
    assert len(above) <= 10 and upto > 1 and ("a", 13) in ls
    for o in "bcd":
        ls.add(o, 0, kept=False)  # refused labels only: at most 3 such origins kept
    assert ls.origins() == ["a", "b", "c", "d"]
    ls.add("e", 0, kept=False)
    assert ls.origins() == ["a", "c", "d", "e"]  # the least recently seen of them forgotten
    ls.add("c", 1)  # journaled: kept for good
    for o in "fgh":
        ls.add(o, 0, kept=False)
    assert ls.origins() == ["a", "c", "f", "g", "h"]


def test_label_set_keeps_every_session_with_a_journaled_label():
    """Issue 36.5: past 256 sessions the learner forgot the least recent one and journaled its
    resent labels again."""
    ls = LabelSet()
    for i in range(1000):
        assert ls.add(f"s{i}", 0)
    assert all(not ls.add(f"s{i}", 0) for i in range(1000))  # resends: held, every one


@pytest.mark.parametrize("bad", ["x", {"a": 3}, {"a": [1]}, {"a": [1, "x"]}, {"a": [1, [2.5]]},
                                 {5: [1, []]}])
def test_label_set_from_a_hostile_map_is_a_value_error(bad):
    with pytest.raises(ValueError, match="label set"):
        LabelSet.from_dict(bad)


# ---- journal records ----------------------------------------------------------------------
def test_journal_records_carry_the_label_identity_and_old_records_still_load(tmp_path):
    path = tmp_path / "t.journal"
    with Journal.create(path, fsync_interval=0.0) as j:
        j.append(0, 0.0, "fwd", _ranges(0), 0.0, np.ones(5, np.float32))
        j.append(1, 0.1, "fwd", _ranges(1), 0.0, np.ones(5, np.float32), "s1", 0)
    # a record written by the code before identities: no "origin"/"seq" fields
    old = {"i": 2, "scan": 2, "ts": 0.2, "label": "fwd", "yaw": 0.0,
           "ranges": _ranges(2).tobytes(), "x": np.ones(5, "<f4").tobytes()}
    with open(path, "ab") as f:
        f.write(_frame(msgpack.packb(old, use_bin_type=True)))
    with Journal.open(path) as j:
        recs = list(j.records())
    assert [(r.origin, r.seq) for r in recs] == [(None, None), ("s1", 0), (None, None)]


# ---- the learner's deduplication ----------------------------------------------------------
def _learn(core: Lineage, origin: str, seqs) -> list:
    return [core.learn(100 + q, 0.1 * q, _ranges(q), 0.0, "fwd", origin, q) for q in seqs]


def test_a_label_learned_twice_is_journaled_once_also_after_recovery(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall")
    assert None not in _learn(core, "s1", range(5))
    assert _learn(core, "s1", [3]) == [None]  # resent: not journaled, not learned
    assert core.applied == 5 and len(core.journal) == 5
    core.journal.sync()  # "crash" before any snapshot: recovery from the journal alone
    again = Lineage(out, features="wall")
    assert again.labels.ack("s1") == (5, ())
    got = _learn(again, "s1", [0, 4, 5])
    assert got[:2] == [None, None] and got[2] is not None  # held twice; seq 5 is new
    assert len(again.journal) == 6
    # a label without identity (an old teacher) is never deduplicated
    again.learn(1, 0.0, _ranges(1), 0.0, "fwd")
    again.learn(1, 0.0, _ranges(1), 0.0, "fwd")
    assert len(again.journal) == 8
    for c in (core, again):
        c.close()


def test_folding_keeps_what_deduplication_needs(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall", fold_journal=True)
    _learn(core, "s1", [0, 1, 2, 4])
    _learn(core, "s2", [0])
    core.snapshot()  # folds every record into the snapshot
    assert core.journal.base == 5 and list(core.journal.records(5)) == []
    _learn(core, "s1", [5])  # only in the journal
    core.journal.sync()
    again = Lineage(out, features="wall", fold_journal=True)  # killed, restarted
    assert again.labels.ack("s1") == (3, (4, 5)) and again.labels.ack("s2") == (1, ())
    assert _learn(again, "s1", [1, 4, 5]) == [None, None, None]
    assert _learn(again, "s1", [3])[0] is not None  # the missing one is learned
    assert again.labels.ack("s1") == (6, ())
    for c in (core, again):
        c.close()
    assert journal_path(out).exists()


# ---- pairing a resent label -----------------------------------------------------------------
def test_a_resent_label_is_ready_at_once_and_replaces_the_one_waiting_for_its_scan():
    p = Pairing(scan_buffer=8, match_timeout=60.0)
    act = TeacherAction(scan_id=40, action="fwd", origin="s1", seq=9)
    p.on_label(act.encode())  # its scan never comes (the learner restarted)
    assert p.pending and p.waiting() == 0
    p.on_labeled(LabeledScan.of(act, _ranges(4), 0.5).encode())
    scan, got = p.get(0.0)
    assert got == act and scan.id == 40 and scan.pose[2] == 0.5
    assert np.array_equal(scan.ranges, _ranges(4)) and not p.pending
    p.on_labeled(b"\x81\xa1v\x01")  # malformed: counted, dropped
    assert p.stats["resent"] == 1 and p.decoder.counts == {"teacher/labeled": 1}


# ---- the teacher's outbox ---------------------------------------------------------------------
class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _scan(i: int) -> Scan:
    return Scan(ts=0.1 * i, id=i, ranges=_ranges(i), pose=(0.0, 0.0, 0.1 * i))


def test_outbox_acks_remove_gaps_and_stalls_resend_with_backoff_and_the_bound_says_full():
    clock = _Clock()
    box = Outbox(cap=6, resend_after=2.0, origin="s1", clock=clock)
    items = [box.label(_scan(i), "fwd", None) for i in range(4)]
    assert [x.seq for x in items] == [0, 1, 2, 3] and items[2].origin == "s1"
    assert items[2].yaw == pytest.approx(0.2) and items[2].scan_id == 2
    assert box.ack(2, (3,)) == 3 and len(box) == 1  # seq 0, 1 below the watermark; 3 above
    assert box.due() == []  # seq 2 is a gap, but not 2 s old yet
    clock.t = 1.0
    box.label(_scan(4), "fwd", None)  # acknowledged in order, later
    clock.t = 2.1
    assert [x.seq for x in box.due()] == [2]  # a later label got through: 2 was missed
    assert box.due() == []  # resent; the next time after 4 s (backoff)
    clock.t = 2.5
    assert box.ack(5) == 2  # seq 2 (the resend) and 4 acknowledged
    # a learner that is behind but acknowledges in order gets no resends
    for i in range(5, 8):
        box.label(_scan(i), "fwd", None)
    clock.t = 4.4
    box.ack(6)
    clock.t = 5.0
    assert box.due() == []  # 6, 7 are 2.5 s old, but the learner progresses, in order
    # a stuck learner (nothing acknowledged for 2 s) gets them again, with backoff
    clock.t = 6.5
    assert [x.seq for x in box.due()] == [6, 7]
    clock.t = 10.0
    assert box.due() == []
    clock.t = 10.6
    assert [x.seq for x in box.due()] == [6, 7]  # 4 s after the first resend
    assert [x.seq for x in box.everything()] == [6, 7]  # a learner (re)started: all at once
    assert box.stats["resent"] == 7 and not box.full
    for i in range(8, 12):
        box.label(_scan(i), "fwd", None)
    assert len(box) == 6 and box.full  # the caller pauses; nothing is dropped
    assert box.ack(12) == 6 and not box.full and box.due() == []


def test_resends_to_a_learner_that_cannot_journal_are_kept_once(tmp_path):
    """The journal cannot be written (here: closed), so nothing is acknowledged and the teacher
    resends: the learner keeps one copy of each label in its backlog, not one per resend (a
    stuck learner's backlog filled with copies and dropped them as "lost"), and a resent label
    it journaled already is acknowledged again."""
    from collections import deque

    from client.roles.learner import LearnerProcess

    core = Lineage(tmp_path / "t.rhbl", features="wall")
    assert None not in _learn(core, "s1", [0])
    core.journal.close()  # every append now raises JournalError
    p = LearnerProcess.__new__(LearnerProcess)
    p.lineage, p.backlog, p.waiting = core, deque(), set()
    p.stats = {"learned": 0, "paired": 0, "rejected": 0, "lost": 0, "duplicates": 0}
    p.retry_at, p.failures, p.backlog_bytes = 0.0, 0, 0
    p.acks = Acknowledgements(lambda _data: None, core.labels)
    for _ in range(10):  # seq 1, resent ten times while the journal fails
        p.learn(_scan(1), TeacherAction(scan_id=1, action="fwd", origin="s1", seq=1))
    assert len(p.backlog) == 1 and p.stats["duplicates"] == 9 and p.stats["lost"] == 0
    assert p.failures >= 1 and p.acks.pending == set()  # nothing journaled, nothing acknowledged
    p.learn(_scan(0), TeacherAction(scan_id=0, action="fwd", origin="s1", seq=0))  # held
    assert p.stats["duplicates"] == 10 and p.acks.pending == {"s1"} and len(p.backlog) == 1


def test_labels_refused_as_bad_input_are_acknowledged_as_refused_not_held():
    """A label the learner refuses for good is acknowledged (never resent) and the ack says how
    many were refused, so the teacher's count of labels held agrees with the journal."""
    from protocol.messages import LearnerAck

    sent = []
    labels = LabelSet()
    acks = Acknowledgements(sent.append, labels)
    for seq in range(3):
        labels.add("o", seq)  # journaled
        acks.handled(TeacherAction(action="fwd", scan_id=seq, origin="o", seq=seq), True)
    acks.handled(TeacherAction(action="nope", scan_id=3, origin="o", seq=3), False)
    acks.handled(TeacherAction(action="nope", scan_id=3, origin="o", seq=3), False)  # resent
    acks.publish()
    ack = LearnerAck.decode(sent[-1])
    assert (ack.upto, ack.refused) == (4, 1)
    box = Outbox(origin="o")
    for seq in range(4):
        box.label(_scan(seq), "fwd", None)
    assert box.ack(ack.upto, ack.seqs, ack.withdrawn, ack.refused) == 4
    assert (box.stats["acked"], box.stats["refused"]) == (4, 1)
    assert LearnerAck.decode(LearnerAck(origin="o", upto=2).encode()).refused is None


def test_an_ack_naming_a_seq_twice_is_taken_once():
    """A hostile or buggy ack (the decoder lets repeated seqs through): no KeyError in the
    teacher's subscription callback, the label forgotten once."""
    box = Outbox(cap=6, resend_after=2.0, origin="s1", clock=_Clock())
    for i in range(3):
        box.label(_scan(i), "fwd", None)
    assert box.ack(0, (1, 1)) == 1 and len(box) == 2 and box.stats["acked"] == 1


def test_labels_unacknowledged_at_exit_are_not_called_lost(free_port, caplog):
    """All services stopped at once: the learner held every label but its last
    acknowledgement never came; the teacher said ERROR "... not acknowledged ... lost"."""
    import logging
    import threading

    import zenoh

    from client.labels import LabelPublisher
    from process.session import make_config
    from protocol import keys

    with zenoh.open(make_config(mode="peer", listen=[f"tcp/127.0.0.1:{free_port()}"])) as s:
        pub = LabelPublisher(s, "r0", outbox=8, resend_after=60.0)
        seen = threading.Event()
        token = s.liveliness().declare_token(keys.alive_key("learner", "r0-1"))
        for _ in range(3000):  # the liveliness callback (at most 30 s)
            if pub.learners.arrivals:
                break
            seen.wait(0.01)
        assert pub.learners.arrivals == 1
        for i in range(3):
            pub.label(_scan(i), "fwd", None)
        token.undeclare()  # the learner stopped first, its acknowledgements never sent
        with caplog.at_level(logging.INFO, logger="client.labels"):
            assert pub.drain(0.2) is False
        pub.close()
    said = [r for r in caplog.records if "unacknowledged at exit" in r.getMessage()]
    assert said and said[0].levelno == logging.WARNING, caplog.text
    assert "seq 0..2" in said[0].getMessage() and "lost" not in caplog.text
