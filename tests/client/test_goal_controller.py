"""rhbl controller drives a tree with goals (docs/goals.md): with each scan it reads the
fiducial message of the same tick, its completion tree moves it from goal to goal (each change
logged, with why) and it ends when every goal is reached. Real processes: a lock-step server of
the red-green world and the controller, stopped by PID."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually  # noqa: E402

from client.behaviour.goals import GoalLearner, parse_goals  # noqa: E402
from lab.behaviours import get  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Decision, DecisionGoal  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]
ROOT = Path(__file__).resolve().parents[2]


def _eager(tmp_path) -> Path:
    """Goals red then green whose completion tree says done at once (the red beacon is in view
    from the world's default pose, the green one hidden behind a box), its action tree fwd."""
    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2]}), task="red-green")
    learner.observe_vector(np.full(b.features.dim, 0.5), "fwd")
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


def _slow(tmp_path) -> Path:
    """Goals red then green: the action tree fwd, the completion tree done when the red beacon
    is seen a little nearer than from the default pose (5.4 m away, its range in units of
    4 x 1.5 m: 0.9; done below some 0.82, a few tenths of a metre on), never with none in view:
    a few decisions pursue goal 1, then goal 2 (the green beacon hidden behind a box) to the
    end."""
    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2], "within": [1.5, 0.6]}),
                          task="red-green")
    learner.observe_vector(np.full(b.features.dim, 0.5), "fwd")
    for _ in range(5):
        learner.observe_completion(np.array([0.0, 1.0]), False)
        learner.observe_completion(np.array([1.0, 0.9]), False)
        learner.observe_completion(np.array([1.0, 0.75]), True)
    return learner.save(tmp_path / "slow.rhbl")


def test_the_decisions_say_the_goal_and_why_it_changed(tmp_path, start_server, client_config):
    """The controller's decisions (``rhbl/<robot>/controller/decision``, what a console and a
    recording get) carry the goal pursued, and from the first change on why it changed."""
    srv = start_server("goals-red-green", lockstep=True)
    got: list[Decision] = []
    with zenoh.open(client_config(srv.endpoint)) as session:
        sub = session.declare_subscriber(
            keys.controller_decision_key("r0"),
            lambda s: got.append(Decision.decode(s.payload.to_bytes())))
        c = Child("controller", rhbl_argv("controller", "--tree", str(_slow(tmp_path)),
                                          "--connect", srv.endpoint, "--seconds", "8"),
                  tmp_path, cwd=ROOT).start()
        try:
            assert c.wait(120) == 0, c.output()
            eventually(lambda: [d.goal for d in got if d.goal is not None and d.goal.index == 1],
                       what="a decision pursuing goal 2", timeout=10)
        finally:
            c.kill()
            sub.undeclare()
    first = [d for d in got if d.goal == DecisionGoal(0, 2, 1)]
    second = [d for d in got if d.goal == DecisionGoal(1, 2, 2)]
    assert first and second and len(first) + len(second) == len(got), [d.goal for d in got]
    assert max(d.scan_id for d in first) < min(d.scan_id for d in second)
    assert all(d.goal_why is None for d in first)  # no goal changed yet
    why = {d.goal_why for d in second}
    assert len(why) == 1, why
    why = why.pop()
    assert why.startswith("goal 1/2 (beacon 1) done at ") and "completion tree: sphere" in why
    assert "at beacon 1 (range 4.9" in why or "at beacon 1 (range 5." in why, why
    assert why in c.output()  # the log says the same
