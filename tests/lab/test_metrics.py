"""Metrics on small cases whose right answer is known by construction."""

import math

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from lab import metrics
from server.world import World, parse_world

CORRIDOR = {
    "name": "straight", "task": "wall-following",
    "robot": {"pose": [1.0, 0.6, 0.0]},
    "walls": [{"points": [[0.0, 0.0], [20.0, 0.0], [20.0, 2.0], [0.0, 2.0]], "closed": True}],
}
BOX_WITH_GOAL = {
    "name": "goalbox", "task": "maze",
    "robot": {"pose": [1.0, 1.0, 0.0]},
    "walls": [{"points": [[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]], "closed": True}],
    "goal": {"center": [3.0, 1.0], "radius": 0.5},
}


def drive(spec, commands, dt=0.1):
    world = World(spec)
    poses, stalls, side = [], [], []
    for vx, va in commands:
        side.append(metrics.side_distance(world.scan(0), "right"))
        world.set_command(0, vx, va)
        world.step(dt)
        poses.append(world.pose(0))
        stalls.append(world.stall(0))
    return poses, stalls, side


def test_straight_corridor_known_answers():
    spec = parse_world(CORRIDOR)
    poses, stalls, side = drive(spec, [DEFAULT_ACTIONS["fwd"]] * 50)
    m = metrics.episode_metrics(poses, stalls, ["fwd"] * 50, 0.1, side=side, start=spec.pose)
    # 50 steps of 0.1 s at 0.4 m/s from x = 1.0: 2.0 m (the first step starts at the start pose)
    assert m["distance"] == pytest.approx(2.0 - 0.04, abs=0.05)
    assert m["collisions"] == 0
    assert m["wall_band_fraction"] == 1.0  # the right wall stays 0.6 m away
    assert np.allclose(side, 0.6, atol=0.01)
    assert m["goal_reached"] is None and m["time_to_goal"] is None
    assert m["oscillations"] == 0 and m["oscillation_loops"] == []
    assert m["seconds"] == pytest.approx(5.0)


def test_driven_into_a_wall_counts_one_collision_per_onset():
    spec = parse_world(CORRIDOR)
    # turn to face the right wall, then push into it, back off by turning, push again
    cmds = [(0.0, -math.pi / 2 / 1.0)] * 10 + [(0.4, 0.0)] * 20 + [(0.0, 1.0)] * 5 + [(0.4, 0.0)] * 10
    poses, stalls, side = drive(spec, cmds)
    # stalled at the end of each push, free while turning: two onsets
    assert stalls[29] and not any(stalls[30:35]) and stalls[-1]
    assert metrics.collisions(stalls) == 2
    assert metrics.collisions([False, True, True, False, True]) == 2
    assert metrics.collisions([True]) == 1
    assert metrics.collisions([]) == 0
    # the robot's centre never passes through the wall
    assert min(p[1] for p in poses) >= 0.2


def test_wall_band_fraction_and_success_rules():
    assert metrics.wall_band_fraction([0.2, 0.3, 0.6, 1.2, 1.3]) == pytest.approx(3 / 5)
    assert metrics.wall_band_fraction([]) == 0.0
    good = {"collisions": 0, "wall_band_fraction": 0.9, "distance": 10.0}
    assert metrics.wall_success(good, 12.0)
    assert not metrics.wall_success(good, 15.0)  # < 70% of the teacher's distance
    assert not metrics.wall_success(dict(good, collisions=1), 10.0)
    assert not metrics.wall_success(dict(good, wall_band_fraction=0.79), 10.0)
    assert metrics.maze_success({"goal_reached": True, "collisions": 0})
    assert not metrics.maze_success({"goal_reached": False, "collisions": 0})
    assert not metrics.maze_success({"goal_reached": True, "collisions": 1})


def test_goal_reached_and_time():
    spec = parse_world(BOX_WITH_GOAL)
    poses, stalls, _ = drive(spec, [DEFAULT_ACTIONS["fwd"]] * 40)
    reached, t = metrics.goal_reached(poses, spec.goal, 0.1)
    # from x = 1.0 at 0.4 m/s the goal edge (x = 2.5) is 1.5 m away: 3.75 s -> the 38th step
    assert reached is True
    assert t == pytest.approx(3.8, abs=0.11)
    assert metrics.goal_reached(poses, ((10.0, 10.0), 0.5), 0.1) == (False, None)
    assert metrics.goal_reached(poses, None, 0.1) == (None, None)


def test_oscillations_and_loops():
    acts = ["fwd", "rot-left", "rot-left", "rot-right", "rot-left", "fwd", "rot-right"]
    assert metrics.oscillations(acts) == 2
    loop = ["fwd"] * 5 + ["rot-left", "rot-right"] * 6 + ["fwd"] * 5
    poses = [(float(i), 0.0, 0.0) for i in range(len(loop))]
    # 12 rotations from step 5 on: 11 switches, the first at step 6 (rot-left -> rot-right); the
    # loop began one step earlier, with the first rot-left at step 5, where the robot stood at x = 5
    assert metrics.oscillation_loops(loop, poses, 0.1) == [
        {"step": 5, "time": 0.5, "pose": [5.0, 0.0, 0.0], "alternations": 11}]
    assert metrics.oscillation_loops(["rot-left", "rot-right", "fwd"], poses[:3], 0.1) == []


def test_teacher_agreement_and_stuck():
    assert metrics.teacher_agreement(["a", "b", "c", "d"], ["a", "x", "c", "y"]) == 0.5
    assert metrics.teacher_agreement(["a"], None) is None
    still = [(0.0, 0.0, 0.0)] * 400
    assert metrics.progress_stuck(still, 0.1)
    moving = [(0.05 * i, 0.0, 0.0) for i in range(400)]
    assert not metrics.progress_stuck(moving, 0.1)


def test_distance_of_known_path():
    assert metrics.distance([(0, 0, 0), (3, 4, 0), (3, 4, 1)]) == pytest.approx(5.0)
    assert metrics.distance([(0, 0, 0)]) == 0.0


def _loops_by_steps(actions, dt, min_alternations=4, window_s=6.0):
    """The definition written out over step indices (switch steps grouped by their gaps), to
    hold the one live detector (client.behaviour.loops) to it."""
    runs = [(a, i) for i, a in enumerate(actions) if i == 0 or actions[i - 1] != a]
    switches = [runs[k + 1][1] for k in range(len(runs) - 1)
                if {runs[k][0], runs[k + 1][0]} == {"rot-left", "rot-right"}]
    gap, groups = max(1, round(window_s / dt)), []
    for s in switches:
        if groups and s - groups[-1][-1] <= gap:
            groups[-1].append(s)
        else:
            groups.append([s])
    return [(max(0, g[0] - 1), len(g)) for g in groups if len(g) >= min_alternations]


@pytest.mark.parametrize("seed", range(20))
def test_the_live_loop_detector_finds_the_loops_of_the_definition(seed):
    rng = np.random.default_rng(seed)
    acts: list[str] = []
    while len(acts) < 800:  # alternations of random runs, other actions, calm stretches
        kind = rng.integers(3)
        if kind == 0:
            for k in range(int(rng.integers(1, 12))):
                acts += [("rot-left", "rot-right")[k % 2]] * int(rng.integers(1, 6))
        elif kind == 1:
            acts += [str(rng.choice(["fwd", "fwd-left", "rot-left", "rot-right"]))]
        else:
            acts += ["fwd"] * int(rng.integers(1, 90))
    poses = [(0.1 * i, 0.0, 0.0) for i in range(len(acts))]
    got = [(lp["step"], lp["alternations"]) for lp in metrics.oscillation_loops(acts, poses, 0.1)]
    assert got == _loops_by_steps(acts, 0.1)
    assert got  # every seed makes some loops
