"""The controller's guard against rot-left/rot-right loops."""

import argparse

import numpy as np
import pytest

from client.behaviour.guard import (
    RotationGuard,
    add_arguments,
    in_path,
    settings,
    settings_for,
)
from client.behaviour.rule import PERSON, SCRIPT, GuardSettings


class Script:
    """A policy answering from a list, one answer per scan."""

    classifier = "the tree"

    def __init__(self, answers):
        self.answers = list(answers)
        self.resets = 0

    def reset(self):
        self.resets += 1

    def act(self, ranges, pose):
        return self.answers.pop(0)


def _drive(guard, n):
    return [guard.act(None, (0.0, 0.0, 0.0)) for _ in range(n)]


def test_a_reversal_is_overruled_and_counted():
    g = RotationGuard(Script(["rot-left", "rot-right", "rot-right", "fwd", "rot-right"]),
                      hold=30, memory=5)
    assert _drive(g, 3) == ["rot-left", "rot-left", "rot-left"]
    assert g.overruled == 2 and g.looping
    # anything but the reversal is taken as it is; then the reversal right after the rotation
    # is a loop too
    assert _drive(g, 2) == ["fwd", "rot-left"]
    assert g.overruled == 3


def test_the_policy_wins_after_hold_scans_and_after_memory_scans():
    g = RotationGuard(Script(["rot-right"] + ["rot-left"] * 4), hold=2)
    assert _drive(g, 5) == ["rot-right", "rot-right", "rot-right", "rot-left", "rot-left"]
    g = RotationGuard(Script(["rot-left", "fwd", "fwd", "fwd", "rot-right"]), memory=2)
    assert _drive(g, 5) == ["rot-left", "fwd", "fwd", "fwd", "rot-right"]  # long ago: taken
    assert g.overruled == 0 and not g.looping


def test_looping_fades_and_reset_forgets():
    s = Script(["rot-left", "rot-right", "fwd", "fwd", "fwd", "rot-left", "rot-right"])
    g = RotationGuard(s, memory=2)
    _drive(g, 2)
    assert g.looping
    _drive(g, 3)
    assert not g.looping  # nothing overruled for more than ``memory`` scans
    g.reset()
    assert s.resets == 2  # made and reset: the wrapped policy is reset too
    assert _drive(g, 2) == ["rot-left", "rot-left"]
    assert g.classifier == "the tree"  # the wrapped policy's attributes


def test_bad_settings():
    with pytest.raises(ValueError, match="hold and memory"):
        RotationGuard(Script([]), hold=-1)


def test_without_a_policy_the_guard_filters_actions():
    g = RotationGuard(hold=2, memory=5)
    assert [g.choose(a) for a in ["rot-right", "rot-left", "rot-left", "rot-left", "fwd"]] == \
        ["rot-right", "rot-right", "rot-right", "rot-left", "fwd"]
    assert g.overruled == 2
    g.reset()  # no policy to reset
    assert not g.looping


def _scan(points):
    """A 360-beam scan over 180 degrees (ranges[0] on the right), 8 m everywhere except the
    beams at ``points`` (bearing in degrees, 0 ahead, negative right -> range)."""
    r = np.full(360, 8.0, np.float32)
    for deg, dist in points.items():
        r[int(round((deg + 90.0) / 180.0 * 359))] = dist
    return r


def test_in_path_finds_the_return_ahead_and_its_side():
    assert in_path(_scan({}), 0.3, 0.5) == 0.0
    assert in_path(_scan({-90: 0.3}), 0.3, 0.5) == 0.0     # the wall beside: not in the path
    assert in_path(_scan({0: 0.8}), 0.3, 0.5) == 0.0       # ahead, but farther than 0.5 m
    assert in_path(_scan({-30: 0.4}), 0.3, 0.5) < 0        # a corner ahead on the right
    assert in_path(_scan({25: 0.4, -60: 0.9}), 0.3, 0.5) > 0
    ahead = np.array([0.4, 8.0], np.float32)                # any beams: bearings given
    assert in_path(ahead, 0.3, 0.5, bearings=[0.0, 1.0]) != 0.0
    assert in_path(ahead, 0.3, 0.5, bearings=[1.5, 0.0]) == 0.0


def test_with_clearance_a_forward_order_into_the_path_rotates_away():
    g = RotationGuard(clearance=0.3)
    corner = _scan({-30: 0.4})
    assert g.choose("fwd", corner) == "rot-left" and g.avoided == 1
    # just after rotating left it keeps rotating left (no reversal), whichever side the return
    assert g.choose("fwd-right", _scan({30: 0.35})) == "rot-left" and g.avoided == 2
    assert g.choose("rot-left", corner) == "rot-left"      # rotations are not forward orders
    assert g.choose("fwd", _scan({})) == "fwd" and g.avoided == 2
    for _ in range(6):                                     # the rotation forgotten (memory 5)
        g.choose("fwd", _scan({}))
    assert g.choose("fwd-right", _scan({30: 0.35})) == "rot-right" and g.avoided == 3
    off = RotationGuard()                                  # clearance 0: no path check
    assert off.choose("fwd", corner) == "fwd" and off.avoided == 0


def test_the_guard_is_the_trees_rules_and_a_rule_can_turn_it_off():
    # snapshots written before the rule was stored whole: the rule their metadata describes
    assert settings_for({"learning": {"rule": "person", "lag": 3}}).clearance == 0.3
    assert settings_for({"learning": {"stride": 1}}).clearance == 0.0
    assert settings_for({}) == settings_for(None) == SCRIPT.guard
    # written whole: what the rule says, also off
    off = PERSON.replace(guard=False)
    assert settings_for({"learning": off.to_dict()}) == GuardSettings(on=False, clearance=0.3)
    assert settings_for({"learning": PERSON.to_dict()}) == PERSON.guard


def test_an_overruled_reversal_drives_straight_on_while_the_path_is_clear():
    clear, blocked = _scan({}), _scan({-10: 0.4})
    g = RotationGuard(clearance=0.3)
    assert g.choose("rot-left", clear) == "rot-left"
    # torn between the two rotations: straight ahead, still counted as overruled (a loop)
    assert g.choose("rot-right", clear) == "fwd"
    assert (g.overruled, g.straight_on, g.looping) == (1, 1, True)
    # the way ahead blocked: the robot keeps turning as it was
    assert g.choose("rot-right", blocked) == "rot-left" and (g.overruled, g.straight_on) == (2, 1)
    assert g.choose("rot-right", clear) == "fwd" and g.straight_on == 2  # still the same turn
    # no path check (clearance 0, or no scan) or straight off: the robot keeps turning
    for g, scan in ((RotationGuard(), clear), (RotationGuard(clearance=0.3), None),
                    (RotationGuard(clearance=0.3, straight=False), clear)):
        g.choose("rot-left", scan)
        assert g.choose("rot-right", scan) == "rot-left"
        assert (g.overruled, g.straight_on) == (1, 0)


def test_the_options_replace_parts_of_the_rules_guard():
    ap = argparse.ArgumentParser()
    add_arguments(ap)
    g = RotationGuard.of(settings(ap.parse_args(["--guard-clearance", "0.3", "--guard-hold",
                                                 "4"])))
    assert (g.clearance, g.hold, g.straight) == (0.3, 4, True)
    assert settings(ap.parse_args(["--no-guard-straight"])).straight is False
    assert settings(ap.parse_args(["--no-guard"])).on is False
    person = {"learning": PERSON.to_dict()}
    assert settings(ap.parse_args([]), person) == PERSON.guard
    assert settings(ap.parse_args(["--guard-clearance", "0"]), person).clearance == 0.0
    off = {"learning": PERSON.replace(guard=False).to_dict()}
    assert settings(ap.parse_args([]), off).on is False
    assert settings(ap.parse_args(["--guard"]), off).on is True
