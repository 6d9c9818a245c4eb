"""Randomised teaching worlds (``lab.generated``, ``rhbl generate``, the recipe's
``round_generated``) and the paper's scenario kept apart from a behaviour's own recipe
(``rhbl experiment --paper``)."""

import math

import numpy as np
import pytest

from lab.behaviours import get, recipe_of
from lab.cli import main
from lab.generated import KINDS, generated
from lab.harness import make_learner, resolve_world
from lab.recipe import RECIPES
from lab.train import train
from server.world import World, load_world


def _side_of_nearest_wall(spec, pose) -> float:
    """> 0: the nearest wall point is on the robot's left, < 0: on its right."""
    x, y, yaw = pose
    best, sign = math.inf, 0.0
    for x0, y0, x1, y1 in spec.segments():
        dx, dy = x1 - x0, y1 - y0
        t = max(0.0, min(1.0, ((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy)))
        px, py = x0 + t * dx, y0 + t * dy
        d = math.hypot(px - x, py - y)
        if d < best:
            best = d
            sign = math.cos(yaw) * (py - y) - math.sin(yaw) * (px - x)
    return sign


@pytest.mark.parametrize("kind", KINDS)
def test_the_same_seed_draws_the_same_valid_worlds(kind):
    a, b = generated(kind, 3, seed=7), generated(kind, 3, seed=7)
    assert [w.walls for w in a] == [w.walls for w in b]
    assert [w.name for w in a] == [f"{kind}-7-{i}" for i in range(3)]
    assert a[0].walls != generated(kind, 1, seed=8)[0].walls
    for spec in a:
        assert len(spec.start_poses) >= 2
        world = World(spec, robots=1, seed=0)
        for pose in spec.start_poses:
            assert spec.inside(pose[0], pose[1]) and spec.clearance(pose[0], pose[1]) > 0.45
            world.reset(poses=[pose])
            assert float(np.min(world.scan(0))) > 0.3  # in the free space, walls in view
        if kind in ("mazes", "dead-ends", "doorways"):
            assert spec.goal is not None and spec.inside(*spec.goal.center)
            assert spec.clearance(*spec.goal.center) > 0.5


@pytest.mark.parametrize("behaviour,kind", [("corridor-centring", "corridors"),
                                            ("dead-end", "dead-ends"), ("doorways", "doorways")])
def test_a_behaviours_expert_succeeds_in_the_worlds_its_generator_draws(behaviour, kind):
    from client.behaviour.actions import DEFAULT_ACTIONS
    from lab import metrics
    from lab.harness import DT
    from lab.practice import teacher_episode

    b = get(behaviour)
    assert recipe_of(b).generator == kind  # the behaviour's file names its kind of world
    spec = generated(kind, 1, seed=0)[0]
    done = []
    for start in spec.start_poses:
        m = teacher_episode(spec, b, DEFAULT_ACTIONS, start, b.seconds, 0, 0.0, 0.0,
                            DT).metrics(spec.goal, b.rules)
        done.append(metrics.judge(b.rules, m, None))
    assert sum(done) >= len(done) - 1, (spec.name, done)


@pytest.mark.parametrize("side", ["right", "left"])
def test_room_starts_have_the_wall_on_the_side_asked(side):
    for spec in generated("rooms", 4, seed=3, side=side):
        for pose in spec.start_poses:
            s = _side_of_nearest_wall(spec, pose)
            assert (s < 0) if side == "right" else (s > 0), (spec.name, pose)
            assert spec.clearance(pose[0], pose[1]) == pytest.approx(0.7, abs=0.05)


def test_rhbl_generate_writes_world_files_it_does_not_replace(tmp_path, capsys):
    out = tmp_path / "worlds"
    assert main(["generate", "mazes", "--count", "2", "--seed", "5", "--out", str(out)]) == 0
    files = sorted(out.glob("*.toml"))
    assert [f.name for f in files] == ["mazes-5-0.toml", "mazes-5-1.toml"]
    for f, spec in zip(files, generated("mazes", 2, seed=5), strict=True):
        loaded = load_world(f)
        assert loaded.name == spec.name and loaded.goal == spec.goal
        assert loaded.start_poses == spec.start_poses
        assert np.allclose(loaded.segments(), spec.segments(), atol=1e-3)
    before = files[0].read_text()
    capsys.readouterr()
    assert main(["generate", "mazes", "--count", "2", "--seed", "5", "--out", str(out)]) == 2
    assert "mazes-5-0.toml exists (not replaced)" in capsys.readouterr().err
    assert files[0].read_text() == before
    with pytest.raises(SystemExit) as exc:
        main(["generate", "hills", "--out", str(out)])
    assert exc.value.code == 2 and "invalid choice: 'hills'" in capsys.readouterr().err


def test_corrective_rounds_in_generated_worlds():
    spec = resolve_world("room")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=10, rounds=1, round_seconds=2,
                                               round_generated=2, generator="rooms")
    train(spec, learner, recipe, seed=4, behaviour=get("wall-following"))
    worlds = [s.get("world") for s in learner.session["round_stats"]]
    assert worlds == ["rooms-4-0", "rooms-4-1", None]
    assert learner.session["round_generated"] == {"worlds": 2, "kind": "rooms"}
    with pytest.raises(ValueError, match="generator"):
        recipe.replace(generator="hills")
    with pytest.raises(ValueError, match="round_generated"):
        recipe.replace(round_generated=-1)


def test_beacon_worlds_hold_the_three_beacons_apart_in_the_free_space(tmp_path):
    from lab.generated import draw, to_toml

    for spec in generated("beacons", 4, seed=2):
        assert [b.id for b in spec.beacons] == [1, 2, 3]
        for b in spec.beacons:
            assert spec.inside(*b.pos) and spec.clearance(*b.pos) >= 0.9 - 1e-3
        for i, b in enumerate(spec.beacons):
            for c in spec.beacons[i + 1:]:
                assert math.dist(b.pos, c.pos) >= 3.0 - 1e-3
    data, spec = draw("beacons", np.random.default_rng(5), name="b5")
    path = tmp_path / "b5.toml"
    path.write_text(to_toml(data))
    loaded = load_world(path)
    assert loaded.beacons == spec.beacons and loaded.start_poses == spec.start_poses


def test_a_goal_behaviour_is_corrected_in_generated_beacon_worlds_too():
    from lab.goals import train_goals

    b = get("red-green")
    recipe = recipe_of(b).replace(seconds=20, segment=10.0, rounds=1, round_seconds=5.0,
                                  round_scales=(), round_free=0, round_generated=0,
                                  generator="beacons")
    spec = resolve_world(b.teach[0])
    _, _, without = train_goals(spec, b, recipe, seed=1)
    _, _, with_two = train_goals(spec, b, recipe.replace(round_generated=2), seed=1)
    starts = sum(len(w.start_poses) for w in generated("beacons", 2, seed=1))
    # every start pose of both drawn worlds driven for up to 5 s (50 steps; a goal sequence
    # finished sooner ends a drive)
    assert without.learned < with_two.learned <= without.learned + 50 * starts


def test_rhbl_behaviours_says_where_a_behaviour_is_taught(capsys):
    assert main(["behaviours", "wall-following"]) == 0
    assert "taught in: room, and 8 randomised rooms" in capsys.readouterr().out
    assert main(["behaviours", "maze"]) == 0
    out = capsys.readouterr().out
    assert "taught in: maze\n" in out and "randomised" not in out


def test_the_paper_scenario_is_kept_apart_from_the_behaviour_recipe(tmp_path, capsys):
    wall = get("wall-following")
    assert recipe_of(wall, paper=True) == RECIPES["wall-following"]
    assert recipe_of(get("maze"), paper=True) == RECIPES["maze"]
    assert recipe_of(wall, paper=True).round_worlds == ()
    with pytest.raises(ValueError, match="not one of the paper's scenarios"):
        recipe_of(get("wandering"), paper=True)
    assert main(["experiment", "wandering", "--paper", "--trials", "1"]) == 2
    assert "--paper goes with wall-following or maze" in capsys.readouterr().err
    assert main(["train", "--behaviour", "wandering", "--paper", "--out",
                 str(tmp_path / "t.rhbl")]) == 2
    assert not (tmp_path / "t.rhbl").exists()
