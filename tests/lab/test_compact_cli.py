"""``rhbl compact``: an existing tree compacted on its learner journal (or an .npz of X, y)."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.policies import ReactiveFollower
from client.journal import Journal, journal_path
from lab.cli import main
from lab.compact import load_data


def _tree_with_journal(tmp_path, rows=400):
    """A learner trained on random scans labelled by the reactive teacher, its snapshot and the
    journal the learner process would have written."""
    rng = np.random.default_rng(3)
    teacher = ReactiveFollower()
    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following",
                                   spawn="winner", record=True)
    out = tmp_path / "t.rhbl"
    j = Journal.create(journal_path(out))
    for i in range(rows):
        ranges = np.repeat(rng.uniform(0.2, 2.5, 24), 15).astype(np.float32)
        label = teacher.act(ranges)
        x = learner.features.extract(ranges, 0.0)
        j.append(i, float(i), label, ranges, 0.0, x.astype(np.float32))
        learner.observe(ranges, 0.0, label)
    j.close()
    learner.save(out)
    return out, learner


def test_compact_a_tree_on_its_journal(tmp_path, capsys):
    tree, learner = _tree_with_journal(tmp_path)
    small = tmp_path / "small.rhbl"
    assert main(["compact", "--tree", str(tree), "--out", str(small)]) == 0
    out = capsys.readouterr().out
    assert "exact:" in out and "wrote" in out
    X, y = learner.recorded()
    before, after = TreePolicy.load(tree), TreePolicy.load(small)
    assert np.array_equal(after.classifier.predict(X), before.classifier.predict(X))
    assert after.classifier.node_count_ < before.classifier.node_count_
    rec = after.metadata["compaction"][-1]
    assert rec["method"] == "exact" and rec["data"]["source"] == "t.rhbl.journal"
    assert rec["data"]["rows"] == len(y)
    # the journal's vectors are exactly the learner's
    Xj, yj = load_data(journal_path(tree), learner.features)
    assert np.array_equal(Xj, X) and list(yj) == list(y)


def test_prune_on_an_npz_to_a_size(tmp_path, capsys):
    tree, learner = _tree_with_journal(tmp_path)
    X, y = learner.recorded()
    np.savez(tmp_path / "d.npz", X=X, y=y)
    small = tmp_path / "small.rhbl"
    assert main(["compact", "--tree", str(tree), "--out", str(small), "--data",
                 str(tmp_path / "d.npz"), "--method", "prune", "--class-weight", "balanced",
                 "--max-nodes", "10"]) == 0
    clf = TreePolicy.load(small).classifier
    assert clf.node_count_ <= 10
    settings = clf.metadata["compaction"][-1]["settings"]
    assert settings["max_nodes"] == 10 and settings["class_weight"] == "balanced"


def test_bad_data_is_named(tmp_path, capsys):
    tree, _ = _tree_with_journal(tmp_path, rows=20)
    journal_path(tree).unlink()
    assert main(["compact", "--tree", str(tree), "--out", str(tmp_path / "o.rhbl")]) == 2
    assert "no data to compact" in capsys.readouterr().err
    np.savez(tmp_path / "bad.npz", X=np.zeros((3, 2)), y=np.array(["fwd"] * 3))
    assert main(["compact", "--tree", str(tree), "--out", str(tmp_path / "o.rhbl"), "--data",
                 str(tmp_path / "bad.npz")]) == 2
    assert "bad.npz" in capsys.readouterr().err


def _lineage(tmp_path, rows=200):
    """A learner's tree (journaled), then a tree extending it (rhbl learner --resume) that
    learned nothing more: its own journal is empty."""
    from client.lineage import Lineage

    rng = np.random.default_rng(5)
    teacher = ReactiveFollower()
    base = Lineage(tmp_path / "base.rhbl", features="wall")
    for i in range(rows):
        ranges = np.repeat(rng.uniform(0.2, 2.5, 24), 15).astype(np.float32)
        base.learn(i, 0.1 * i, ranges, 0.0, teacher.act(ranges))
    base.snapshot()
    base.close()
    ext = Lineage(tmp_path / "resumed.rhbl", resume=str(tmp_path / "base.rhbl"))
    ext.snapshot()
    ext.close()
    return tmp_path / "base.rhbl", tmp_path / "resumed.rhbl"


def test_a_resumed_tree_is_compacted_on_its_whole_lineage(tmp_path, capsys):
    """It printed "776 -> 1 nodes ... agreement nan%" and destroyed the tree: it compacted on
    the new lineage's empty journal. Now the parent's journal (up to the fork) is data too."""
    base, resumed = _lineage(tmp_path)
    small = tmp_path / "small.rhbl"
    assert main(["compact", "--tree", str(resumed), "--out", str(small)]) == 0
    out = capsys.readouterr().out
    before, after = TreePolicy.load(resumed).classifier, TreePolicy.load(small).classifier
    X, y = load_data(journal_path(base), TreePolicy.load(base).features)
    agree = float(np.mean(before.predict(X) == y))  # the tree's own, kept by "exact"
    assert f"200 labelled vectors from 2 file(s), agreement with their labels {agree:.1%}" in out
    assert np.array_equal(after.predict(X), before.predict(X))
    assert 1 < after.node_count_ <= before.node_count_
    # the parent's journal gone: refused, saying which data it needs
    journal_path(base).unlink()
    assert main(["compact", "--tree", str(resumed), "--out", str(small)]) == 2
    err = capsys.readouterr().err
    assert f"extends {base.resolve()}" in err and "base.rhbl.journal" in err, err


def test_empty_data_is_refused(tmp_path, capsys):
    tree, learner = _tree_with_journal(tmp_path, rows=5)
    empty = Journal.create(tmp_path / "empty.journal")
    empty.close()
    assert main(["compact", "--tree", str(tree), "--out", str(tmp_path / "o.rhbl"), "--data",
                 str(tmp_path / "empty.journal")]) == 2
    assert "no labelled vectors in" in capsys.readouterr().err


def test_a_tree_trained_from_a_recording_is_compacted_on_the_recording(tmp_path, capsys):
    """``--data run.mcap`` printed a traceback (exit 1) and a tree trained from a recording
    could not be compacted at all; ``--rounds`` with ``--from-recording`` was silently
    ignored. Recordings are a data source, and a flag that cannot apply is a named error."""
    rec, tree = tmp_path / "train.mcap", tmp_path / "r.rhbl"
    assert main(["train", "--world", "room", "--seconds", "20", "--rounds", "0", "--out",
                 str(tmp_path / "sim.rhbl"), "--record", str(rec)]) == 0
    assert main(["train", "--from-recording", str(rec), "--out", str(tree)]) == 0
    capsys.readouterr()
    for data in ([], ["--data", str(rec)]):  # its recording, found or given
        assert main(["compact", "--tree", str(tree), "--out", str(tmp_path / "s.rhbl"),
                     *data]) == 0
        out = capsys.readouterr().out
        assert "200 labelled vectors from 1 file(s)" in out, out
    data = TreePolicy.load(tmp_path / "s.rhbl").metadata["compaction"][-1]["data"]
    assert data["source"] == "train.mcap" and data["rows"] == 200  # 20 s at 10 Hz
    for flags, named in ((["--rounds", "3"], "--rounds"),
                         (["--seconds", "9", "--seed", "2"], "--seed, --seconds"),
                         (["--world", "room"], "--world"),
                         (["--compact-rounds"], "--compact-rounds")):
        assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "x.rhbl"),
                     *flags]) == 2
        err = capsys.readouterr().err
        assert f"{named} do" in err and "not apply to --from-recording" in err, err
    # --compact applies: the retrained tree compacted on the recording's vectors
    assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "c.rhbl"),
                 "--compact", "exact"]) == 0
    assert TreePolicy.load(tmp_path / "c.rhbl").metadata["compaction"][-1]["method"] == "exact"


def test_a_recording_retrained_as_a_persons_labels(tmp_path, capsys):
    """``rhbl train --from-recording --teacher person --lag 3``: the labels paired with the
    scan three earlier and the tree built by the neighbours' vote, as the live learner does;
    the two flags refused where they cannot apply."""
    from client.behaviour.teaching import PersonLearner
    from lab.retrain import labeled_scans

    rec, tree = tmp_path / "train.mcap", tmp_path / "p.rhbl"
    assert main(["train", "--world", "room", "--seconds", "20", "--rounds", "0", "--out",
                 str(tmp_path / "sim.rhbl"), "--record", str(rec)]) == 0
    assert main(["train", "--from-recording", str(rec), "--out", str(tree), "--teacher",
                 "person", "--lag", "3"]) == 0
    assert "200 labeled scans" in capsys.readouterr().out
    meta = TreePolicy.load(tree).metadata
    assert meta["learning"]["rule"] == "person" and meta["learning"]["lag"] == 3
    stats: dict = {}
    pairs = [(s.id, a.scan_id) for _r, s, a in labeled_scans(rec, stats=stats, lag=3)]
    assert sum(s == named - 3 for s, named in pairs) >= len(pairs) - 3
    ref = PersonLearner(TreePolicy.load(tree).features, lag=3, task="wall-following")
    for _r, s, a in labeled_scans(rec, lag=3):
        ref.observe(s.ranges, float(s.pose[2]), a.action)
    assert ref.classifier.tree_equal(TreePolicy.load(tree).classifier)
    # --lag auto: each label with the scans before it, the lag estimated from them
    auto = tmp_path / "a.rhbl"
    assert main(["train", "--from-recording", str(rec), "--out", str(auto), "--teacher",
                 "person", "--lag", "auto"]) == 0
    learning = TreePolicy.load(auto).metadata["learning"]
    assert learning["lag"] is None and 0 <= learning["estimated_lag"] <= 6
    windows = [(s.id, [e.id for e in s.earlier]) for _r, s, _a in labeled_scans(rec, window=6)]
    assert sum(ids == list(range(sid - 1, sid - 7, -1)) for sid, ids in windows) >= len(windows) - 6
    with pytest.raises(SystemExit) as bad:
        main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "y.rhbl"),
              "--teacher", "person", "--lag", "soon"])
    assert bad.value.code == 2 and "'auto' or an integer 0..6" in capsys.readouterr().err
    # one vote, the rule's: no --vote
    with pytest.raises(SystemExit) as bad:
        main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "y.rhbl"),
              "--vote", "median"])
    assert bad.value.code == 2 and "unrecognized arguments: --vote" in capsys.readouterr().err
    # --lag is the person rule's: refused for the script rule
    assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "s.rhbl"),
                 "--teacher", "script", "--lag", "2"]) == 2
    assert "--lag is the person rule's" in capsys.readouterr().err
    assert not (tmp_path / "s.rhbl").exists()
    for flags in (["--world", "room", "--teacher", "person"], ["--world", "room", "--lag", "2"]):
        assert main(["train", "--out", str(tmp_path / "x.rhbl"), *flags]) == 2
        assert "go with --from-recording" in capsys.readouterr().err
    assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "x.rhbl"),
                 "--teacher", "person", "--compact", "exact"]) == 2
    assert "no --compact" in capsys.readouterr().err
    # the margin is the script rule's, and compaction keeps the paper's rule: both named
    assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "x.rhbl"),
                 "--teacher", "person", "--radius", "margin"]) == 2
    assert "--radius margin is the script rule's" in capsys.readouterr().err
    assert main(["train", "--from-recording", str(rec), "--out", str(tmp_path / "x.rhbl"),
                 "--teacher", "script", "--radius", "margin", "--compact", "exact"]) == 2
    assert "not with --radius margin" in capsys.readouterr().err
    assert not (tmp_path / "x.rhbl").exists()
