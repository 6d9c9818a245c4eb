"""rhbl controller drives a tree with goals (docs/goals.md): with each scan it reads the
fiducial message of the same tick, its completion tree moves it from goal to goal (each change
logged, with why) and it ends when every goal is reached. Real processes: a lock-step server of
the red-green world and the controller, stopped by PID."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from client.behaviour.goals import GoalLearner, parse_goals  # noqa: E402
from lab.behaviours import get  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]
ROOT = Path(__file__).resolve().parents[2]


def _eager(tmp_path) -> Path:
    """Goals red then green whose completion tree says done at once (the red beacon is in view
    from the world's default pose, the green one hidden behind a box), its action tree fwd."""
    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2]}), task="red-green")
    learner.observe(np.full(b.features.dim, 0.5), "fwd")
    learner.observe_completion(np.array([0.5, 0.5]), True)
    return learner.save(tmp_path / "eager.rhbl")


def test_the_controller_goes_from_goal_to_goal_and_says_why(tmp_path, start_server):
    srv = start_server("goals-red-green", lockstep=True)
    c = Child("controller", rhbl_argv("controller", "--tree", str(_eager(tmp_path)),
                                      "--connect", srv.endpoint, "--seconds", "60"),
              tmp_path, cwd=ROOT).start()
    try:
        assert c.wait(120) == 0, c.output()
    finally:
        c.kill()
    text = c.output()
    assert "pursuing goal 1/2: beacon 1" in text, text
    # the fiducial message of the scan's tick: the red beacon seen 5.4 m away
    assert "goal 1/2 (beacon 1) done at " in text and "completion tree: sphere" in text, text
    assert "at beacon 1 (range 5.4" in text and "now goal 2/2: beacon 2" in text, text
    assert "goal 2/2 (beacon 2) done at " in text and "(none in view)" in text, text
    assert "every goal reached (finished (2 goals)): done" in text, text
    assert "controller stopped after 1 commands" in text, text
