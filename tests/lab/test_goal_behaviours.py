"""Goal behaviours in the lab (lab.goals): the scripted teacher reaches the goals in order, a
short training run gives both trees, rhbl train / evaluate take a behaviour with goals and the
report says when and why the goal changed. (The figures: docs/goals.md.)"""

from __future__ import annotations

import json

import pytest

from client.behaviour.goals import GoalPolicy, load_policy
from lab import metrics
from lab.behaviours import get, recipe_of, world_of
from lab.cli import main as cli
from lab.goals import (
    drive_goals,
    episode_goal_metrics,
    evaluate_goals,
    expert_of,
    targets,
    train_goals,
)


def test_the_teacher_reaches_red_then_green_from_every_start_of_its_world():
    b = get("red-green")
    spec = world_of(b, b.teach[0])
    assert [t[:2] for t in targets(spec, b)] == [(2.0, 5.5), (8.5, 5.5)]
    for start in spec.start_poses:
        ep, events = drive_goals(spec, expert_of(b), start, b, kind="teacher")
        m = episode_goal_metrics(ep, spec, b)
        assert metrics.judge(b.rules, m), (start, m["goals_reached"], m["collisions"])
        # the episode ends on the true path (within 0.6 + 0.1 m of green), perhaps before the
        # teacher's own rule (0.6 m) said so
        assert [e["beacon"] for e in events] in ([1], [1, 2])


def test_a_world_without_the_goals_beacons_is_named():
    with pytest.raises(ValueError, match="names beacon 1, which world 'room' does not have"):
        targets(world_of(get("red-green"), "room"), get("red-green"))


def test_a_short_training_run_gives_both_trees_and_a_report_of_goal_changes():
    b = get("red-green")
    spec = world_of(b, b.teach[0])
    recipe = recipe_of(b).replace(seconds=60.0, rounds=0, random_segment=0.0)
    learner, reactive, ep = train_goals(spec, b, recipe, seed=1)
    assert learner.marks >= 1 and learner.vectors == len(ep.labels) == ep.learned
    policy = learner.policy()
    assert policy.completion.node_count_ > 1 and reactive.classifier.node_count_ > 1
    rep = evaluate_goals(spec, policy, b, episodes=1, seconds=20.0)
    assert rep["task"] == "red-green" and rep["completion_tree"]["nodes"] > 1
    lm = rep["learner"][0]
    assert lm["goals_total"] == 2 and isinstance(lm["goal_events"], list)
    assert rep["teacher"][0]["goals_total"] == 2


def test_a_goal_behaviours_action_tree_is_learned_again_bounded_by_the_margin(tmp_path):
    """With the radius "margin" the action tree is learned again from every vector at the end
    (as rhbl train ends for a behaviour without goals) and the reactive baseline fitted so; the
    completion tree learns its marks as they come, by the paper's radius."""
    from rhbl import HypersphereClassifier

    b = get("red-green")
    spec = world_of(b, b.teach[0])
    recipe = recipe_of(b).replace(seconds=60.0, rounds=1, round_seconds=5.0, round_generated=0,
                                  round_scales=(), round_free=0, random_segment=0.0,
                                  radius="margin")
    learner, reactive, _ = train_goals(spec, b, recipe, seed=1)
    X, y = learner.recorded()
    params = learner.classifier.get_params()
    assert params["radius"] == "margin"
    assert learner.classifier.tree_equal(HypersphereClassifier(**params).fit(X, y))
    assert learner.completion.radius == "parent" and learner.completion.node_count_ > 1
    assert reactive.classifier.radius == "margin" and reactive.classifier.node_count_ > 1
    policy = load_policy(learner.save(tmp_path / "g.msgpack"))
    assert policy.classifier.radius == "margin" and policy.completion.radius == "parent"


def test_rhbl_train_and_evaluate_take_a_behaviour_with_goals(tmp_path, capsys):
    out = tmp_path / "rg.msgpack"
    assert cli(["train", "--behaviour", "red-green", "--seconds", "60", "--rounds", "0",
                "--random-segment", "0", "--out", str(out)]) == 0
    assert "completion tree" in capsys.readouterr().out
    assert isinstance(load_policy(out), GoalPolicy)
    report = tmp_path / "r.json"
    assert cli(["evaluate", "--behaviour", "red-green", "--tree", str(out), "--episodes", "1",
                "--seconds", "30", "--json", str(report)]) == 0
    text = capsys.readouterr().out
    assert "goals in order" in text and "episode 0: learner reached" in text
    data = json.loads(report.read_text())
    assert data["goals"]["beacons"] == [1, 2] and "goal_events" in data["learner"][0]


def test_the_goal_experiment_judges_the_trees_alone_with_the_guard_beside(tmp_path, capsys):
    """``rhbl experiment`` of a goal behaviour: the goal learner's trees and the reactive tree
    are judged alone; the goal learner through the controller's guard is a column beside."""
    out = tmp_path / "rows.json"
    assert cli(["experiment", "red-green", "--trials", "1", "--train-seconds", "30", "--rounds",
                "0", "--episodes", "2", "--seconds", "10", "--eval-world", "none",
                "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "the learned trees alone, the controller's guard beside them" in printed
    assert "goal learner through the guard" in printed
    rows = json.loads(out.read_text())["red-green"]["rows"]
    w = rows[0]["worlds"]["goals-red-green"]
    assert w["episodes"] == 2 and len(w["goals_reached"]) == 2
    assert 0 <= w["success_rate"] <= 1 and 0 <= w["guarded_success_rate"] <= 1
    assert w["guard"]["clearance"] == 0.3  # the path check a goal tree is driven with
