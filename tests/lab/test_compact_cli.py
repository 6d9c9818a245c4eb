"""``rhbl compact``: an existing tree compacted on its learner journal (or an .npz of X, y)."""

from __future__ import annotations

import numpy as np

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
