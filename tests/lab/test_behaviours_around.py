"""The all-round perception and the behaviours taught with it: the default perception of a new
tree sees ahead and both sides; corridor centring's and wandering's files parse and each one's
expert succeeds from every start of every world it names, by its own rule."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.features import DEFAULT_FEATURES, FEATURES
from client.behaviour.policies import CorridorCentrer, Wanderer
from client.behaviour.spec import shipped
from client.behaviour.tasks import task_of_features
from lab import metrics
from lab.behaviours import get, world_of
from lab.harness import drive


def _expert_succeeds_everywhere(name: str) -> None:
    b = get(name)
    for world in b.worlds:
        spec = world_of(b, world)
        assert len(spec.start_poses) >= 4, world
        for start in spec.start_poses:
            m = drive(spec, b.expert(), start, b.seconds, behaviour=b).metrics(spec.goal, b.rules)
            assert metrics.judge(b.rules, m), (world, start, m)


def test_the_default_perception_sees_ahead_and_both_sides():
    spec = FEATURES[DEFAULT_FEATURES]
    assert DEFAULT_FEATURES == "around" and spec.dim == 9 and spec.heading is None
    assert spec.beams[0] == 0.0 and spec.beams[4] == 90.0 and spec.beams[-1] == 180.0
    assert task_of_features("around") is None  # several behaviours' perception: no task implied
    # the sectors tile the field of view: every beam of a scan is in one of them
    ranges = np.full(360, 5.0, dtype=np.float32)
    for i in (0, 90, 180, 270, 359):
        near = ranges.copy()
        near[i] = 0.5
        assert spec.extract(near).min() == pytest.approx(0.25), i


def test_corridor_centring_is_a_file_and_its_expert_succeeds_from_every_start():
    b = shipped()["corridor-centring"]
    assert b.features == FEATURES["around"] and b.expert_name == "corridor-centrer"
    assert len(b.held_out) >= 3 and set(b.rules) >= {"centred", "no-collision", "time-limit"}
    _expert_succeeds_everywhere("corridor-centring")


def test_the_corridor_centrer_steers_towards_the_middle_from_its_sectors_alone():
    expert = CorridorCentrer()
    ranges = np.full(360, 1.0, dtype=np.float32)
    assert expert.act(ranges) == "fwd"  # midway, nothing ahead
    ranges[:60] = 0.5  # the right wall near: away from it, to the left
    assert expert.act(ranges) == "fwd-left"
    assert expert.act(ranges[::-1].copy()) == "fwd-right"
    ranges[170:190] = 0.3  # a wall straight ahead: rotate
    assert expert.act(ranges).startswith("rot")
    # the same sectors, the same label (what a tree with the same perception can learn)
    rng = np.random.default_rng(0)
    for _ in range(200):
        r = rng.uniform(0.3, 3.0, 360).astype(np.float32)
        assert expert.act(r) == expert.decide(FEATURES["around"].extract(r) * 2.0)
    with pytest.raises(ValueError, match="9 sectors, got 5"):
        CorridorCentrer(features=FEATURES["wall"])


def test_wandering_is_a_file_and_its_expert_succeeds_from_every_start():
    b = shipped()["wandering"]
    assert b.features == FEATURES["around"] and b.expert_name == "wanderer"
    assert len(b.held_out) >= 3 and set(b.rules) >= {"coverage", "no-collision", "time-limit"}
    _expert_succeeds_everywhere("wandering")


def test_the_wanderer_drives_on_when_clear_and_turns_away_when_blocked():
    expert = Wanderer()
    ranges = np.full(360, 3.0, dtype=np.float32)
    assert expert.act(ranges) == "fwd"
    near_right = ranges.copy()
    near_right[120:175] = 0.9  # something close ahead, on the right: away from it
    assert expert.act(near_right) == "fwd-left"
    assert expert.act(near_right[::-1].copy()) == "fwd-right"
    ranges[150:210] = 0.4  # in the way: rotate, always the preferred way
    assert expert.act(ranges) == "rot-left" and Wanderer(prefer="right").act(ranges) == "rot-right"
    rng = np.random.default_rng(1)
    for _ in range(200):
        r = rng.uniform(0.3, 3.0, 360).astype(np.float32)
        assert expert.act(r) == expert.decide(FEATURES["around"].extract(r) * 2.0)
    with pytest.raises(ValueError, match="prefer must be 'left' or 'right', got 'up'"):
        Wanderer(prefer="up")
