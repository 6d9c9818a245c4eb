"""``rhbl demo --scenario goals`` end to end, shortened: goals in order taught and learned over
the bus by separate processes. The scripted teacher (``rhbl teacher --behaviour red-green``)
labels each scan with the goal it pursues, the goal it reached and what the fiducial finder
saw; the learner journals them and learns both trees; the controller drives the learner's tree
(following it in the corrective round, the final snapshot after), from each start pose it is
put at, its completion tree moving it on from the red beacon to the green one."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]


def test_goals_are_taught_learned_and_driven_by_separate_processes(tmp_path):
    from client.behaviour.goals import DONE, GoalPolicy, load_policy
    from client.journal import Journal, journal_path

    out = tmp_path / "demo"
    r = subprocess.run(
        [sys.executable, "-m", "lab.cli", "demo", "--scenario", "goals", "--out", str(out),
         "--teach-seconds", "120", "--rounds", "1", "--round-seconds", "120",
         "--drive-seconds", "150", "--starts", "2", "--quiet"],
        cwd=ROOT, capture_output=True, text=True, timeout=220)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "| red-green |" in r.stdout and "in order" in r.stdout, r.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["behaviour"] == "red-green" and s["world"] == "goals-red-green"
    # the teacher reached both beacons in order from each start (its demonstrations end there)
    assert [(m["goals_reached"], m["goals_total"]) for m in s["teacher"]] == [(2, 2), (2, 2)]
    teacher = s["processes"]["teacher"]
    assert teacher["goals_reached"] >= 2 and teacher["no_fiducial"] == 0, teacher
    # every label journaled with its goal; the teacher's "reached" marks among them
    with Journal.open(journal_path(out / "tree.rhbl")) as j:
        recs = list(j.records())
    assert recs and all(rec.goal in (1, 2) for rec in recs)
    assert {rec.reached for rec in recs} >= {1, 2, None}
    assert any(len(rec.seen) for rec in recs)
    # the snapshot holds both trees; the completion tree learned when a goal is done
    policy = load_policy(out / "tree.rhbl")
    assert isinstance(policy, GoalPolicy) and DONE in policy.completion.classes_
    assert policy.metadata["provenance"]["marks"] >= 2
    # the controller following the learner's tree in the corrective round: put at each start,
    # the goals from the first; its completion tree moved it on to the green beacon
    follow = (out / "logs" / "controller-follow.log").read_text()
    assert "--goals-again" in follow and follow.count("the robot was put elsewhere") >= 1, follow
    assert "now goal 2/2: beacon 2" in follow and "completion tree: sphere" in follow, follow
    # the final snapshot drove from both starts, each judged by the goals in order; the
    # controller started the goals again when the robot was put at the second start, unless the
    # learned robot had ended its first drive where that start is (then nothing moved it: its
    # fiducial messages' true poses show no jump)
    log = (out / "logs" / "controller.log").read_text()
    assert "Traceback" not in log and "pursuing goal 1/2" in log, log
    paths = np.load(out / "trajectories.npz")
    drives = sorted((k for k in paths.files if k.startswith("learner") and k.endswith("_poses")),
                    key=lambda k: int(k[len("learner"):-len("_poses")]))
    assert len(drives) == 2
    if math.dist(paths[drives[0]][-1][:2], paths[drives[1]][0][:2]) > 1.0:
        assert log.count("the robot was put elsewhere") >= 1, log
    assert len(s["learned"]) == 2 and all(m["goals_total"] == 2 for m in s["learned"])
    assert len(s["success"]) == 2
