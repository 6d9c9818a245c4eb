"""The controller's guard: a safety layer against rot-left/rot-right loops (the paper's
section 7.3) and forward orders into a wall, between the tree and the robot.

It is not the learning: its settings are part of a tree's learning rule
(``client.behaviour.rule.GuardSettings``, stored in the snapshot: ``settings_for``), a rule or
a behaviour can turn it off (``on``), ``rhbl controller --no-guard`` drives without it, and
``rhbl evaluate`` judges the tree alone and reports, beside it, the guarded run and what the
guard did (``interventions``).

A learned tree can bounce between a rotate-left and a rotate-right sphere forever: each
rotation brings the robot into the other sphere (a loop as ``client.behaviour.loops`` defines
it, the one definition; the guard overrules the switch, ``loops.reverses``, as it comes). ``RotationGuard`` wraps any policy with a
hysteresis on the direction of rotation, as a person or the scripted teacher would: once the
robot rotates one way, an order to rotate the other way is overruled (the robot keeps turning
as it was) until the policy asks for anything but that reversal, for at most ``hold`` scans in a
row; then the policy's answer is taken as it is. Every overruled reversal is counted, and
``looping`` says the guard had to step in lately: the place where a person should show the way
out (a loop is a state the teacher has not shown yet).

Given the scan, the guard also keeps the robot from driving into what is straight ahead: a
forward order while a laser return lies in the robot's path (within ``lookahead`` m ahead and
``clearance`` m of its centre line: ``in_path``) becomes a rotation in place, the way the robot
rotated lately or else away from that return (counted ``avoided``). A tree taught in one room
meets corners it never saw elsewhere (a convex corner approached at an angle); a person's
demonstrations show how to follow a wall, not how close is too close.

With the path check on, an overruled reversal drives straight on while the path ahead is clear
(``straight``, the default): a tree that asks for the other rotation right after one is torn
between the two, and straight ahead is the action between them. Keeping on turning instead
(``straight=False``, the guard before) spins a robot in place for as long as its tree is torn:
the trees of a person who steers only by rotating in place (``bang`` in
``benchmarks/people.py``) are torn that way along every wall (docs/teaching.md). Without the
path check (``clearance`` 0, or no scan) the guard cannot know the way ahead is free and keeps
turning.

    tree = TreePolicy.load("tree.rhbl")
    policy = RotationGuard.of(settings_for(tree.metadata), tree)   # as the tree's rule says
    action = policy.act(ranges, pose)        # one call per scan
    policy.looping, policy.overruled         # for the console: "stuck here: show it the way"
    policy.avoided                           # forward orders turned into a rotation
    policy.straight_on                       # overruled reversals driven straight on

    guard = RotationGuard()                  # no policy: the controller asks its tree itself
    action = guard.choose(tree_action, ranges, bearings)  # one call per scan (ranges: optional)

Pure (no zenoh): the controller process and the in-process harness use this same code.
"""

from __future__ import annotations

__all__ = ["RotationGuard", "add_arguments", "in_path", "settings", "settings_for"]

import argparse
import dataclasses

import numpy as np

from process import arguments

from .loops import ROTATIONS, reverses
from .rule import GuardSettings, LearningRule

_FORWARD = ("fwd", "fwd-left", "fwd-right")


def settings_for(metadata) -> GuardSettings:
    """The guard a tree is driven through: its learning rule's (``LearningRule.of`` its
    snapshot metadata): for a tree taught by hand the loop hysteresis and the path check
    (0.3 m), for the scripted teacher's the hysteresis alone (its demonstrations keep their
    own distance; docs/teaching.md: with the check its trees collided less but reached the
    5-tier maze's goal less often), for a tree with goals both (``rule.for_goals``)."""
    return LearningRule.of(metadata).guard


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The guard's options as ``rhbl controller`` and ``rhbl evaluate`` take them, each
    default the tree's learning rule's (``settings``)."""
    parser.add_argument("--guard", action=argparse.BooleanOptionalAction, default=None,
                        help="the controller's guard, a safety layer (client.behaviour.guard): "
                             "never reverse a rotation at once, and (with a path check) no "
                             "forward order into a return straight ahead; default: as the "
                             "tree's learning rule says (on for the shipped rules)")
    parser.add_argument("--guard-hold", type=arguments.non_negative_int, default=None,
                        metavar="SCANS",
                        help="with the guard: at most this many overruled reversals in a row, "
                             "then the tree's answer is taken (default: the rule's, 30: 3 s)")
    parser.add_argument("--guard-straight", action=argparse.BooleanOptionalAction,
                        default=None,
                        help="with the guard and its path check: an overruled reversal drives "
                             "straight on while the path ahead is clear (--no-guard-straight: "
                             "the robot keeps turning as it was; default: the rule's, on)")
    parser.add_argument("--guard-clearance", type=arguments.non_negative_float,
                        default=None, metavar="M",
                        help="with the guard: a forward order while a laser return lies within "
                             "the rule's lookahead (0.5 m) ahead and M m of the robot's centre "
                             "line becomes a rotation in place (0: off; default: the rule's, "
                             "0.3 for a tree taught by hand, 0 for the scripted teacher's)")


def settings(args: argparse.Namespace, metadata=None) -> GuardSettings:
    """The guard ``add_arguments``' options ask for a tree of ``metadata``: its rule's
    (``settings_for``), each option given replacing its part (``--no-guard``: off)."""
    base = settings_for(metadata)
    changes = {name: value for name, value in (
        ("on", args.guard), ("hold", args.guard_hold), ("straight", args.guard_straight),
        ("clearance", args.guard_clearance)) if value is not None}
    return dataclasses.replace(base, **changes) if changes else base


def in_path(ranges, clearance: float, lookahead: float, bearings=None) -> float:
    """The side of the nearest laser return in the robot's path straight ahead: a point at
    most ``lookahead`` m ahead and less than ``clearance`` m to either side of the robot's
    centre line (``bearings`` in rad, 0 ahead, positive left; default: spread evenly over 180
    degrees, ``ranges[0]`` on the right). Negative: it is on the right, positive: on the left,
    0.0: the path is clear."""
    r = np.asarray(ranges, dtype=np.float64)
    b = (np.linspace(-np.pi / 2, np.pi / 2, len(r)) if bearings is None
         else np.asarray(bearings, dtype=np.float64))
    x, y = r * np.cos(b), r * np.sin(b)
    hit = np.flatnonzero((x > 0) & (x < lookahead) & (np.abs(y) < clearance) & np.isfinite(r))
    if not len(hit):
        return 0.0
    near = hit[np.argmin(r[hit])]
    return float(y[near]) if y[near] != 0 else -1e-9


class RotationGuard:
    """A policy that never reverses its rotation at once (see the module's docstring).

    ``hold``: at most this many scans in a row of overruled reversals (30 = 3 s at 10 Hz: a
    rotation of about 140 degrees at the default 0.8 rad/s); ``memory``: a rotation counts as
    the current one for this many scans after the robot stopped rotating (a reversal right after
    a short arc is a loop too). ``looping`` is True for ``memory`` scans after a reversal was
    overruled. ``straight``: with the path check (``clearance`` > 0), an overruled reversal drives
    straight on (``fwd``) while the path ahead is clear (counted ``straight_on``), else the robot
    keeps turning. ``classifier``, ``features``, ``actions``, ``metadata`` are the wrapped
    policy's. Without a policy, ``choose(action)`` filters the actions of any source (the
    controller, whose tree may be swapped while the guard's memory goes on)."""

    def __init__(self, policy=None, hold: int = GuardSettings.hold,
                 memory: int = GuardSettings.memory, clearance: float = GuardSettings.clearance,
                 lookahead: float = GuardSettings.lookahead,
                 straight: bool = GuardSettings.straight):
        self.policy = policy
        self.apply(GuardSettings(hold=hold, memory=memory, clearance=clearance,
                                 lookahead=lookahead, straight=straight))
        self.overruled = 0
        self.straight_on = 0  # overruled reversals driven straight on (the path ahead clear)
        self.avoided = 0  # forward orders turned into a rotation away from a return in the path
        self.reset()

    @classmethod
    def of(cls, settings: GuardSettings, policy=None) -> RotationGuard:
        """The guard of ``settings`` (a rule's ``GuardSettings``), wrapping ``policy``."""
        return cls(policy, hold=settings.hold, memory=settings.memory,
                   clearance=settings.clearance, lookahead=settings.lookahead,
                   straight=settings.straight)

    def apply(self, settings: GuardSettings) -> None:
        """Take ``settings`` (a swapped tree's rule's) and keep what the robot is doing."""
        self.hold, self.memory = int(settings.hold), int(settings.memory)
        self.clearance, self.lookahead = float(settings.clearance), float(settings.lookahead)
        self.straight = bool(settings.straight)

    @property
    def interventions(self) -> dict:
        """What the guard did instead of the tree: reversals overruled (and of them driven
        straight on) and forward orders turned into a rotation."""
        return {"overruled": self.overruled, "straight_on": self.straight_on,
                "avoided": self.avoided}

    def __getattr__(self, name):  # classifier, features, actions, metadata: the policy's
        if name == "policy":
            raise AttributeError(name)
        return getattr(self.policy, name)

    def reset(self) -> None:
        if self.policy is not None:
            self.policy.reset()
        self._turn: str | None = None   # the current rotation
        self._since = self.memory + 1   # scans since the robot last rotated that way
        self._held = 0                  # overruled reversals in a row
        self._last_overruled = self.memory + 1

    @property
    def looping(self) -> bool:
        return self._last_overruled <= self.memory

    def act(self, ranges, pose) -> str:
        return self.choose(self.policy.act(ranges, pose), ranges)

    def _path(self, ranges, bearings) -> float | None:
        """``in_path`` of the scan with the guard's clearance; None: no path check (clearance
        0, or no scan)."""
        if self.clearance <= 0 or ranges is None:
            return None
        return in_path(ranges, self.clearance, self.lookahead, bearings)

    def choose(self, want: str, ranges=None, bearings=None) -> str:
        """The action to execute when the policy wants ``want`` (one call per scan). With
        ``clearance`` > 0 and the scan's ``ranges``: a forward order while a laser return lies
        in the robot's path (``in_path``: within ``lookahead`` m ahead, ``clearance`` m of the
        centre line) becomes a rotation in place: the way the robot rotated within ``memory``
        scans, else away from that return (counted ``avoided``); and an overruled reversal
        drives straight on while that path is clear (``straight``, counted ``straight_on``)."""
        if want in _FORWARD:
            side = self._path(ranges, bearings)
            if side:
                self.avoided += 1
                # rotating in place is safe (a round robot); keep turning as it was, if it
                # did lately (no reversal: the hysteresis below), else away from the return
                want = (self._turn if self._turn is not None and self._since <= self.memory
                        else "rot-left" if side < 0 else "rot-right")
                self._last_overruled += 1
                self._held, self._turn, self._since = 0, want, 0
                return want
        self._last_overruled += 1
        if (reverses(self._turn, want) and self._since <= self.memory
                and self._held < self.hold):
            self._held += 1
            self.overruled += 1
            self._last_overruled = 0
            self._since = 0
            if self.straight and self._path(ranges, bearings) == 0.0:  # checked, and clear
                self.straight_on += 1
                return "fwd"  # torn between the two rotations: the action between them
            return self._turn
        self._held = 0
        if want in ROTATIONS:
            self._turn, self._since = want, 0
        else:
            self._since += 1
        return want
