"""Rotate-left/rotate-right loops, detected as they happen: the one definition of a loop.

The paper (section 7.3) saw a learned robot bounce between rotate-left and rotate-right spheres:
a state the teacher has not shown yet. A *switch* is a run of one of the two actions followed
directly by a run of the other (``a`` then ``b``, or ``b`` then ``a``; another action in
between breaks the pair but not the loop); a *loop* is a group of at least ``min_alternations``
switches, each within ``window_s`` of the one before. The same definition serves the batch
metric ``lab.metrics.oscillation_loops`` (an evaluated episode), the console's live "the robot
is stuck here" and the controller's guard (``client.behaviour.guard.RotationGuard``), which
overrules the switch defined here (``reverses``) before it can happen:

    detector = LoopDetector()                  # min_alternations=4, window_s=6.0
    for t, action in commands:                 # sim time of the scan, the action driven
        if detector.observe(t, action):        # True while the robot loops
            ...                                # detector.current: the loop (Loop)
    detector.flush(); detector.loops           # every loop that ended (and the last one)

Pure (no I/O, no clock of its own): give it the times.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ROTATIONS", "Loop", "LoopDetector", "reverses"]

ROTATIONS = ("rot-left", "rot-right")  # the pair whose alternation is a loop
_EPS = 1e-6  # s: times that are k * dt apart compare as equal


def reverses(current: str | None, action: str, pair=ROTATIONS) -> bool:
    """True when ``action`` after a run of ``current`` is a switch: the other of the pair."""
    return current is not None and action != current and {current, action} == set(pair)


@dataclass
class Loop:
    """A group of switches: ``first`` the time of its first switch, ``last`` of its latest,
    ``start`` the time of the step before the first switch (where the loop began),
    ``alternations`` how many switches."""

    first: float
    last: float
    start: float
    alternations: int


class LoopDetector:
    """Online detection of ``a``/``b`` alternation loops (see the module)."""

    def __init__(self, min_alternations: int = 4, window_s: float = 6.0,
                 a: str = ROTATIONS[0], b: str = ROTATIONS[1]):
        if min_alternations < 1 or not window_s > 0:
            raise ValueError(f"min_alternations must be >= 1 and window_s > 0, got "
                             f"{min_alternations} and {window_s}")
        self.min_alternations, self.window_s = int(min_alternations), float(window_s)
        self.pair = (a, b)
        self.loops: list[Loop] = []  # the loops that ended (group closed, long enough)
        self.reset()

    def reset(self) -> None:
        """Forget the current run and group (a teleport, another driver); ``loops`` stay."""
        self._run: str | None = None  # the action of the current run
        self._prev_t: float | None = None  # the time of the step before this one
        self.current: Loop | None = None  # the group of switches being counted
        self._t: float | None = None

    def observe(self, t: float, action: str) -> bool:
        """One step: the action driven at time ``t`` (non-decreasing). True while looping."""
        t = float(t)
        if self.current is not None and t - self.current.last > self.window_s + _EPS:
            self._close()
        if reverses(self._run, action, self.pair):
            if self.current is None:
                start = self._prev_t if self._prev_t is not None else t
                self.current = Loop(first=t, last=t, start=start, alternations=1)
            else:
                self.current.last = t
                self.current.alternations += 1
        if action != self._run:
            self._run = action
        self._prev_t, self._t = t, t
        return self.looping

    @property
    def looping(self) -> bool:
        """True when the current group of switches is a loop (and has not timed out)."""
        c = self.current
        return c is not None and c.alternations >= self.min_alternations

    def flush(self) -> None:
        """Close the current group (the end of an episode): a loop goes to ``loops``."""
        if self.current is not None:
            self._close()

    def _close(self) -> None:
        if self.looping:
            self.loops.append(self.current)
        self.current = None
