"""What ``rhbl demo --behaviour`` hands its processes, without running them: a shipped behaviour
of a task runs what ``--scenario TASK`` ran (the same recipe, lengths, perception, task and
expert); a behaviour file gives its own to the learner and the teachers."""

from __future__ import annotations

import argparse

import pytest

from client.behaviour.spec import behaviour, shipped
from client.roles.learner import features_of
from lab.cli import build_parser
from lab.demo_run import SCENARIOS, demo_behaviour, scenario_of


@pytest.mark.parametrize("task", [t for t, sc in SCENARIOS.items() if sc.behaviour is None])
def test_a_tasks_behaviour_runs_what_its_scenario_ran(task):
    before, now = SCENARIOS[task], scenario_of(shipped()[task])
    assert now.recipe == before.recipe and now.drive == before.drive
    learner = build_parser("learner").parse_args([*now.learner_args(), "--out", "x.rhbl"])
    assert features_of(learner) == (before.recipe.features, task, None)
    old = build_parser("learner").parse_args([*before.learner_args(), "--out", "x.rhbl"])
    assert (learner.spawn, learner.stride, learner.min_delta, learner.max_nodes) == \
        (old.spawn, old.stride, old.min_delta, old.max_nodes)
    teacher = build_parser("teacher").parse_args(now.teacher_args("reactive", 7))
    assert teacher.behaviour == task and teacher.policy is None and teacher.seed == 7
    assert behaviour(teacher.behaviour).expert_name == before.policy
    corrector = build_parser("teacher").parse_args(now.corrector_args("reactive"))
    assert corrector.correct and corrector.takeover == before.recipe.takeover


def test_a_behaviour_file_gives_its_own_perception_and_name(tmp_path):
    text = (shipped()["left-wall"].path.read_text()
            .replace('name = "left-wall"', 'name = "mine"'))
    path = tmp_path / "mine.toml"
    path.write_text(text)
    b = behaviour(path)
    sc = scenario_of(b)
    assert sc.recipe.rounds == 5 and sc.drive == 120.0  # its [recipe], its time limit
    learner = build_parser("learner").parse_args([*sc.learner_args(), "--out", "x.rhbl"])
    spec, task, goals = features_of(learner)
    assert goals is None
    assert task == "mine" and spec.to_dict() == b.features.to_dict()
    assert build_parser("teacher").parse_args(sc.teacher_args("reactive", 0)).behaviour == \
        str(path.resolve())


def test_scenario_and_behaviour_are_one_choice():
    ns = argparse.Namespace
    assert demo_behaviour(ns(behaviour=None, scenario=None)).name == "wall-following"
    assert demo_behaviour(ns(behaviour=None, scenario="maze")).name == "maze"
    assert demo_behaviour(ns(behaviour="left-wall", scenario=None)).name == "left-wall"
    with pytest.raises(ValueError, match="--scenario maze and --behaviour left-wall: give one"):
        demo_behaviour(ns(behaviour="left-wall", scenario="maze"))


def test_the_goals_scenario_is_red_green_taught_and_learned_with_its_goals():
    sc = SCENARIOS["goals"]
    assert sc.behaviour.name == "red-green" and sc.behaviour.goals is not None
    learner = build_parser("learner").parse_args([*sc.learner_args(), "--out", "x.rhbl"])
    spec, task, goals = features_of(learner)
    assert task == "red-green" and goals == sc.behaviour.goals and spec.beacon == "goal"
    teacher = build_parser("teacher").parse_args(sc.teacher_args("reactive", 0))
    assert teacher.behaviour == "red-green"
