"""``rhbl demo`` end to end, shortened: every process starts (the teacher demonstrates from two
start poses, one corrective round with the correcting teacher and the following controller, the
final tree drives), the tables and the files appear."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

ROOT = Path(__file__).resolve().parents[2]


def test_short_demo(tmp_path):
    out = tmp_path / "demo"
    r = subprocess.run(
        [sys.executable, "-m", "lab.cli", "demo", "--out", str(out), "--teach-seconds", "30",
         "--rounds", "1", "--round-seconds", "20", "--drive-seconds", "20", "--starts", "2",
         "--quiet", "--console", "127.0.0.1:0", "--record"],
        cwd=ROOT, capture_output=True, text=True, timeout=150)
    assert r.returncode == 0, r.stdout + r.stderr
    # the console served the page beside the others (view-only) and said where
    assert "console: http://127.0.0.1:" in r.stdout
    assert "serving the console" in (out / "logs/console.log").read_text()
    assert "| wall-following |" in r.stdout and "demonstration vectors" in r.stdout
    assert "Corrective rounds" in r.stdout and "What the robots did" in r.stdout
    # the last lines name every file it made (it left out trajectories.npz and run.mcap)
    made = next(ln for ln in r.stdout.splitlines() if ln.startswith("output: "))
    for name in ("tree.rhbl", "tree.rhbl.journal", "paths.png", "summary.json",
                 "trajectories.npz", "run.mcap", "logs/"):
        assert name in made, made
    for name in ("tree.rhbl", "tree.rhbl.journal", "paths.png", "summary.json",
                 "trajectories.npz", "run.mcap", "logs/learner.log", "logs/teacher.log",
                 "logs/teacher-correct.log", "logs/controller-follow.log",
                 "logs/controller.log"):
        assert (out / name).exists(), name
    assert "correcting from" in (out / "logs/teacher-correct.log").read_text()
    s = json.loads((out / "summary.json").read_text())
    assert len(s["teacher"]) == 2 and all(m["seconds"] >= 29 for m in s["teacher"])
    assert s["demonstration_labels"] >= 590
    (rnd,) = s["rounds"]
    # one bus tap fed the episodes and the recording: it holds at least the round's scans
    from client.recording.inspect import recording_summary

    rec = recording_summary(out / "run.mcap")
    assert rec["robots"]["r0"]["scans"] >= rnd["scans"] > 0 and not rec["notes"], rec
    # every scan of the round labelled or, when the correcting teacher fell behind the
    # lock-step controller on a busy machine, counted as missed by it (its --stats)
    corrector = s["processes"]["teacher-correct"]
    assert rnd["episodes"] == 2 and rnd["seconds"] >= 39 and corrector["exit"] == 0
    assert rnd["labels"] + corrector["missed"] >= 0.95 * rnd["scans"], (rnd, corrector)
    # the labels of both phases are in the tree
    assert s["tree"]["nodes"] > 1 and rnd["labels"] > 0
    assert s["tree"]["vectors"] >= s["demonstration_labels"] + rnd["labels"], (s["tree"], rnd)
    assert len(s["learned"]) == 2 and all(m["seconds"] >= 19 for m in s["learned"])


def test_demo_fails_loudly(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "lab.cli", "demo", "--out", str(tmp_path / "d"),
         "--world", "no-such-world"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no-such-world" in r.stderr and "Traceback" not in r.stderr


def test_demo_exits_nonzero_when_a_child_fails(tmp_path):
    out = tmp_path / "d"
    out.mkdir()
    (out / "tree.rhbl").write_bytes(b"not a tree")  # the learner refuses to overwrite it
    r = subprocess.run(
        [sys.executable, "-m", "lab.cli", "demo", "--out", str(out), "--quiet"],
        cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "learner" in r.stderr and "exited early with status 2" in r.stderr
    assert "has no journal" in r.stderr
