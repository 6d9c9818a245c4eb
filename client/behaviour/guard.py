"""The controller's guard against rot-left/rot-right loops (the paper's section 7.3).

A learned tree can bounce between a rotate-left and a rotate-right sphere forever: each
rotation brings the robot into the other sphere. ``RotationGuard`` wraps any policy with a
hysteresis on the direction of rotation, as a person or the scripted teacher would: once the
robot rotates one way, an order to rotate the other way is overruled (the robot keeps turning
as it was) until the policy asks for anything but that reversal, for at most ``hold`` scans in a
row; then the policy's answer is taken as it is. Every overruled reversal is counted, and
``looping`` says the guard had to step in lately: the place where a person should show the way
out (a loop is a state the teacher has not shown yet).

    policy = RotationGuard(TreePolicy.load("tree.rhbl"))
    action = policy.act(ranges, pose)        # one call per scan
    policy.looping, policy.overruled         # for the console: "stuck here: show it the way"

    guard = RotationGuard()                  # no policy: the controller asks its tree itself
    action = guard.choose(tree_action)       # the action to execute, one call per scan

Pure (no zenoh): the controller process and the in-process harness use this same code.
"""

from __future__ import annotations

__all__ = ["RotationGuard"]

_OPPOSITE = {"rot-left": "rot-right", "rot-right": "rot-left"}


class RotationGuard:
    """A policy that never reverses its rotation at once (see the module's docstring).

    ``hold``: at most this many scans in a row of overruled reversals (30 = 3 s at 10 Hz: a
    rotation of about 140 degrees at the default 0.8 rad/s); ``memory``: a rotation counts as
    the current one for this many scans after the robot stopped rotating (a reversal right after
    a short arc is a loop too). ``looping`` is True for ``memory`` scans after a reversal was
    overruled. ``classifier``, ``features``, ``actions``, ``metadata`` are the wrapped
    policy's. Without a policy, ``choose(action)`` filters the actions of any source (the
    controller, whose tree may be swapped while the guard's memory goes on)."""

    def __init__(self, policy=None, hold: int = 30, memory: int = 5):
        if hold < 0 or memory < 0:
            raise ValueError(f"hold and memory must be >= 0 scans, got {hold}, {memory}")
        self.policy = policy
        self.hold, self.memory = int(hold), int(memory)
        self.overruled = 0
        self.reset()

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
        return self.choose(self.policy.act(ranges, pose))

    def choose(self, want: str) -> str:
        """The action to execute when the policy wants ``want`` (one call per scan)."""
        self._last_overruled += 1
        if (self._turn is not None and want == _OPPOSITE.get(self._turn)
                and self._since <= self.memory and self._held < self.hold):
            self._held += 1
            self.overruled += 1
            self._last_overruled = 0
            self._since = 0
            return self._turn
        self._held = 0
        if want in _OPPOSITE:
            self._turn, self._since = want, 0
        else:
            self._since += 1
        return want
