"""Goals in order (client.behaviour.goals): the [goals] table, the goal state, the scripted
seeker, the goal learner's two trees and their snapshot (today's single trees still load)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from client.behaviour.features import FEATURES, FeatureSpec
from client.behaviour.goals import (
    DONE,
    NOT_DONE,
    BeaconSeeker,
    GoalExpert,
    GoalLearner,
    GoalPolicy,
    Goals,
    GoalStep,
    GoalTracker,
    ReactiveBeaconPolicy,
    Sighting,
    load_policy,
    parse_goals,
)
from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.spec import BehaviourError, parse_behaviour, shipped
from lab import metrics

GOAL_SPEC = FeatureSpec(beams=FEATURES["around"].beams, window=11.25, beacon="goal",
                        beacon_range=6.0)


def test_a_goals_table_gives_the_order_of_its_goals():
    g = parse_goals({"beacons": [2, 1, 3]})
    assert g.visits == (0, 1, 2) and g.within == (0.6, 0.6, 0.6) and g.distinct == (2, 1, 3)
    patrol = parse_goals({"beacons": [1, 2, 3], "cycle": True, "laps": 2, "within": 0.8})
    assert [patrol.beacons[k] for k in patrol.visits] == [1, 2, 3, 1, 2, 3, 1]
    assert Goals.from_dict(patrol.to_dict()) == patrol


@pytest.mark.parametrize("table, field", [
    ({"beacons": []}, "goals.beacons"), ({"beacons": [0]}, "goals.beacons"),
    ({"beacons": [1, 2], "within": [0.5]}, "goals.within"),
    ({"beacons": [1], "within": -1}, "goals.within"),
    ({"beacons": [1], "laps": 2}, "goals.laps"), ({"beacons": [1], "cycle": "yes"}, "goals.cycle"),
    ({"beacons": [1], "order": 1}, "goals.order"),
])
def test_a_bad_goals_table_is_named(table, field):
    with pytest.raises(ValueError, match=f"field '{field}'"):
        parse_goals(table)


def test_a_behaviour_with_goals_is_judged_by_the_goals_rule_and_only_it():
    base = {"name": "x", "summary": "s", "expert": {"name": "beacon-seeker"},
            "perception": {"beams": [0.0, 22.5, 45.0, 67.5, 90.0, 112.5, 135.0, 157.5, 180.0],
                           "window": 11.25, "beacon": "goal"},
            "worlds": {"teach": ["goals-red-green"]}}
    b = parse_behaviour({**base, "goals": {"beacons": [1, 2]}, "success": {"goals": {}}})
    assert b.goals.beacons == (1, 2) and b.rules["goals"] == {"slack": 0.1}
    with pytest.raises(BehaviourError, match="success.goals"):
        parse_behaviour({**base, "goals": {"beacons": [1, 2]}, "success": {"no-collision": {}}})
    with pytest.raises(BehaviourError, match="success.goals"):
        parse_behaviour({**base, "success": {"goals": {}}})
    with pytest.raises(BehaviourError, match="goals.beacons"):
        parse_behaviour({**base, "goals": {"beacons": "red"}, "success": {"goals": {}}})


def test_the_shipped_goal_behaviours_see_their_goals_beacon():
    for name in ("red-green", "patrol", "remembered"):
        b = shipped()[name]
        assert b.goals is not None and b.features.beacon == "goal" and b.features.dim == 12
        assert "goals" in b.rules and "no-collision" in b.rules and len(b.held_out) >= 2
    assert shipped()["patrol"].goals.cycle and len(shipped()["patrol"].goals.visits) == 7
    assert shipped()["remembered"].goals.beacons == (2, 1, 2, 3)


def test_the_tracker_moves_on_and_says_why():
    t = GoalTracker(parse_goals({"beacons": [1, 2]}))
    assert (t.goal, t.beacon, t.finished) == (0, 1, False) and t.describe() == "goal 1/2: beacon 1"
    ev = t.advance("reached", t=3.25)
    assert ev == {"t": 3.25, "visit": 0, "goal": 0, "beacon": 1, "next": 2, "why": "reached"}
    t.advance("reached")
    assert t.finished and t.beacon is None and t.describe() == "finished (2 goals)"
    t.reset()
    assert t.visit == 0 and t.events == []


def _scan(r: float = 3.0) -> np.ndarray:
    return np.full(360, r, dtype=np.float32)


def test_the_seeker_heads_for_its_beacon_and_follows_a_wall_without_one():
    s = BeaconSeeker()
    s.see(Sighting(1, 3.0, 0.0))
    assert s.act(_scan()) == "fwd"
    s.see(Sighting(1, 3.0, 0.4))
    assert s.act(_scan()) == "fwd-left"
    s.see(Sighting(1, 3.0, -1.2))
    assert s.act(_scan()) == "rot-right"
    s.see(None)
    assert s.act(_scan()) == "fwd"  # open space, none in view: straight on
    wall = _scan()
    wall[:120] = 0.3  # a wall close on the right
    s.see(Sighting(1, 3.0, 0.0))
    assert s.act(wall) == "fwd-left"  # away from it first
    with pytest.raises(ValueError, match="near must be a number > 0"):
        BeaconSeeker(near=0)


def test_the_expert_says_reached_within_the_goals_distance():
    expert = GoalExpert(parse_goals({"beacons": [1, 2], "within": 0.6}))
    expert.reset()
    assert expert.see({1: Sighting(1, 0.9, 0.0)}) is None and expert.tracker.beacon == 1
    ev = expert.see({1: Sighting(1, 0.55, 0.0), 2: Sighting(2, 4.0, 0.1)})
    assert ev["beacon"] == 1 and ev["next"] == 2 and "teacher: reached beacon 1" in ev["why"]
    assert expert.seeker.sighting == Sighting(2, 4.0, 0.1)  # it now pursues the next
    expert.reset(visit=1)
    assert expert.tracker.beacon == 2


def _taught(goals: Goals) -> GoalLearner:
    """A goal learner taught a toy stream: ahead when the goal's beacon is to the left, and
    'reached' at 0.55 m, 'not reached' from 0.7 m on, at either beacon."""
    learner = GoalLearner(GOAL_SPEC, goals)
    rng = np.random.default_rng(0)
    for _ in range(300):
        for goal, beacon in enumerate(goals.beacons):
            r = float(rng.uniform(0.7, 5.0))
            seen = {beacon: Sighting(beacon, r, float(rng.uniform(-0.3, 0.3)))}
            learner.observe_vector(learner.vector(_scan(), 0.0, GoalStep(beacon, None, seen)), "fwd")
            learner.observe_completion(goals.completion_inputs(seen, goal), False)
            near = {beacon: Sighting(beacon, float(rng.uniform(0.3, 0.58)), 0.0)}
            learner.observe_completion(goals.completion_inputs(near, goal), True)
            side = {beacon: Sighting(beacon, r, 1.2)}
            learner.observe_vector(learner.vector(_scan(), 0.0, GoalStep(beacon, None, side)), "rot-left")
    return learner


def test_the_learned_completion_moves_the_robot_on(tmp_path):
    goals = parse_goals({"beacons": [1, 2]})
    policy = _taught(goals).policy()
    assert set(policy.completion.classes_) == {DONE, NOT_DONE}
    policy.reset()
    assert policy.see({1: Sighting(1, 3.0, 0.0)}, t=1.0) is None
    assert policy.act(_scan(), (0, 0, 0)) == "fwd"
    ev = policy.see({1: Sighting(1, 0.4, 0.0)}, t=2.0)
    assert ev["beacon"] == 1 and ev["next"] == 2 and "completion tree" in ev["why"]
    # now the robot pursues beacon 2: beacon 1 straight ahead is none in view for it
    assert policy.see({2: Sighting(2, 3.0, 1.2)}, t=2.1) is None
    assert policy.act(_scan(), (0, 0, 0)) == "rot-left"
    assert policy.see({2: Sighting(2, 0.45, 0.0)}, t=3.0)["next"] is None
    assert policy.tracker.finished


def test_a_goal_snapshot_holds_both_trees_and_old_snapshots_load_unchanged(tmp_path):
    goals = parse_goals({"beacons": [2, 1], "within": [0.6, 0.8]})
    learner = _taught(goals)
    path = learner.save(tmp_path / "goals.msgpack")
    policy = load_policy(path)
    assert isinstance(policy, GoalPolicy) and policy.goals == goals
    assert policy.features == GOAL_SPEC
    assert policy.classifier.tree_equal(learner.action_tree)
    assert policy.completion.tree_equal(learner.completion_tree)
    assert policy.metadata["goals"]["version"] == 1
    # a single tree, as every snapshot before goals: the same TreePolicy as ever
    single = DemonstrationLearner(FEATURES["around"])
    single.observe(_scan(), 0.0, "fwd")
    single.save(tmp_path / "single.msgpack")
    old = load_policy(tmp_path / "single.msgpack")
    assert type(old) is TreePolicy and old.act(_scan(), (0, 0, 0)) == "fwd"
    with pytest.raises(Exception, match="no 'goals'"):
        GoalPolicy.load(tmp_path / "single.msgpack")


def test_the_reactive_baseline_sees_every_beacon_and_no_goal():
    goals = parse_goals({"beacons": [1, 2, 1]})
    base = ReactiveBeaconPolicy(GOAL_SPEC, goals)
    x = base.vector(_scan(), 0.0, {2: Sighting(2, 3.0, 0.0)})
    assert len(x) == 9 + 3 * 2  # the laser, then beacons 1 and 2
    assert x[9:12].tolist() == [0.0, 1.0, 0.5] and x[12:15].tolist() == [1.0, 0.5, 0.5]
    with pytest.raises(ValueError, match="beacon = 'goal'"):
        ReactiveBeaconPolicy(FEATURES["around"], goals)


def test_goals_count_only_in_order():
    poses = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (1, 0, 0), (0, 0, 0)]
    targets = [(0.0, 0.0, 0.2), (2.0, 0.0, 0.2), (0.0, 0.0, 0.2)]
    assert metrics.goals_in_order(poses, targets, 1.0) == [1.0, 3.0, 5.0]
    assert metrics.goals_in_order(poses, [(2.0, 0.0, 0.2), (5.0, 0.0, 0.2)], 1.0) == [3.0]
    m = metrics.episode_metrics(poses, [False] * 5, ["fwd"] * 5, 1.0,
                                rules={"goals": {"slack": 0.1}}, targets=targets)
    assert (m["goals_reached"], m["goals_total"]) == (3, 3)
    assert metrics.judge({"goals": {"slack": 0.1}}, m)
    m["goals_reached"] = 2
    assert not metrics.judge({"goals": {"slack": 0.1}}, m)
    assert math.isfinite(m["distance"])


def test_a_narrower_bearing_spreads_the_beacons_field_over_its_input():
    wide = FeatureSpec(beams=(90.0,), beacon="goal")
    narrow = FeatureSpec(beams=(90.0,), beacon="goal", beacon_bearing=90.0)
    seen = [Sighting(1, 3.0, math.pi / 4)]
    assert wide.beacon_values(seen, 1)[2] == pytest.approx(0.625)
    assert narrow.beacon_values(seen, 1)[2] == pytest.approx(0.75)
    assert narrow.beacon_values([Sighting(1, 3.0, 2.0)], 1)[2] == 1.0  # clipped
    assert "beacon_bearing" not in wide.to_dict()  # the dicts of specs before: unchanged
    assert FeatureSpec.from_dict(narrow.to_dict()) == narrow
    base = {"name": "x", "summary": "s", "expert": {"name": "beacon-seeker"},
            "worlds": {"teach": ["goals-red-green"]}, "success": {"no-collision": {}}}
    with pytest.raises(BehaviourError, match="perception.beacon_bearing': only with 'beacon'"):
        parse_behaviour({**base, "perception": {"sectors": 9, "beacon_bearing": 90}})


def test_a_teacher_on_and_on_labels_the_goal_and_starts_again_after_the_last():
    """``GoalExpert.label_state``: the goal pursued and the goal reached at a step, a label's
    ``goal`` and ``reached``; after the last goal the first again (a patrol's end is its first
    goal: reached again at once, the next pursued)."""
    expert = GoalExpert(parse_goals({"beacons": [1, 2]}))
    assert expert.label_state({1: Sighting(1, 3.0, 0.0)}) == (1, None)
    assert expert.label_state({1: Sighting(1, 0.5, 0.0)}) == (2, 1)
    assert expert.label_state({2: Sighting(2, 0.5, 0.0)}) == (1, 2)  # the last: from the first
    assert expert.tracker.visit == 0 and not expert.tracker.finished
    patrol = GoalExpert(parse_goals({"beacons": [1, 2], "cycle": True}))
    for b in (1, 2):
        patrol.label_state({b: Sighting(b, 0.5, 0.0)})
    # the cycle ends at beacon 1: reached, and with the restart reached again: on to 2
    assert patrol.label_state({1: Sighting(1, 0.5, 0.0)}) == (2, 1)


def test_the_robot_put_elsewhere_is_told_by_a_jump_between_two_ticks():
    """Farther than ``PUT`` beyond what the robot can drive in the time between the two
    messages: consecutive ticks, or after a gap (a paused teacher) no false move."""
    from types import SimpleNamespace as Msg

    from client.behaviour.goals import PUT, Relocation

    r = Relocation()
    assert not r.moved(Msg(truth=(1.0, 1.0, 0.0), pose=(0.0, 0.0, 0.0), ts=0.0))  # the first
    assert not r.moved(Msg(truth=(1.0 + PUT, 1.0, 0.0), pose=(5.0, 5.0, 0.0), ts=0.1))
    assert r.moved(Msg(truth=(4.0, 1.0, 0.0), pose=(0.0, 0.0, 0.0), ts=0.2))
    assert not r.moved(Msg(truth=(9.0, 1.0, 0.0), pose=(0.0, 0.0, 0.0), ts=20.2))  # 20 s later
    odom = Relocation()  # no true pose (a real robot): odometry, which a set_pose resets
    odom.moved(Msg(truth=None, pose=(3.0, 2.0, 0.0), ts=1.0))
    assert odom.moved(Msg(truth=None, pose=(0.0, 0.0, 0.0), ts=1.1))


def test_one_spot_that_completes_every_goal_still_names_a_goal():
    """A single goal (or the same beacon twice in a row): reached, the sequence again, and the
    label still names the goal pursued, never none."""
    expert = GoalExpert(parse_goals({"beacons": [5]}))
    for _ in range(3):
        goal, reached = expert.label_state({5: Sighting(5, 0.3, 0.0)})
        assert goal == 5
    assert reached == 5


def test_a_beacon_named_twice_has_one_distance():
    assert parse_goals({"beacons": [2, 1, 2], "within": [0.6, 0.6, 0.6]}).beacons == (2, 1, 2)
    with pytest.raises(ValueError, match="beacon 2 is named twice with other distances"):
        parse_goals({"beacons": [2, 1, 2], "within": [0.6, 0.6, 1.5]})


def test_a_behaviour_with_goals_sees_the_goals_beacon_and_is_taught_by_the_seeker(tmp_path):
    from client.behaviour.spec import behaviour as load

    text = shipped()["red-green"].path.read_text()
    bad = tmp_path / "wall.toml"
    bad.write_text(text.replace('name = "beacon-seeker"', 'name = "wall-follower"'))
    with pytest.raises(BehaviourError, match="expert.name.*beacon-seeker"):
        load(bad)
    blind = tmp_path / "blind.toml"
    blind.write_text(text.replace('beacon = "goal"', 'beacon = 1'))
    with pytest.raises(BehaviourError, match="perception.beacon"):
        load(blind)
