"""The learner's core without zenoh: journal first, snapshots with provenance, exact recovery;
labels paired with their scans under a flood of scans, in bounded memory."""

from __future__ import annotations

import logging
import os
import threading
import time
import tracemalloc

import numpy as np
import pytest

from client.behaviour.features import DEFAULT_FEATURES, FEATURES
from client.behaviour.learning import load_snapshot
from client.journal import Journal, journal_path
from client.labels import Pairing
from client.lineage import Lineage
from process.runtime import ProcessError
from protocol.messages import Scan, TeacherAction

LABELS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def _feed(core: Lineage, n: int, seed: int, start_id: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for k in range(n):
        ranges = rng.uniform(0.2, 3.0, 360).astype(np.float32)
        core.learn(start_id + k, 0.1 * k, ranges, float(rng.uniform(-3, 3)),
                   LABELS[int(rng.integers(5))])


def test_snapshot_provenance_and_recovery_after_a_crash(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall")
    _feed(core, 40, seed=0)
    core.snapshot()
    _feed(core, 25, seed=1, start_id=40)  # not in any snapshot: only in the journal
    core.journal.sync()
    # "crash": no close, no final snapshot; a new core rebuilds from snapshot + journal
    again = Lineage(out, features="wall")
    assert again.replayed == 25 and again.applied == 65
    ref = Lineage(tmp_path / "ref.rhbl", features="wall")
    _feed(ref, 40, seed=0)
    _feed(ref, 25, seed=1, start_id=40)
    assert again.learner.classifier.tree_equal(ref.learner.classifier)
    again.snapshot()
    _clf, _f, _a, meta = load_snapshot(out)
    prov = meta["provenance"]
    assert prov["labeled"] == 65 and prov["journal"]["records"] == 65
    assert prov["journal"]["lineage"] == again.journal.lineage and prov["parent"] is None
    for c in (core, again, ref):
        c.close()


def test_crash_before_the_first_snapshot_replays_everything(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="maze")
    _feed(core, 30, seed=2)
    core.close()
    assert not out.exists()
    again = Lineage(out)  # features come from the journal's header
    assert again.replayed == 30 and again.features.heading == "lr"
    again.close()


def test_resume_starts_a_new_lineage_and_guards_paths(tmp_path):
    base = tmp_path / "base.rhbl"
    core = Lineage(base, features="wall")
    _feed(core, 30, seed=3)
    core.snapshot()
    core.close()
    ext = Lineage(tmp_path / "ext.rhbl", resume=str(base))
    _feed(ext, 10, seed=4)
    ext.snapshot()
    meta = load_snapshot(ext.out)[3]
    assert meta["provenance"]["parent"] == str(base.resolve())
    assert meta["provenance"]["vectors"] == 40 and meta["provenance"]["labeled"] == 10
    assert ext.journal.lineage != Lineage(base).journal.lineage
    ext.close()
    with pytest.raises(ProcessError, match="other features"):
        Lineage(tmp_path / "x.rhbl", resume=str(base), features="maze")
    with pytest.raises(ProcessError, match="choose another --out"):
        Lineage(base, resume=str(tmp_path / "ext.rhbl"))
    with pytest.raises(ProcessError, match="cannot continue"):
        Lineage(base, features="maze")
    (tmp_path / "plain.rhbl").write_bytes(base.read_bytes())
    with pytest.raises(ProcessError, match="has no journal"):
        Lineage(tmp_path / "plain.rhbl", features="wall")


def test_snapshot_ahead_of_its_journal_is_an_error(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall")
    _feed(core, 20, seed=5)
    core.snapshot()
    core.close()
    jp = journal_path(out)
    data = jp.read_bytes()
    jp.write_bytes(data[: len(data) // 2])  # lose records (more than a torn tail)
    with pytest.raises(ProcessError, match="lost records"):
        Lineage(out)


def test_a_new_tree_without_features_sees_all_round_and_its_snapshot_says_so(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out)
    assert core.features == FEATURES[DEFAULT_FEATURES] == FEATURES["around"]
    _feed(core, 20, seed=5)
    core.snapshot()
    core.close()
    assert load_snapshot(out)[1] == FEATURES["around"]
    again = Lineage(out)  # continued: the tree's spec, not the default asked again
    assert again.features == FEATURES["around"]
    again.close()
    walled = Lineage(tmp_path / "w.rhbl", features="wall")
    assert walled.features == FEATURES["wall"]
    walled.close()


# ---- pairing under a flood of scans -----------------------------------------------------------
def _scan(sid: int, ranges: np.ndarray) -> bytes:
    return Scan(ts=0.01 * sid, id=sid, ranges=ranges).encode()


def _label(sid: int) -> bytes:
    return TeacherAction(scan_id=sid, action=LABELS[sid % 5]).encode()


def test_a_scan_flood_stays_bounded_and_every_label_whose_scan_arrived_is_learned(tmp_path):
    """30000 scans arrive while the learning loop is stalled (a learner far behind a server at a
    high --speedup); one scan in 60 is labeled, the label some scans after its scan, a few
    before it. Memory stays bounded by the pairing buffer plus the labeled scans, and once the
    loop runs every label is learned, in order, exactly once."""
    n, every, buffer = 30_000, 60, 256
    rng = np.random.default_rng(0)
    ranges = [rng.uniform(0.3, 3.0, 360).astype(np.float32) for _ in range(16)]
    scans = [_scan(sid, ranges[sid % 16]) for sid in range(1, n + 1)]  # encoded up front
    labeled = list(range(every, n + 1, every))
    early = set(labeled[::25])  # these labels arrive before their scan
    lag = {sid: 1 + sid % 200 for sid in labeled}  # the others 1..200 scans after theirs
    due: dict[int, list[int]] = {}
    for sid in labeled:
        if sid not in early:
            due.setdefault(sid + lag[sid], []).append(sid)
    too_late = n - 2 * buffer  # one label that comes after its scan was forgotten
    assert too_late not in labeled

    pairing = Pairing(scan_buffer=buffer, match_timeout=60.0)
    sizes = {"scans": 0, "ready": 0, "pending": 0}

    def flood():
        for sid, data in enumerate(scans, start=1):
            if sid in early:
                pairing.on_label(_label(sid))
            pairing.on_scan(data)
            for old in due.pop(sid, ()):
                pairing.on_label(_label(old))
            if sid % 500 == 0:
                sizes["scans"] = max(sizes["scans"], len(pairing.scans))
                sizes["ready"] = max(sizes["ready"], pairing.waiting())
                sizes["pending"] = max(sizes["pending"], len(pairing.pending))
        for rest in due.values():
            for old in rest:
                pairing.on_label(_label(old))
        pairing.on_label(_label(too_late))

    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        thread = threading.Thread(target=flood)  # the zenoh callbacks' thread
        thread.start()
        thread.join(120)
        assert not thread.is_alive()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()

    assert pairing.stats["scans"] == n
    assert len(pairing.scans) <= buffer and sizes["scans"] <= buffer
    assert pairing.waiting() == len(labeled)  # every labeled scan kept, none dropped
    assert sizes["pending"] <= len(early)
    assert pairing.pending == {}
    assert pairing.stats["lost"] == 0
    assert pairing.stats["unmatched"] == 1  # the one label after its scan was forgotten
    # every scan was either labeled, forgotten unlabeled, or is still in the buffer
    assert pairing.stats["forgotten"] + len(pairing.scans) + len(labeled) == n
    assert pairing.stats["forgotten"] > n - buffer - len(labeled) - every
    # what stays in memory is the buffer plus the labeled scans (~2 KB each), not the 30000
    # scans that arrived (~60 MB as queued bytes, more as decoded scans)
    one = 2_000 + 8 * 360
    assert peak < (buffer + len(labeled)) * one * 2 + 2_000_000, peak

    out = tmp_path / "flood.rhbl"
    core = Lineage(out, features="wall")
    while (item := pairing.get(0.0)) is not None:
        scan, act = item
        core.learn(scan.id, scan.ts, scan.ranges, float(scan.pose[2]), act.action)
    core.close()
    with Journal.open(journal_path(out), readonly=True) as jr:
        records = [(r.scan_id, r.label) for r in jr.records()]
    assert sorted(records) == [(sid, LABELS[sid % 5]) for sid in labeled]
    assert len(records) == len(set(records))


def test_pairing_says_when_the_learner_falls_behind_and_counts_what_it_drops(caplog):
    pairing = Pairing(scan_buffer=8, max_ready=10, behind=4)
    ranges = np.ones(360, np.float32)
    with caplog.at_level(logging.WARNING, logger="client.labels"):
        for sid in range(1, 16):
            pairing.on_scan(_scan(sid, ranges))
            pairing.on_label(_label(sid))
    text = caplog.text
    assert "falls behind the teacher: 5 labeled scans wait" in text
    assert "far behind the teacher: dropped the oldest" in text
    assert pairing.stats["lost"] == 5 and pairing.waiting() == 10
    assert pairing.get(0.0)[0].id == 6  # the oldest went first
    # malformed input is counted and logged, never raised into the zenoh callback
    pairing.on_scan(b"not a scan")
    pairing.on_label(b"not a label")
    assert pairing.decoder.counts == {"scan": 1, "teacher/action": 1}
    # a label whose scan never arrives expires after match_timeout, counted
    clock = [0.0]
    late = Pairing(match_timeout=1.0, clock=lambda: clock[0])
    late.on_label(_label(99))
    clock[0] = 2.0
    assert late.expire() == [99] and late.stats["unmatched"] == 1
    # ids going backwards (a restarted server): the old run's scans are forgotten
    late.on_scan(_scan(500, ranges))
    late.on_scan(_scan(1, ranges))
    late.on_label(_label(500))
    assert late.waiting() == 0 and 500 in late.pending


def test_a_resumed_learner_says_the_vectors_its_tree_holds(tmp_path):
    """A new lineage extending a tree starts with that tree's vectors, not with "0 vectors"
    (its own journal is empty: the first line said "0 vectors so far, 776 nodes")."""
    base = tmp_path / "base.rhbl"
    core = Lineage(base, features="wall")
    _feed(core, 30, seed=4)
    core.snapshot()
    nodes = core.learner.nodes
    core.close()
    ext = Lineage(tmp_path / "ext.rhbl", resume=str(base))
    said = ext.describe()
    assert f"30 vectors so far (0 journaled in lineage {ext.journal.lineage}), {nodes} nodes" in said
    assert ext.journal.header["fork"] == {"lineage": core.journal.lineage, "records": 30}
    ext.close()
    fresh = Lineage(tmp_path / "fresh.rhbl", features="wall")
    assert "0 vectors so far (0 journaled" in fresh.describe() and fresh.describe().endswith(
        "1 nodes")
    fresh.close()


def test_one_learner_per_lineage_and_no_stale_lock_after_a_kill(tmp_path):
    """Issue 36.1: two learners on one lineage both journaled every label and left a journal
    no learner could open. The lineage's lock refuses a second holder, naming the first's pid;
    a SIGKILLed holder leaves no stale lock; ``wait`` waits for a holder that ends."""
    import subprocess
    import sys

    from client.lineage import LineageLock, lock_path

    def holder(path) -> str:
        return path.read_text().strip() if path.exists() else ""

    out = tmp_path / "t.rhbl"
    hold = ("import sys, time\nfrom client.lineage import LineageLock\n"
            "lock = LineageLock(sys.argv[1])\ntime.sleep(120)\n")
    holders = []
    try:
        for _ in range(2):
            proc = subprocess.Popen([sys.executable, "-c", hold, str(out)])
            holders.append(proc)
            end = time.monotonic() + 30
            while holder(lock_path(out)) != str(proc.pid):
                assert time.monotonic() < end and proc.poll() is None, "the holder never locked"
                time.sleep(0.02)
            with pytest.raises(ProcessError, match=f"held by another learner \\(pid {proc.pid}"):
                Lineage(out, features="wall")
            assert not journal_path(out).exists()  # refused before anything was written
            if len(holders) == 1:
                proc.kill()  # SIGKILL: the OS drops its lock
                proc.wait(10)
                lock = LineageLock(out)  # not stale
                lock.close()
        # a holder that ends while we wait (a learner draining after SIGTERM)
        threading.Timer(0.5, holders[1].terminate).start()
        t0 = time.monotonic()
        core = Lineage(out, features="wall", lock_wait=30)
        assert time.monotonic() - t0 < 30 and holder(lock_path(out)) == str(os.getpid())
        core.close()
    finally:
        for proc in holders:
            proc.kill()
            proc.wait(10)
