"""The shipped behaviours doorways (room to room through doorways) and dead-end (out of a
blind corridor): their files parse into what they say, and their scripted experts succeed, by
each behaviour's own rule, from every start pose of every world they name (their trees'
figures: docs/behaviours.md)."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.features import FEATURES
from client.behaviour.policies import DeadEndEscaper, DoorwayTeacher, ReactiveDoorwayFollower
from client.behaviour.spec import shipped
from client.behaviour.tasks import make_policy, task_of_teacher
from lab import metrics
from lab.behaviours import get, recipe_of, world_of
from lab.harness import drive


def test_the_files_say_what_they_are():
    doorways, dead_end = shipped()["doorways"], shipped()["dead-end"]
    assert doorways.expert_name == "doorway" and task_of_teacher("doorway") == "doorways"
    assert type(doorways.expert()) is ReactiveDoorwayFollower and doorways.expert().target == 0.55
    assert doorways.features == FEATURES["wall"]
    assert type(make_policy("doorways", style="smooth")) is DoorwayTeacher  # rhbl teacher's
    assert doorways.teach == ("doorways",) and len(doorways.held_out) == 3
    assert set(doorways.rules) == {"time-limit", "no-collision", "goal"}
    assert doorways.seconds == 240.0
    assert dead_end.expert_name == "dead-end" and task_of_teacher("dead-end") == "dead-end"
    assert type(dead_end.expert()) is DeadEndEscaper and dead_end.features == FEATURES["around"]
    assert dead_end.teach == ("dead-end",) and len(dead_end.held_out) == 3
    assert set(dead_end.rules) == {"time-limit", "no-collision", "goal"}
    assert dead_end.seconds == 60.0
    for b in (doorways, dead_end):
        assert "goal" in b.instructions and b.summary
        recipe = recipe_of(b)
        assert recipe.task == b.name and recipe.world == b.teach[0] and recipe.rounds >= 4
        for world in b.worlds:  # every world it names is there and has a goal to reach
            assert world_of(b, world).goal is not None, world


@pytest.mark.parametrize("name", ["doorways", "dead-end"])
def test_the_expert_succeeds_from_every_start_of_every_world(name):
    b = get(name)
    for world in b.worlds:
        spec = world_of(b, world)
        assert len(spec.start_poses) >= 3, world
        for start in spec.start_poses:
            m = drive(spec, b.expert(), start, b.seconds, behaviour=b).metrics(spec.goal, b.rules)
            assert metrics.judge(b.rules, m), (world, start, m["collisions"], m["goal_reached"])


def _scan(right: float, ahead: float, left: float, n: int = 360) -> np.ndarray:
    """A made-up scan: ``right`` over the right quarter (-90..-45 deg), ``ahead`` in the middle,
    ``left`` over the left quarter (metres)."""
    r = np.full(n, ahead, dtype=np.float32)
    r[: n // 4], r[3 * n // 4:] = right, left
    return r


def test_the_dead_end_experts_rule_on_made_up_scans():
    e = make_policy("dead-end")
    assert e.act(_scan(0.6, 0.5, 0.6)) == "rot-left"      # the blind end ahead: turn round
    assert e.act(_scan(0.6, 5.0, 0.6)) == "fwd"           # a corridor's line: straight on
    assert e.act(_scan(0.3, 5.0, 0.7)) == "fwd-left"      # too close on the right: steer off
    assert e.act(_scan(0.7, 5.0, 0.3)) == "fwd-right"     # too close on the left
    assert e.act(_scan(5.0, 5.0, 5.0)) == "fwd"           # the open hall: straight on
    assert e.label(_scan(0.6, 0.5, 0.6)) == e.act(_scan(0.6, 0.5, 0.6))  # reactive
    with pytest.raises(ValueError, match="needs a feature spec with >= 9 sectors"):
        DeadEndEscaper(features=FEATURES["wall"])
    with pytest.raises(ValueError, match="stop must be a number of metres > 0, got -1"):
        DeadEndEscaper(stop=-1)
