"""The live rotate-left/rotate-right loop detector: on at the fourth switch within the window,
off once the robot stops switching for longer than the window."""

from __future__ import annotations

import pytest

from client.behaviour.loops import LoopDetector


def test_a_loop_is_four_switches_each_within_the_window():
    d = LoopDetector()
    t = 0.0
    assert not d.observe(t, "fwd")
    seen = []
    for k in range(6):  # rot-left, rot-right, ... one step each
        t += 0.1
        seen.append(d.observe(t, ("rot-left", "rot-right")[k % 2]))
    assert seen == [False, False, False, False, True, True]  # the 4th switch is the 5th step
    assert d.current.alternations == 5 and d.current.start == pytest.approx(0.1)
    assert d.observe(t + 6.0, "fwd")  # within the window of the last switch: still looping
    assert not d.observe(t + 6.2, "fwd")  # quiet for longer: the loop ended
    assert len(d.loops) == 1 and d.loops[0].alternations == 5


def test_other_actions_and_long_runs_are_no_switches():
    d = LoopDetector(min_alternations=2)
    for t, a in enumerate(["rot-left", "fwd", "rot-right", "fwd", "rot-left"]):
        assert not d.observe(float(t), a)
    d.flush()
    assert d.loops == []
    d.reset()
    for t, a in enumerate(["rot-left"] * 3 + ["rot-right"] * 3 + ["rot-left"]):
        d.observe(float(t), a)
    assert d.looping and d.current.alternations == 2


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="min_alternations"):
        LoopDetector(min_alternations=0)
    with pytest.raises(ValueError, match="window_s"):
        LoopDetector(window_s=0)
