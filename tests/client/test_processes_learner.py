"""The learner's core without zenoh: journal first, snapshots with provenance, exact recovery."""

from __future__ import annotations

import numpy as np
import pytest

from client._process import ProcessError
from client.behaviour.learning import load_snapshot
from client.journal import journal_path
from client.learner import LearnerCore

LABELS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def _feed(core: LearnerCore, n: int, seed: int, start_id: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for k in range(n):
        ranges = rng.uniform(0.2, 3.0, 360).astype(np.float32)
        core.learn(start_id + k, 0.1 * k, ranges, float(rng.uniform(-3, 3)),
                   LABELS[int(rng.integers(5))])


def test_snapshot_provenance_and_recovery_after_a_crash(tmp_path):
    out = tmp_path / "t.rhbl"
    core = LearnerCore(out, features="wall")
    _feed(core, 40, seed=0)
    core.snapshot()
    _feed(core, 25, seed=1, start_id=40)  # not in any snapshot: only in the journal
    core.journal.sync()
    # "crash": no close, no final snapshot; a new core rebuilds from snapshot + journal
    again = LearnerCore(out, features="wall")
    assert again.replayed == 25 and again.applied == 65
    ref = LearnerCore(tmp_path / "ref.rhbl", features="wall")
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
    core = LearnerCore(out, features="maze")
    _feed(core, 30, seed=2)
    core.close()
    assert not out.exists()
    again = LearnerCore(out)  # features come from the journal's header
    assert again.replayed == 30 and again.features.heading == "lr"
    again.close()


def test_resume_starts_a_new_lineage_and_guards_paths(tmp_path):
    base = tmp_path / "base.rhbl"
    core = LearnerCore(base, features="wall")
    _feed(core, 30, seed=3)
    core.snapshot()
    core.close()
    ext = LearnerCore(tmp_path / "ext.rhbl", resume=str(base))
    _feed(ext, 10, seed=4)
    ext.snapshot()
    meta = load_snapshot(ext.out)[3]
    assert meta["provenance"]["parent"] == str(base.resolve())
    assert meta["provenance"]["vectors"] == 40 and meta["provenance"]["labeled"] == 10
    assert ext.journal.lineage != LearnerCore(base).journal.lineage
    ext.close()
    with pytest.raises(ProcessError, match="other features"):
        LearnerCore(tmp_path / "x.rhbl", resume=str(base), features="maze")
    with pytest.raises(ProcessError, match="choose another --out"):
        LearnerCore(base, resume=str(tmp_path / "ext.rhbl"))
    with pytest.raises(ProcessError, match="cannot continue"):
        LearnerCore(base, features="maze")
    (tmp_path / "plain.rhbl").write_bytes(base.read_bytes())
    with pytest.raises(ProcessError, match="has no journal"):
        LearnerCore(tmp_path / "plain.rhbl", features="wall")


def test_snapshot_ahead_of_its_journal_is_an_error(tmp_path):
    out = tmp_path / "t.rhbl"
    core = LearnerCore(out, features="wall")
    _feed(core, 20, seed=5)
    core.snapshot()
    core.close()
    jp = journal_path(out)
    data = jp.read_bytes()
    jp.write_bytes(data[: len(data) // 2])  # lose records (more than a torn tail)
    with pytest.raises(ProcessError, match="lost records"):
        LearnerCore(out)


def test_a_new_tree_needs_features(tmp_path):
    with pytest.raises(ProcessError, match="needs --features"):
        LearnerCore(tmp_path / "t.rhbl")
