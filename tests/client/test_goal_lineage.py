"""A learner's lineage of a behaviour with goals (``client.lineage`` with ``goals``): each label
is journaled with the goal pursued, the goal reached and what the fiducial finder saw; the
snapshot holds both trees (a goal snapshot, ``client.behaviour.goals.load_policy``); a restart
rebuilds the same trees from the journal; a label that names no goal, or a beacon the goals do
not name, is refused and nothing is written; a goal snapshot is extended by a goal learner."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.goals import DONE, GoalLearner, GoalPolicy, GoalStep, load_policy
from client.journal import Journal, journal_path
from client.lineage import Lineage, Refused
from lab.behaviours import get

B = get("red-green")
ACTIONS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def _ranges(k: int) -> np.ndarray:
    return np.random.default_rng(k).uniform(0.3, 5.0, 360).astype(np.float32)


def _step(k: int) -> GoalStep:
    """Goal 1 for the first half, goal 2 after; reached marks near each beacon now and then."""
    goal = 1 if k < 40 else 2
    near = k % 10 == 9
    reached = goal if near else None
    if k == 39:  # the step goal 1 is reached at: the label is for goal 2 from then on
        goal, reached = 2, 1
    rng = np.random.default_rng(1000 + k)
    seen = [(goal, 0.5 if near else float(rng.uniform(1.0, 5.0)), float(rng.uniform(-1, 1)))]
    if k % 3 == 0:
        seen.append((3 - goal, float(rng.uniform(1.0, 5.0)), 0.2))
    return GoalStep.of(goal, reached, seen)


def _lineage(out, **kw) -> Lineage:
    return Lineage(out, features=B.perception or B.features, task=B.name, goals=B.goals, **kw)


def _teach(core: Lineage, n: int = 80) -> None:
    for k in range(n):
        assert core.learn(k, 0.1 * k, _ranges(k), 0.0, ACTIONS[k % 5], "s1", k,
                          step=_step(k)) is not None


def test_a_goal_lineage_journals_each_labels_goal_and_a_restart_rebuilds_both_trees(tmp_path):
    out = tmp_path / "rg.rhbl"
    core = _lineage(out)
    assert isinstance(core.learner, GoalLearner)
    _teach(core, 50)
    core.snapshot()
    _teach_more = [(k, _step(k)) for k in range(50, 80)]
    for k, step in _teach_more:  # after the snapshot: only in the journal
        core.learn(k, 0.1 * k, _ranges(k), 0.0, ACTIONS[k % 5], "s1", k, step=step)
    want = core.learner.policy()
    core.close()
    # the journal holds every label's goal, the goal reached and what was seen
    with Journal.open(journal_path(out)) as j:
        recs = list(j.records())
    assert len(recs) == 80 and all(r.goal in (1, 2) for r in recs)
    assert [r.reached for r in recs if r.reached is not None] == \
        [_step(k).reached for k in range(80) if _step(k).reached is not None]
    assert recs[39].goal == 2 and recs[39].reached == 1
    assert np.allclose(recs[3].seen, _step(3).rows())
    # a restart (snapshot + the journal after it) has the same two trees
    again = _lineage(out)
    got = again.learner.policy()
    assert got.classifier.tree_equal(want.classifier)
    assert got.completion.tree_equal(want.completion)
    assert DONE in got.completion.classes_ and again.learner.marks == want.metadata[
        "provenance"]["marks"] == 8
    again.snapshot()
    again.close()
    # the snapshot is a goal snapshot: what rhbl controller drives
    policy = load_policy(out)
    assert isinstance(policy, GoalPolicy) and policy.goals == B.goals
    assert policy.completion.tree_equal(want.completion)


def test_a_label_without_its_goal_or_with_another_beacon_is_refused_and_not_written(tmp_path):
    out = tmp_path / "rg.rhbl"
    core = _lineage(out)
    _teach(core, 3)
    with pytest.raises(Refused, match="names no goal") as exc:
        core.learn(10, 1.0, _ranges(10), 0.0, "fwd", "s1", 10)
    assert exc.value.kind == "goal"
    with pytest.raises(Refused, match="beacon 7 is not one of the goals' beacons"):
        core.learn(11, 1.1, _ranges(11), 0.0, "fwd", "s1", 11,
                   step=GoalStep.of(7, None, [(7, 2.0, 0.0)]))
    with pytest.raises(Refused, match="beacon 99 is not one of the goals' beacons"):
        core.learn(12, 1.2, _ranges(12), 0.0, "fwd", "s1", 12,
                   step=GoalStep.of(99, 1, [(1, 0.4, 0.0)]))  # reached a goal, pursues another
    assert not any(core.holds("s1", q) for q in (10, 11, 12))
    core.close()
    with Journal.open(journal_path(out)) as j:
        assert len(j) == 3
    # the lineage learns these goals: a learner told other goals refuses it
    from client.behaviour.goals import parse_goals
    from process.runtime import ProcessError

    with pytest.raises(ProcessError, match=r"its tree learns the goals \[1, 2\], not"):
        Lineage(out, features=B.perception or B.features, task=B.name,
                goals=parse_goals({"beacons": [2, 1]}))


def test_a_plain_lineage_learns_a_goal_label_as_a_label(tmp_path):
    """A tree without goals (wall following) given a goal teacher's label learns its action
    from the scan alone: the goal fields are for lineages that have goals."""
    core = Lineage(tmp_path / "w.rhbl", features="wall")
    assert core.learn(0, 0.0, _ranges(0), 0.0, "fwd", "s1", 0, step=_step(0))
    with Journal.open(journal_path(tmp_path / "w.rhbl")) as j:
        (rec,) = list(j.records())
    assert rec.goal is None
    core.close()


def test_a_goal_snapshot_is_extended_by_a_goal_learner(tmp_path):
    parent = tmp_path / "rg.rhbl"
    core = _lineage(parent)
    _teach(core, 40)
    core.snapshot()
    core.close()
    child = tmp_path / "more.rhbl"
    ext = Lineage(child, resume=str(parent), goals=B.goals)
    assert isinstance(ext.learner, GoalLearner)
    assert ext.learner.completion.tree_equal(load_policy(parent).completion)
    ext.learn(100, 9.0, _ranges(100), 0.0, "rot-left", "s2", 0, step=_step(45))
    ext.snapshot()
    ext.close()
    p = load_policy(child)
    assert isinstance(p, GoalPolicy) and p.metadata["provenance"]["parent"] == str(parent)


def test_a_persons_goal_lineage_learns_by_the_person_rule_and_a_restart_rebuilds_it(tmp_path):
    """A person's labels of a behaviour with goals are learned by the person rule (one rule for
    a person's labels whatever the behaviour): every label kept, each voted by its nearest, so
    one wrong key among many is outvoted; the completion tree learns the marks; with the lag
    estimated each label is journaled with the scans shown before it, as vectors with its goal's
    beacon, and a restart rebuilds the same trees from the journal."""
    from client.behaviour.goals import PersonGoalLearner

    out = tmp_path / "rg.rhbl"
    core = _lineage(out, teacher="auto")  # the rule chosen by the first label's source
    assert core.undecided
    earlier = [(_ranges(1000 + j), 0.0) for j in range(3)]
    for k in range(80):
        label = "rot-left" if k == 79 else "fwd"  # one wrong key among 80, the last
        core.learn(k, 0.1 * k, _ranges(k), 0.0, label, "s1", k, earlier=earlier,
                   source="console", step=_step(k))
    # a person at the console: the person rule, the lag estimated (the scans before each kept)
    assert isinstance(core.learner, PersonGoalLearner) and core.estimates
    want = core.learner.policy()
    x = core.learner.vector(_ranges(79), 0.0, _step(79))
    assert want.classifier.predict_one(x) == "fwd"  # outvoted
    assert want.metadata["learning"]["rule"] == "person"
    assert want.metadata["provenance"]["marks"] == 8 and DONE in want.completion.classes_
    with Journal.open(journal_path(out)) as j:
        rec = list(j.records())[5]
    assert rec.goal == _step(5).goal and rec.earlier.shape == (3, len(x))
    assert np.allclose(rec.earlier[0], core.learner.vector(_ranges(1000), 0.0, _step(5)))
    core.close()
    again = _lineage(out, teacher="person")
    assert isinstance(again.learner, PersonGoalLearner)
    got = again.learner.policy()
    assert got.classifier.tree_equal(want.classifier)
    assert got.completion.tree_equal(want.completion)
    again.snapshot()
    again.close()
    policy = load_policy(out)
    assert isinstance(policy, GoalPolicy) and policy.metadata["learning"]["rule"] == "person"
    assert policy.classifier.tree_equal(want.classifier)


def test_the_scripted_rule_learns_the_wrong_key_a_person_rule_outvotes(tmp_path):
    """The same labels from the scripted teacher: each learned as it arrives, the wrong key
    carves its sphere (what the person rule is for)."""
    core = _lineage(tmp_path / "rg.rhbl")
    assert type(core.learner) is GoalLearner
    for k in range(80):
        core.learn(k, 0.1 * k, _ranges(k), 0.0, "rot-left" if k == 79 else "fwd", "s1", k,
                   step=_step(k))
    x = core.learner.vector(_ranges(79), 0.0, _step(79))
    assert core.learner.policy().classifier.predict_one(x) == "rot-left"
    core.close()
