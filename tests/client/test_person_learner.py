"""A person's labels in the learner: paired with the scan ``lag`` scans before the one they
name (``Pairing(lag=...)``), learned by the majority of their neighbours (``Lineage``
with ``teacher="person"``), and rebuilt from the whole journal after a crash."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.learning import load_snapshot
from client.behaviour.teaching import PersonLearner
from client.labels import Pairing
from client.lineage import Lineage
from process.runtime import ProcessError
from protocol.messages import LabeledScan, Scan, TeacherAction

LABELS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def _scan(sid: int, x: float = 0.0) -> bytes:
    ranges = np.full(8, 1.0 + 0.01 * sid, np.float32)
    return Scan(ts=0.1 * sid, id=sid, ranges=ranges, pose=(x + 0.01 * sid, 0.0, 0.0)).encode()


def _label(sid: int, action: str = "fwd") -> bytes:
    return TeacherAction(scan_id=sid, action=action).encode()


def _paired(p: Pairing) -> list[tuple[int, int]]:
    """(scan id learned, scan id the label named) of every labeled scan ready."""
    out = []
    while (item := p.get(0.0)) is not None:
        out.append((item[0].id, item[1].scan_id))
    return out


def test_a_label_is_paired_with_the_scan_lag_scans_earlier():
    p = Pairing(scan_buffer=16, lag=3)
    for sid in range(10):
        p.on_scan(_scan(sid))
    p.on_label(_label(7))         # its scan arrived already
    p.on_label(_label(11))        # its scan arrives later
    p.on_scan(_scan(10))
    p.on_scan(_scan(11))
    p.on_label(_label(1))         # no scan 3 earlier than it: its own scan
    assert _paired(p) == [(4, 7), (8, 11), (1, 1)]
    assert p.stats["shifted"] == 2 and p.stats["unshifted"] == 1
    # the ranges learned are the earlier scan's
    p.on_label(_label(9))
    scan, act = p.get(0.0)
    assert scan.id == 6 and float(scan.ranges[0]) == pytest.approx(1.06)


def test_a_robot_put_elsewhere_in_between_keeps_the_labels_own_scan():
    p = Pairing(scan_buffer=16, lag=3)
    for sid in range(5):
        p.on_scan(_scan(sid))
    for sid in range(5, 8):
        p.on_scan(_scan(sid, x=5.0))  # set_pose between scans 4 and 5
    p.on_label(_label(6))             # scans 3..6 cross the jump
    p.on_label(_label(4))             # scans 1..4 do not
    assert _paired(p) == [(6, 6), (1, 4)]


def test_a_resent_label_is_shifted_when_its_scans_are_held_and_no_lag_pairs_as_named():
    p = Pairing(scan_buffer=4, lag=2)
    for sid in range(10):
        p.on_scan(_scan(sid))
    resend = LabeledScan(scan_id=9, action="rot-left", origin="o" * 16, seq=0,
                         ranges=np.ones(8, np.float32), yaw=0.0, ts=0.9)
    old = LabeledScan(scan_id=2, action="rot-left", origin="o" * 16, seq=1,
                      ranges=np.ones(8, np.float32), yaw=0.0, ts=0.2)
    p.on_labeled(resend.encode())
    p.on_labeled(old.encode())        # scans 0..2 no longer held: its own scan
    assert _paired(p) == [(7, 9), (2, 2)]
    plain = Pairing(scan_buffer=4)
    for sid in range(5):
        plain.on_scan(_scan(sid))
    plain.on_label(_label(4))
    assert _paired(plain) == [(4, 4)] and not plain.recent
    with pytest.raises(ValueError, match="lag"):
        Pairing(lag=-1)


def test_a_window_pairs_each_label_with_its_own_scan_and_the_scans_before():
    p = Pairing(scan_buffer=16, window=3)
    for sid in range(5):
        p.on_scan(_scan(sid))
    for sid in range(5, 9):
        p.on_scan(_scan(sid, x=5.0))  # set_pose between scans 4 and 5
    p.on_label(_label(3))             # scans 0..3: three before it
    p.on_label(_label(1))             # only scan 0 before it
    p.on_label(_label(6))             # the jump cuts it after scan 5
    got = []
    while (item := p.get(0.0)) is not None:
        got.append((item[0].id, [s.id for s in item[0].earlier]))
    assert got == [(3, [2, 1, 0]), (1, [0]), (6, [5])]
    assert p.stats["shifted"] == 3 and p.stats["unshifted"] == 0
    with pytest.raises(ValueError, match="window"):
        Pairing(lag=2, window=3)      # one or the other


def test_an_estimated_lag_is_journaled_and_a_restart_rebuilds_the_same_tree(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall", teacher="person", lag=None)  # --lag auto
    assert core.person and core.estimates and core.lag is None
    rng = np.random.default_rng(5)
    scans = [(rng.uniform(0.2, 3.0, 360).astype(np.float32), float(rng.uniform(-3, 3)))
             for _ in range(260)]
    for k in range(6, 260):
        earlier = [scans[k - i] for i in range(1, min(k, 6) + 1)]
        core.learn(k, 0.1 * k, *scans[k], LABELS[(k // 7) % 5], origin="p" * 16, seq=k,
                   earlier=earlier)
    core.snapshot()
    lag, agree = core.learner.estimated_lag, core.learner.lag_agreement
    assert len(agree) == 7 and 0 <= lag <= 6
    rec = next(iter(core.journal.records()))
    assert rec.earlier.shape == (6, 5)  # the features of the 6 scans before the label's own
    core.close()
    _clf, _f, _a, meta = load_snapshot(out)
    assert meta["learning"]["lag"] is None and meta["learning"]["estimated_lag"] == lag
    again = Lineage(out, features="wall")
    assert again.estimates and again.learner.estimated_lag == lag
    assert again.learner.lag_agreement == agree
    assert again.learner.classifier.tree_equal(core.learner.classifier)
    assert "the lag estimated" in again.describe()
    again.close()
    with pytest.raises(ProcessError, match="--lag must be 0..6"):
        Lineage(tmp_path / "n.rhbl", features="wall", teacher="person", lag=7)


def _feed(core: Lineage, n: int, seed: int, start_id: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for k in range(n):
        ranges = rng.uniform(0.2, 3.0, 360).astype(np.float32)
        core.learn(start_id + k, 0.1 * k, ranges, float(rng.uniform(-3, 3)),
                   LABELS[int(rng.integers(5))], origin="p" * 16, seq=start_id + k)


def test_a_persons_lineage_is_rebuilt_from_its_whole_journal(tmp_path):
    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall", teacher="person", lag=2)
    assert core.person and core.lag == 2 and isinstance(core.learner, PersonLearner)
    assert core.learner.background  # the live learner relearns beside (docs/teaching.md)
    _feed(core, 60, seed=0)
    core.snapshot()
    _feed(core, 30, seed=1, start_id=60)
    core.journal.sync()
    _clf, _f, _a, meta = load_snapshot(out)
    assert meta["learning"]["rule"] == "person" and meta["learning"]["lag"] == 2
    # "crash": the lineage keeps its rule (the default teacher is the script) and its lag
    again = Lineage(out, features="wall")
    assert again.person and again.lag == 2 and again.learner.background
    assert again.replayed == 90 and again.applied == 90 and len(again.labels) == 90
    ref = Lineage(tmp_path / "ref.rhbl", features="wall", teacher="person", lag=2)
    _feed(ref, 60, seed=0)
    _feed(ref, 30, seed=1, start_id=60)
    assert again.learner.classifier.tree_equal(ref.learner.classifier)
    assert again.learner.nodes == ref.learner.nodes > 1
    assert "a person's labels" in again.describe()
    for c in (core, again, ref):
        c.close()
    with pytest.raises(ProcessError, match="fold-journal"):
        Lineage(out, fold_journal=True)
    with pytest.raises(ProcessError, match="cannot --resume"):
        Lineage(tmp_path / "r.rhbl", resume=str(out), teacher="person")
    with pytest.raises(ProcessError, match="fold-journal"):
        Lineage(tmp_path / "f.rhbl", features="wall", teacher="person", fold_journal=True)
    assert not (tmp_path / "f.rhbl.journal").exists()  # refused before anything was written
    with pytest.raises(ProcessError, match="--lag"):
        Lineage(tmp_path / "n.rhbl", features="wall", teacher="person", lag=-1)


def test_a_new_lineage_keeps_its_rule_and_a_behaviours_guard_off(tmp_path):
    """The rule (``client.behaviour.rule``) is written whole into the journal's header and the
    snapshot; a recovered lineage learns by the header's rule; a behaviour that turns the
    guard off gives trees whose rule says so (the controller reads it from the snapshot)."""
    from client.behaviour.rule import PERSON, LearningRule

    out = tmp_path / "t.rhbl"
    core = Lineage(out, features="wall", teacher="person", guard=False)
    assert core.learner.rule == PERSON.replace(guard=False) and "sided vote" in core.describe()
    _feed(core, 60, seed=0)
    core.snapshot()
    core.close()
    rule = LearningRule.of(load_snapshot(out)[3])
    assert rule == core.learner.rule and rule.guard.on is False
    again = Lineage(out, features="wall")  # the journal's header keeps it
    assert again.learner.rule == rule
    ref = Lineage(tmp_path / "ref.rhbl", features="wall", teacher="person")
    _feed(ref, 60, seed=0)
    assert again.learner.classifier.tree_equal(ref.learner.classifier)  # the guard: not learning
    assert LearningRule.of(ref.metadata()).guard.on is True
    for c in (again, ref):
        c.close()
    script = Lineage(tmp_path / "s.rhbl", features="wall", teacher="script", guard=False)
    assert script.learner.rule.name == "script" and script.learner.rule.guard.on is False
    script.close()


def test_the_majority_outvotes_a_wrong_key(tmp_path):
    cores = {"person": Lineage(tmp_path / "t.rhbl", features="wall", teacher="person")}
    rng = np.random.default_rng(3)
    base = rng.uniform(1.0, 2.0, 360).astype(np.float32)
    for k in range(40):
        label = "rot-left" if k == 20 else "fwd"  # one wrong key among its neighbours
        ranges = (base + rng.normal(0, 0.05, 360)).astype(np.float32)
        for core in cores.values():
            core.learn(k, 0.1 * k, ranges, 0.0, label)
    X = cores["person"].learner.labelled()[0][:, 0]  # each label's own scan
    assert set(map(str, cores["person"].learner.classifier.predict(X))) == {"fwd"}
    assert len(cores["person"].journal) == 40  # the wrong key is kept as given, outvoted
    for core in cores.values():
        core.close()


@pytest.mark.parametrize(("argv", "needle"), [
    (["learner", "--features", "wall", "--teacher", "person", "--lag", "-1", "--out", "t.rhbl"],
     "--lag must be 'auto' or an integer 0..6"),
    (["controller", "--tree", "t.rhbl", "--guard-hold", "-2"],
     "--guard-hold must be an integer >= 0"),
])
def test_bad_lag_or_guard_hold_is_refused_before_connecting(tmp_path, argv, needle):
    import subprocess
    import sys

    if argv[0] == "controller":  # an input file must exist for the parse to reach --guard-hold
        (tmp_path / "t.rhbl").write_bytes(b"")
    proc = subprocess.run([sys.executable, "-m", "lab.cli", *argv, "--connect", "tcp/127.0.0.1:1"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert needle in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "t.rhbl.journal").exists()
