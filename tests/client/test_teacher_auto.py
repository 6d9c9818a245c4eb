"""``--teacher auto`` (the learner's default): a new lineage takes the person rule when its first
label comes from a person (``source`` ``console`` or ``keyboard``), the scripted rule
otherwise; the journal's header keeps the rule, ``--teacher script|person`` still force it, and
``rhbl train --from-recording`` chooses alike (the real processes: tests/integration/
test_auto_rule_processes.py)."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.learning import load_snapshot
from client.behaviour.rule import PERSON
from client.behaviour.teaching import PersonLearner
from client.journal import Journal, journal_path
from client.labels import PERSON_SOURCES, SOURCE, Pairing, by_person
from client.lineage import Lineage
from client.recording.mcap_file import RecordingWriter
from lab.retrain import first_label_source, retrain
from protocol import keys
from protocol.messages import Scan, TeacherAction, Withdrawal

LABELS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]
MAX_LAG = PERSON.alignment.max_lag


def _ranges(rng) -> np.ndarray:
    return rng.uniform(0.2, 3.0, 360).astype(np.float32)


def test_sources_of_people_and_of_the_scripted_teacher():
    assert set(PERSON_SOURCES) == {"console", "keyboard"}
    assert all(by_person(s) for s in PERSON_SOURCES)
    assert not any(by_person(s) for s in (SOURCE, "", None, "Console", "teacher-2"))


def test_the_pairing_shifts_a_persons_labels_only():
    p = Pairing(scan_buffer=16, lag_of=lambda a: (3, 0) if by_person(a.source) else (0, 0))
    for sid in range(10):
        p.on_scan(Scan(ts=0.1 * sid, id=sid, ranges=np.full(8, 1.0, np.float32),
                       pose=(0.01 * sid, 0.0, 0.0)).encode())
    p.on_label(TeacherAction(scan_id=8, action="fwd", source="console").encode())
    p.on_label(TeacherAction(scan_id=9, action="fwd", source="teacher").encode())
    got = [(scan.id, act.scan_id) for scan, act in iter(lambda: p.get(0.0), None)]
    assert got == [(5, 8), (9, 9)]
    p.settle(0, 0)  # the learner chose the scripted rule: no lag, no recent scans kept
    assert p.recent == {} and p.lag == 0
    p.on_scan(Scan(ts=1.0, id=10, ranges=np.full(8, 1.0, np.float32)).encode())
    p.on_label(TeacherAction(scan_id=10, action="fwd", source="console").encode())
    assert p.get(0.0)[0].id == 10 and p.recent == {}


def _core(tmp_path, name: str = "t", **kw) -> Lineage:
    return Lineage(tmp_path / f"{name}.rhbl", features="wall", teacher="auto", **kw)


@pytest.mark.parametrize(("source", "person"), [("console", True), ("keyboard", True),
                                                 ("teacher", False), ("", False)])
def test_the_first_label_chooses_the_rule_and_the_journal_keeps_it(tmp_path, source, person):
    core = _core(tmp_path)
    assert core.undecided and not journal_path(core.out).exists()
    assert "chosen by the first label" in core.describe()
    # a person's label would carry the scans before it (the lag estimated: --lag auto)
    assert core.lag_for("console") == (0, MAX_LAG) and core.lag_for("teacher") == (0, 0)
    rng = np.random.default_rng(0)
    for k in range(30):
        core.learn(k, 0.1 * k, _ranges(rng), 0.0, LABELS[k % 5], origin="o" * 16, seq=k,
                   source=source if k == 0 else "teacher")  # the first label decides
    assert not core.undecided and core.person is person
    assert core.estimates is person and core.lag_for("teacher") == core.pairing()
    assert core.pairing() == ((0, MAX_LAG) if person else (0, 0))
    rule = (Journal.open(core.jpath).header["meta"].get("learning") or {}).get("rule")
    assert (rule == "person") is person
    core.snapshot()
    core.close()
    assert ((load_snapshot(core.out)[3].get("learning") or {}).get("rule") == "person") is person
    # a restart keeps the lineage's rule, whatever --teacher says now
    for teacher in ("auto", "script"):
        again = Lineage(core.out, features="wall", teacher=teacher)
        assert again.person is person and len(again.journal) == 30
        again.close()


def test_a_fixed_lag_shifts_a_persons_first_label(tmp_path):
    core = _core(tmp_path, lag=2)
    assert core.lag_for("keyboard") == (2, 0) and core.lag_for("teacher") == (0, 0)
    core.learn(0, 0.0, _ranges(np.random.default_rng(4)), 0.0, "fwd", source="keyboard")
    assert core.person and core.lag == 2 and core.pairing() == (2, 0)
    core.close()


def test_forced_rules_and_the_cases_auto_cannot_choose_the_person_rule(tmp_path):
    forced = Lineage(tmp_path / "p.rhbl", features="wall", teacher="person")
    assert not forced.undecided and forced.person and journal_path(forced.out).exists()
    forced.close()
    script = Lineage(tmp_path / "s.rhbl", features="wall", teacher="script")
    assert not script.undecided and not script.person
    rng = np.random.default_rng(1)
    script.learn(0, 0.0, _ranges(rng), 0.0, "fwd", source="console")  # forced: stays script
    assert not script.person
    script.snapshot()
    script.close()
    # auto cannot take the person rule with --fold-journal or --resume: the scripted one
    for kw in ({"fold_journal": True}, {"resume": str(tmp_path / "s.rhbl")}):
        name = "f" if "fold_journal" in kw else "r"
        core = Lineage(tmp_path / f"{name}.rhbl", features="wall", teacher="auto", **kw)
        assert not core.undecided and not core.person
        core.learn(0, 0.0, _ranges(rng), 0.0, "fwd", source="console")
        assert not core.person
        core.close()


def test_a_withdrawal_before_the_first_label_is_journaled_with_the_lineage(tmp_path):
    core = _core(tmp_path)
    w = Withdrawal(origin="o" * 16, id=0, first=0, upto=2, ts=1.0, reason="undo")
    assert core.withdraw(w) is False and core.undecided
    assert core.withdraw(w) is None  # held already
    rng = np.random.default_rng(2)
    assert core.learn(0, 0.0, _ranges(rng), 0.0, "fwd", origin="o" * 16, seq=0,
                      source="console") is None  # withdrawn: never journaled
    core.learn(5, 0.5, _ranges(rng), 0.0, "fwd", origin="o" * 16, seq=2, source="console")
    assert core.person
    recs = list(Journal.open(core.jpath).records())
    assert [type(r).__name__ for r in recs] == ["JournalWithdrawal", "JournalRecord"]
    core.close()


def _recording(path, source: str, n: int = 60) -> None:
    rng = np.random.default_rng(3)
    with RecordingWriter(path, viewer=False) as w:
        for k in range(n):
            t = 1_000_000_000 + k * 100_000_000
            w.write(keys.scan_key("r0"), Scan(ts=0.1 * k, id=k, ranges=_ranges(rng),
                                              pose=(0.01 * k, 0.0, 0.0)).encode(), t)
            w.write(keys.teacher_action_key("r0"), TeacherAction(
                scan_id=k, action=LABELS[k % 5], source=source, ts=0.1 * k).encode(), t + 1000)


@pytest.mark.parametrize(("source", "rule"), [("console", "person"), ("teacher", "script")])
def test_retraining_from_a_recording_chooses_alike(tmp_path, source, rule):
    rec = tmp_path / "r.mcap"
    _recording(rec, source)
    assert first_label_source([rec]) == source
    learner, stats = retrain([rec], features="wall")
    assert stats["rule"].startswith(rule) and isinstance(learner, PersonLearner) is (rule == "person")
    forced, _ = retrain([rec], features="wall", teacher=rule)
    assert learner.classifier.tree_equal(forced.classifier)
    other, _ = retrain([rec], features="wall",
                       teacher="script" if rule == "person" else "person")
    assert isinstance(other, PersonLearner) is (rule != "person")
