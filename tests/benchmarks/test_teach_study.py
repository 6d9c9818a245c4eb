"""The in-process teaching study (``benchmarks/bench_teach_study.py``): the console's semantics
it reproduces, and a short session taught by a person model that must give a robot that
follows the wall without a loop."""

from __future__ import annotations

import dataclasses
import math
import types

import pytest

from client.behaviour.guard import RotationGuard, settings_for
from client.behaviour.learning import TreePolicy
from lab.evaluate import evaluate
from lab.harness import resolve_world
from server.world import Goal


class Scripted:
    """A 'person' pressing keys on a timetable: [(from, to, key)] in page seconds."""

    def __init__(self, plan):
        self.plan = plan
        self.style = types.SimpleNamespace(name="scripted")
        self.intent, self.wrong_now = None, False
        self.views = []

    def reset(self):
        self.views = []

    def observe(self, view):
        self.views.append(view)
        for a, b, key in self.plan:
            if a <= view.t < b:
                self.intent = key
                return key
        return None


def test_keys_drive_and_label_release_stops_the_robot(study):
    spec = resolve_world("room")
    person = Scripted([(1.0, 2.0, "fwd"), (3.0, 3.5, "rot-left")])
    rec, learner = study.teach(spec, person, study.make_method("today"), demo=5.0, correct=0.0)
    assert rec.labels == rec.demo_labels == 15 == learner.vectors  # one label per scan held
    x = [p[0] for p in rec.poses]
    assert x[9] == pytest.approx(spec.pose[0], abs=1e-6)  # no key: the console stops it
    assert x[19] - x[9] == pytest.approx(0.4, abs=0.03)  # 1 s of fwd at 0.4 m/s
    assert rec.poses[34][2] - rec.poses[29][2] == pytest.approx(0.4, abs=0.03)  # rot-left
    assert x[-1] == pytest.approx(x[35], abs=1e-6)  # released: stopped again
    assert person.views[12].scan_id == 12 and person.views[12].mode == "demonstrate"


def test_labels_are_tied_to_the_scan_the_person_answered(study):
    spec = resolve_world("room")
    seen = []

    class Recording(study.Method):
        def learner(self, task: str = "wall-following"):
            real = super().learner(task)
            real.observe = lambda ranges, yaw, label: seen.append(ranges.copy()) or True
            return real

    person = Scripted([(1.0, 2.0, "fwd")])
    study.teach(spec, person, Recording("person", 3, {}), demo=3.0, correct=0.0)
    world = study.World(spec)
    world.reset(poses=[tuple(spec.pose)])
    first = world.scan(0)  # the robot stood still until the key: scans 7..10 are the same
    assert len(seen) == 10 and (seen[0] == first).all()
    rec, _ = study.teach(spec, Scripted([(1.0, 2.0, "fwd")]), study.make_method("today"),
                         demo=3.0, correct=0.0)
    assert rec.labels == 10


def test_make_method_reads_options_and_names_mistakes(study):
    m = study.make_method("person:lag=2+k=25+vote=mean+sigma=0.05")
    assert (m.name, m.lag, m.options) == ("person", 2, {"k": 25, "vote": "mean", "sigma": 0.05})
    assert study.make_method("today").lag == 0
    assert study.make_method("person").lag is None and study.make_method("person:lag=3").lag == 3
    with pytest.raises(ValueError, match="unknown method 'magic'"):
        study.make_method("magic")


def test_a_short_session_by_hand_gives_a_robot_that_follows_the_wall(study, people):
    """CI-sized: two minutes demonstrating and one correcting by the steady person model, the
    tree through the guard from every start pose of the room for 60 s: no loop, no collision,
    the wall on the right."""
    spec = resolve_world("room")
    rec, learner = study.teach(spec, people.PEOPLE["steady"](seed=0),
                               study.make_method("person"), demo=120.0, correct=60.0,
                               guard=True)
    assert rec.labels > 1000 and rec.wrong > 0  # the person did press wrong keys
    report = evaluate(spec, RotationGuard.of(settings_for(learner.metadata()),
                                             TreePolicy.from_learner(learner)),
                      seconds=60.0)
    for ep in report["learner"]:
        assert ep["oscillation_loops"] == [], ep["start"]
        assert ep["collisions"] == 0, ep["start"]
        assert ep["wall_band_fraction"] >= 0.8, ep["start"]
        assert not ep["stuck"], ep["start"]
    assert math.isfinite(report["tree"]["nodes"])


def test_a_robot_at_the_goal_is_put_at_the_next_start(study):
    """A world with a goal: reaching it (in either mode), the person puts the robot at the
    world's next start pose and goes on teaching."""
    spec = dataclasses.replace(resolve_world("maze"), goal=Goal((2.0, 1.1), 0.3))
    rec, _ = study.teach(spec, Scripted([(0.0, 4.0, "fwd")]), study.make_method("today"),
                         demo=4.0, correct=0.0)
    x = [p[0] for p in rec.poses]
    assert rec.goals >= 1
    jump = next(k for k in range(1, len(x)) if x[k] < x[k - 1] - 0.1)
    assert x[jump - 1] >= 1.7 - 1e-6  # at the goal's edge, then at a start pose
    assert rec.poses[jump][:2] == pytest.approx(spec.start_poses[1][:2], abs=0.05)
