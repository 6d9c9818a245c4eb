"""One training run = several demonstrations (start poses, then poses near the teacher's path)."""

import argparse

import numpy as np
import pytest

from client.behaviour.features import FEATURES
from client.behaviour.policies import Demonstrator
from client.behaviour.tasks import make_policy
from lab.harness import make_learner, resolve_world
from lab.recipe import RECIPES, parse_scales
from lab.train import train


def test_world_starts_then_sampled_poses():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=60, starts="world", segment=10,
                                        random_segment=0.5, rounds=0)
    traj = train(spec, learner, recipe, seed=1)
    n_fixed = len(spec.start_poses)
    assert [tuple(p) for p in traj.segments[:n_fixed]] == [tuple(p) for p in spec.start_poses]
    assert len(traj.segments) > n_fixed  # the rest of the time: sampled poses
    assert len(traj.labels) == 600
    assert learner.session["demonstrations"] == len(traj.segments)


def test_explicit_start_is_one_demonstration():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=20, starts="world", segment=5)
    traj = train(spec, learner, recipe, seed=0, start=spec.start_poses[-1])
    assert traj.segments == [list(spec.start_poses[-1])]


def test_maze_recipe_features_and_reactive_labels():
    assert FEATURES["maze-right"].dim == 5 and FEATURES["maze-right"].heading is None
    teacher = make_policy("wall-following")
    demo = Demonstrator(teacher, perturb=0.0)
    scan = np.full(360, 0.6, dtype=np.float32)
    for _ in range(5):
        demo.step(scan, (0.0, 0.0, 0.0))
    # the reactive label is a pure function of the scan
    assert teacher.reactive(scan) == make_policy("wall-following").reactive(scan)
    assert isinstance(demo.consistent, bool)


def test_corrective_rounds_learner_drives_teacher_labels():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=20, starts="world", segment=10,
                                        random_segment=0.0, rounds=2, round_seconds=5,
                                        takeover=0.3, round_scales=())
    traj = train(spec, learner, recipe, seed=0)
    n = len(spec.start_poses)
    stats = learner.session["round_stats"]
    assert [s["round"] for s in stats] == [1, 2]
    assert all(s["steps"] == n * 50 for s in stats)
    assert len(traj.labels) == 200 + 2 * n * 50
    assert learner.session["demonstration_vectors"] < learner.vectors
    assert learner.metadata()["provenance"]["sessions"][-1]["rounds"] == 2


def test_free_starts_and_free_round_poses():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=40, starts="free", segment=10,
                                        random_segment=0.5, rounds=1, round_seconds=3,
                                        round_free=2)
    traj = train(spec, learner, recipe, seed=2)
    n_fixed = len(spec.start_poses)
    assert [tuple(p) for p in traj.segments[:n_fixed]] == [tuple(p) for p in spec.start_poses]
    assert len(traj.segments) > n_fixed
    assert learner.session["round_stats"][0]["steps"] == (n_fixed + 2) * 30
    assert learner.session["round_free"] == 2


def test_scale_augmentation_offers_scaled_scans_labelled_by_the_teacher():
    from lab.train import _Augmenter

    spec = resolve_world("corridor")
    plain = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=10, rounds=0)
    train(spec, plain, recipe, seed=3)
    learner = make_learner("wall-following")
    traj = train(spec, learner, recipe.replace(augment=2, augment_scale=1.3), seed=3)
    assert learner.vectors == 3 * plain.vectors  # each state offered 1 + 2 times
    assert traj.learned == learner.vectors
    assert learner.session["augment"] == 2 and learner.session["augment_scale"] == 1.3
    policy = make_policy("maze")
    aug = _Augmenter(policy, 5, 1.3, seed=0)
    seen = []

    class Rec:
        def observe(self, ranges, yaw, label):
            seen.append((np.asarray(ranges).copy(), label))
            return True

    ranges = np.full(360, 1.0)
    assert aug.offer(Rec(), ranges, (0.0, 0.0, 0.0)) == 5
    for r, label in seen:
        s = float(r[0])
        assert 1 / 1.3 - 1e-9 <= s <= 1.3 + 1e-9 and np.allclose(r, s)
        assert label == policy.label(r)


def test_scale_augmentation_needs_a_scan_only_teacher():
    import pytest

    from lab.train import _Augmenter

    with pytest.raises(ValueError):
        _Augmenter(object(), 1, 1.3, seed=0)
    with pytest.raises(ValueError):
        _Augmenter(make_policy("maze"), 1, 0.9, seed=0)


def test_rounds_in_scaled_copies_of_the_world():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=10, rounds=1, round_seconds=2,
                                        round_scales=(0.9, 1.1))
    train(spec, learner, recipe, seed=0)
    stats = learner.session["round_stats"]
    assert [s.get("scale") for s in stats] == [0.9, 1.1, None]  # training world last
    assert learner.session["round_scales"] == [0.9, 1.1]


def test_rounds_in_the_other_teaching_worlds_come_first():
    """``round_worlds``: corrective rounds also in other worlds (a behaviour's other teaching
    worlds), each in its scaled copies then itself, before the training world's; a behaviour
    with two teaching worlds gets them from ``recipe_of``."""
    from lab.behaviours import get, recipe_of

    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=10, rounds=1, round_seconds=2,
                                               round_scales=(0.9,), round_worlds=("room",))
    train(spec, learner, recipe, seed=0)
    stats = learner.session["round_stats"]
    assert [(s.get("world"), s.get("scale")) for s in stats] == [
        ("room", 0.9), ("room", None), (None, 0.9), (None, None)]
    assert learner.session["round_worlds"] == ["room"]
    assert stats[1]["steps"] == len(resolve_world("room").start_poses) * 20  # its own starts
    for bad in ("room", ("room", ""), (3,)):
        with pytest.raises(ValueError, match="round_worlds"):
            RECIPES["wall-following"].replace(round_worlds=bad)
    wandering = get("wandering")
    assert recipe_of(wandering).round_worlds == wandering.teach[1:] != ()
    assert recipe_of(get("wall-following")).round_worlds == ()


def test_the_recipe_runs_rounds_in_scaled_copies_and_none_turns_them_off():
    spec = resolve_world("maze")
    learner = make_learner("maze")
    recipe = RECIPES["maze"].replace(seconds=10, rounds=1, round_seconds=2)  # its scales
    train(spec, learner, recipe, seed=0)
    assert [s.get("scale") for s in learner.session["round_stats"]] == [0.85, 1.2, None]
    room = resolve_world("corridor")  # wall following: the world itself only
    learner = make_learner("wall-following")
    recipe = RECIPES["wall-following"].replace(seconds=10, rounds=1, round_seconds=2)
    train(room, learner, recipe, seed=0)
    assert [s.get("scale") for s in learner.session["round_stats"]] == [None]
    assert parse_scales("none") == () and parse_scales("0.9, 1.1") == (0.9, 1.1)
    for bad in ("abc", "0,1", "-1", "nan"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_scales(bad)
