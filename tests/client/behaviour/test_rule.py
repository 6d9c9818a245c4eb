"""The learning rule: one object, chosen in one place, stored in the snapshot and read back."""

import dataclasses

import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.learning import DemonstrationLearner
from client.behaviour.rule import (
    PERSON,
    SCRIPT,
    GuardSettings,
    LearningRule,
    NeighbourEditing,
    ReactionAlignment,
    rule_for,
)
from client.behaviour.teaching import PersonLearner


def test_the_rules_are_chosen_in_one_place():
    assert rule_for("person") is PERSON and rule_for("script") is SCRIPT
    assert PERSON.person and not SCRIPT.person
    assert PERSON.guard.clearance > 0 and SCRIPT.guard.clearance == 0  # the path check
    assert PERSON.guard.on and SCRIPT.guard.on
    with pytest.raises(ValueError, match="teacher must be 'person' or 'script'"):
        rule_for("robot")


def test_a_rule_goes_into_the_metadata_and_comes_back_whole():
    rule = PERSON.replace(lag=4, guard=False, seed=7)
    rule = rule.replace(editing=dataclasses.replace(rule.editing, k=20, copies=2))
    meta = {"learning": rule.to_dict(), "tree_params": dict(rule.tree)}
    assert LearningRule.of(meta) == rule
    script = SCRIPT.replace(stride=3, min_delta=0.1, tree={"spawn": "all"})
    assert LearningRule.of({"learning": script.to_dict(), "tree_params": {"spawn": "all"}}) \
        == script
    # what the learners write is what they learn by
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule)
    assert LearningRule.of(learner.metadata()) == learner.rule == rule
    d = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, stride=2, spawn="all")
    assert LearningRule.of(d.metadata()) == d.rule and d.rule.stride == 2


def test_a_snapshot_written_before_gets_the_rule_its_metadata_describes():
    old_person = {"learning": {"rule": "person", "lag": 3, "k": 25, "copies": 0,
                               "sigma": 0.05, "vote": "median", "passes": 1,
                               "build": "batch", "seed": 2},
                  "tree_params": {"spawn": "winner"}}
    rule = LearningRule.of(old_person)
    assert rule.person and rule.alignment.lag == 3 and rule.seed == 2
    assert rule.editing == NeighbourEditing(k=25, copies=0, sigma=0.05)
    assert rule.passes == 1  # as it was written
    assert rule.guard == PERSON.guard  # a person's tree: the path check, as before
    old_script = {"learning": {"stride": 2, "min_delta": 0.0}, "tree_params": {"spawn": "all"}}
    rule = LearningRule.of(old_script)
    assert rule.name == "script" and rule.stride == 2 and rule.tree == {"spawn": "all"}
    assert rule.guard == SCRIPT.guard
    assert LearningRule.of(None) == LearningRule.of({}) == SCRIPT


def test_bad_rules_are_refused_naming_what_is_wrong():
    with pytest.raises(ValueError, match="k must be an integer >= 1"):
        NeighbourEditing(k=0)
    with pytest.raises(ValueError, match="lag must be None"):
        ReactionAlignment(lag=9)
    with pytest.raises(ValueError, match="guard hold and memory"):
        GuardSettings(hold=-1)
    with pytest.raises(ValueError, match="together, or neither"):
        LearningRule("x", editing=NeighbourEditing())
    with pytest.raises(ValueError, match="a lag is the person rule's"):
        SCRIPT.replace(lag=2)
    with pytest.raises(ValueError, match="not one this version reads"):
        LearningRule.of({"learning": {"rule": "person", "editing": {"k": 5, "loud": 1}}})
    with pytest.raises(ValueError, match="edits its labels"):
        PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=SCRIPT)
    with pytest.raises(ValueError, match="passes are the person rule's"):
        SCRIPT.replace(passes=2)


def test_a_tree_with_goals_stores_and_reads_the_path_check(tmp_path):
    """A goal learner's rule is the scripted one with the guard's path check, written in its
    snapshot; a goal snapshot written before the rule said so (the script's guard stored) is
    read with it too, and the rule's guard off stays off."""
    import numpy as np

    from client.behaviour.goals import GoalLearner, GoalPolicy, parse_goals
    from client.behaviour.guard import settings_for
    from client.behaviour.rule import PATH_CHECK, for_goals
    from lab.behaviours import get

    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2]}), task="red-green")
    assert learner.rule.guard.clearance == PATH_CHECK.clearance and not learner.rule.person
    learner.observe_vector(np.full(b.features.dim, 0.5), "fwd")
    learner.observe_completion(np.array([0.5, 0.5]), True)
    meta = GoalPolicy.load(learner.save(tmp_path / "g.rhbl")).metadata
    assert meta["learning"]["guard"]["clearance"] == PATH_CHECK.clearance
    assert settings_for(meta) == PATH_CHECK
    older = dict(meta, learning=SCRIPT.to_dict())  # as a goal snapshot of 2026-12-06 says
    assert settings_for(older) == PATH_CHECK
    off = dict(meta, learning=SCRIPT.replace(guard=False).to_dict())
    assert not settings_for(off).on and for_goals(SCRIPT).guard == PATH_CHECK
    assert settings_for({"learning": SCRIPT.to_dict()}).clearance == 0  # a tree without goals
    # rhbl evaluate drives beside the trees alone through that guard, or none if it is off
    from lab.goals import guarded

    class Off:
        metadata = off

        def reset(self):
            pass

    tree = Off()
    assert guarded(tree) is tree and guarded(tree, True).clearance == PATH_CHECK.clearance
