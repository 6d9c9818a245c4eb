"""lab.recipe: the one typed training recipe per task and what is derived from it (the demo's
scenario; the help texts: tests/test_cli.py)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from lab.cli import build_parser
from lab.harness import make_learner, resolve_world
from lab.recipe import EVAL_SECONDS, RECIPES, Recipe, recipe_for, recipe_from_args
from lab.train import train


def test_the_maze_demo_snapshot_records_task_maze():
    from lab.demo_run import SCENARIOS

    for task, sc in SCENARIOS.items():
        if sc.behaviour is not None:  # (--scenario goals: a behaviour's, its own test)
            continue
        args = build_parser("learner").parse_args([*sc.learner_args(), "--out", "x.rhbl"])
        assert args.task == task == sc.task
        assert (args.features, args.spawn, args.stride) == (sc.recipe.features, sc.recipe.spawn,
                                                            sc.recipe.stride)
        teacher = build_parser("teacher").parse_args(sc.teacher_args("reactive", 7))
        assert teacher.perturb == sc.recipe.perturb and teacher.seed == 7
        corrector = build_parser("teacher").parse_args(sc.corrector_args("reactive"))
        assert corrector.correct and corrector.takeover == sc.recipe.takeover


def test_replace_validates_and_names_the_field():
    r = RECIPES["maze"]
    assert r.replace(rounds=1).rounds == 1 and r.rounds == 6  # frozen: a copy
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.rounds = 1  # type: ignore[misc]
    with pytest.raises(TypeError, match="not a recipe field: roundz"):
        r.replace(roundz=1)
    for field, bad in [("rounds", -1), ("seconds", 0.0), ("perturb", 1.5), ("stride", 0),
                       ("starts", "anywhere"), ("features", "sonar"), ("task", ""),
                       ("round_scales", (0.9, -1.0)), ("segment", math.nan), ("rounds", 1.5)]:
        with pytest.raises(ValueError, match=f"recipe {field} must be"):
            r.replace(**{field: bad})
    assert r.replace(round_scales=[1, 2]).round_scales == (1.0, 2.0)
    for field, bad in [("compact", "shrink"), ("compact_max_nodes", 0),
                       ("compact_max_error", 1.5)]:
        with pytest.raises(ValueError, match=f"recipe {field} must be"):
            r.replace(**{"compact": "prune", field: bad})
    with pytest.raises(ValueError, match="apply to compact 'prune'.*got compact 'exact'"):
        r.replace(compact="exact", compact_max_nodes=10)
    with pytest.raises(ValueError, match="no training recipe for task 'dance'"):
        recipe_for("dance")


def test_recipe_from_args_takes_the_flags_given():
    parser = build_parser("train")
    args = parser.parse_args(["--world", "maze", "--out", "x", "--seconds", "120", "--rounds",
                              "1", "--round-scales", "none", "--consistent"])
    r = recipe_from_args("maze", args)
    assert r == RECIPES["maze"].replace(seconds=120.0, rounds=1, round_scales=(),
                                        consistent=True)
    assert recipe_from_args("maze", parser.parse_args(["--world", "maze", "--out", "x"])) \
        == RECIPES["maze"]
    for r in RECIPES.values():  # no compaction by default: Table I does not change
        assert r.compact == "none" and r.compact_params() is None
    args = build_parser("experiment").parse_args(
        ["wall-following", "--compact", "prune-balanced", "--compact-max-nodes", "200"])
    r = recipe_from_args("wall-following", args)
    assert r.compact_params() == {"method": "prune", "class_weight": "balanced",
                                  "max_nodes": 200}
    assert make_learner(r).recording and not make_learner(RECIPES["maze"]).recording


def test_learner_and_run_follow_the_recipe():
    r = RECIPES["wall-following"].replace(stride=2, spawn="all", max_nodes=50)
    learner = make_learner(r)
    assert learner.task == "wall-following" and learner.stride == 2
    spec = resolve_world("corridor")
    train(spec, learner, r.replace(seconds=5, rounds=0), seed=0)
    assert learner.nodes <= 50
    assert learner.session["seconds"] == 5 and learner.session["rounds"] == 0
    with pytest.raises(ValueError, match="recipe is for task 'maze'"):  # room: wall following's
        train(resolve_world("room"), make_learner("maze"), RECIPES["maze"], seed=0)


def test_every_task_has_a_recipe_and_an_evaluation_length():
    assert set(RECIPES) == set(EVAL_SECONDS) == {"wall-following", "maze"}
    for task, r in RECIPES.items():
        assert isinstance(r, Recipe) and r.task == task and r.for_demo().task == task


def test_compact_rounds_needs_a_compaction_and_has_a_flag_both_ways():
    r = RECIPES["wall-following"]
    with pytest.raises(ValueError, match="compact_rounds needs a compaction step"):
        r.replace(compact_rounds=True)
    with pytest.raises(ValueError, match="recipe compact_rounds must be True or False"):
        r.replace(compact="exact", compact_rounds=1)
    parser = build_parser("experiment")
    on = recipe_from_args("wall-following", parser.parse_args(
        ["wall-following", "--compact", "prune-balanced", "--compact-max-nodes", "53",
         "--compact-rounds"]))
    assert on.compact_rounds and on.compact_max_nodes == 53
    off = on.replace(compact_rounds=False)
    assert recipe_from_args("wall-following", parser.parse_args(
        ["wall-following", "--compact", "prune-balanced", "--compact-max-nodes", "53",
         "--no-compact-rounds"])) == off


def test_a_compact_flag_replaces_the_recipes_whole_compaction_step(monkeypatch):
    # a recipe that compacts by default: --compact none / exact drop the settings that no
    # longer apply unless they are given too
    compacting = dict(RECIPES, **{"wall-following": RECIPES["wall-following"].replace(
        compact="prune-balanced", compact_max_nodes=53, compact_rounds=True)})
    monkeypatch.setattr("lab.recipe.RECIPES", compacting)
    parser = build_parser("experiment")
    none = recipe_from_args("wall-following", parser.parse_args(
        ["wall-following", "--compact", "none"]))
    assert none.compact == "none" and not none.compact_rounds
    assert none.compact_max_nodes is None and none.compact_params() is None
    exact = recipe_from_args("wall-following", parser.parse_args(
        ["wall-following", "--compact", "exact"]))
    assert exact.compact_rounds and exact.compact_max_nodes is None
    kept = recipe_from_args("wall-following", parser.parse_args(["wall-following"]))
    assert kept == compacting["wall-following"]


def test_compact_visits_needs_a_compaction_and_valid_scales():
    r = RECIPES["wall-following"]
    with pytest.raises(ValueError, match="compact_visits needs a compaction step"):
        r.replace(compact_visits=2)
    with pytest.raises(ValueError, match="recipe visit_scales must be finite factors > 0"):
        r.replace(compact="exact", compact_visits=1, visit_scales=(0.0,))
    with pytest.raises(ValueError, match="recipe compact_visits must be an integer >= 0"):
        r.replace(compact="exact", compact_visits=-1)
    args = build_parser("train").parse_args(
        ["--world", "room", "--out", "x", "--compact", "prune-balanced", "--compact-visits",
         "2", "--visit-scales", "none", "--visit-free", "0"])
    got = recipe_from_args("wall-following", args)
    assert (got.compact_visits, got.visit_scales, got.visit_free) == (2, (), 0)
