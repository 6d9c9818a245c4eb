"""The one task table (client.behaviour.tasks) and what reads it."""

from __future__ import annotations

import pytest

from client.behaviour.features import FEATURES
from client.behaviour.policies import (
    MazeTeacher,
    ReactiveFollower,
    ReactiveMazeTeacher,
    WallFollower,
)
from client.behaviour.tasks import (
    TASKS,
    make_policy,
    task_named,
    task_of_features,
    task_of_teacher,
)


def test_the_world_format_knows_the_same_tasks():
    from server.world import TASKS as WORLD_TASKS  # the server cannot import client/

    assert tuple(TASKS) == WORLD_TASKS


def test_each_task_names_a_feature_spec_an_expert_and_its_worlds():
    assert {t.features for t in TASKS.values()} <= set(FEATURES)
    assert task_of_features("wall") == "wall-following"
    assert task_of_features("maze") == "maze"
    assert task_of_features("nothing") is None
    assert task_of_teacher("wall-follower") == "wall-following"
    assert task_of_teacher("maze") == "maze"
    with pytest.raises(ValueError, match="no scripted teacher 'keyboard'; known: wall-follower, maze"):
        task_of_teacher("keyboard")
    assert TASKS["wall-following"].side == "right" and TASKS["maze"].side is None


def test_make_policy_builds_each_tasks_expert_of_each_style():
    assert type(make_policy("wall-following")) is ReactiveFollower
    assert type(make_policy("wall-following", style="smooth")) is WallFollower
    assert type(make_policy("maze")) is ReactiveMazeTeacher
    assert type(make_policy("maze", style="smooth")) is MazeTeacher
    with pytest.raises(ValueError, match="no scripted teacher for task 'soccer'; known: "
                                         "wall-following, maze"):
        make_policy("soccer")
    with pytest.raises(ValueError, match="teacher style must be one of"):
        make_policy("maze", style="jerky")
    with pytest.raises(ValueError, match="no task 'soccer'; known: wall-following, maze"):
        task_named("soccer")


def test_the_commands_offer_the_tables_tasks():
    from lab.cli import build_parser

    teacher = build_parser("teacher")
    choices = next(a.choices for a in teacher._actions if a.dest == "policy")
    assert list(choices) == [t.teacher for t in TASKS.values()] + ["keyboard"]
    assert list(choices)[:2] == ["wall-follower", "maze"]
    experiment = build_parser("experiment")
    for task in ("wall-following", "maze", "both"):  # a behaviour (client.behaviour.spec)
        assert experiment.parse_args([task]).task == task
    with pytest.raises(SystemExit):
        experiment.parse_args(["soccer"])
