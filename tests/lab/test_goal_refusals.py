"""A behaviour with goals in order: rhbl refine practises a tree with goals (its action tree,
the completion tree kept) and refuses a tree of the other kind."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _rhbl(*args):
    return subprocess.run([sys.executable, "-m", "lab.cli", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)


def _goal_tree(tmp_path: Path) -> Path:
    """A tiny tree with goals of red-green (two vectors, one completion mark)."""
    import numpy as np

    from client.behaviour.goals import GoalLearner, parse_goals
    from lab.behaviours import get

    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2]}), task="red-green")
    learner.observe_vector(np.full(b.features.dim, 0.5), "fwd")
    learner.observe_vector(np.full(b.features.dim, 0.2), "rot-left")
    learner.observe_completion(np.array([0.5, 0.5]), True)
    learner.observe_completion(np.array([0.1, 0.9]), False)
    return learner.save(tmp_path / "goals.rhbl")


@pytest.mark.parametrize("command", ["refine", "evaluate"])
def test_a_tree_of_the_other_kind_is_refused(tmp_path, command):
    """A goal behaviour given one reactive tree, or a reactive behaviour given a goal
    snapshot (by --behaviour or by the world's behaviour): one line, exit 2, before any
    episode (rhbl evaluate raised an AttributeError from its first episode)."""
    single = Path(__file__).resolve().parents[1] / "rhbl" / "data" / "room-1200.rhbl"
    out = (["--out", str(tmp_path / "t2.rhbl")] if command == "refine"
           else ["--json", str(tmp_path / "t2.rhbl")])
    cases = [(["--behaviour", "red-green"], single, "'red-green' has goals in order, which"),
             (["--behaviour", "wall-following"], _goal_tree(tmp_path),
              "pursues goals in order (an action and a completion tree), but behaviour "
              "'wall-following' has none")]
    if command == "evaluate":  # the world's behaviour: red-green's world
        cases.append((["--world", "goals-red-green"], single, "'red-green' has goals in order"))
    for given, tree, says in cases:
        r = _rhbl(command, *given, "--tree", str(tree), *out)
        assert r.returncode == 2 and says in r.stderr, r.stderr
        assert "Traceback" not in r.stderr
        assert not (tmp_path / "t2.rhbl").exists()


@pytest.mark.slow
def test_refine_practises_a_tree_with_goals_and_keeps_its_completion_tree(tmp_path):
    from client.behaviour.goals import GoalPolicy

    tree = _goal_tree(tmp_path)
    out = tmp_path / "refined.rhbl"
    r = _rhbl("refine", "--behaviour", "red-green", "--tree", str(tree), "--out", str(out),
              "--seconds", "5", "--scales", "none", "--minutes", "0.02", "--workers", "1")
    assert r.returncode == 0, r.stdout + r.stderr
    before, after = GoalPolicy.load(tree), GoalPolicy.load(out)
    assert after.goals == before.goals
    assert after.completion.node_count_ == before.completion.node_count_
    rec = after.metadata["refinement"][-1]
    assert rec["behaviour"] == "red-green" and rec["episodes"] >= 1
    assert set(rec["worlds_after"]) == {"goals-red-green", "eval-goals-red-green-wide",
                                        "eval-goals-red-green-l"}
    assert "goals-red-green (taught): success" in r.stdout


def test_a_wall_behaviour_is_still_taken():
    r = _rhbl("learner", "--behaviour", "wall-following", "--help")
    assert r.returncode == 0, r.stderr


def test_evaluate_of_a_goal_tree_refuses_the_options_it_cannot_apply(tmp_path):
    """Options rhbl evaluate has for one tree but not yet for a tree with goals are refused
    by name (they were silently ignored), before any episode runs."""
    import numpy as np

    from client.behaviour.goals import GoalLearner, parse_goals
    from lab.behaviours import get

    b = get("red-green")
    learner = GoalLearner(b.features, parse_goals({"beacons": [1, 2]}), task="red-green")
    learner.observe_vector(np.full(b.features.dim, 0.5), "fwd")
    learner.observe_completion(np.array([0.5, 0.5]), True)
    tree = learner.save(tmp_path / "goals.rhbl")
    for extra in (["--guard-clearance", "0.1"], ["--no-guard-straight"]):
        r = _rhbl("evaluate", "--tree", str(tree), "--world", "goals-red-green", *extra)
        assert r.returncode == 2 and extra[0] in r.stderr and "with goals" in r.stderr, r.stderr


@pytest.mark.slow
def test_a_tree_with_goals_is_evaluated_on_a_pool_as_here(tmp_path):
    """``rhbl evaluate --workers 2`` of a tree with goals (judged alone, with the guard's run
    beside it by default, and alone only) gives the report it gives in this process."""
    import json

    tree = _goal_tree(tmp_path)
    for guard in ("--guard", "--no-guard"):
        reports = []
        for workers in ("1", "2"):
            out = tmp_path / f"r{guard}{workers}.json"
            r = _rhbl("evaluate", "--tree", str(tree), "--world", "goals-red-green",
                      "--episodes", "3", "--seconds", "8", "--workers", workers, guard,
                      "--json", str(out))
            assert r.returncode == 0, r.stdout + r.stderr
            reports.append(json.loads(out.read_text()))
        assert reports[0] == reports[1]
        assert reports[0]["episodes"] == 3 and len(reports[0]["learner"]) == 3
        # judged by the trees alone; the guard's run beside it unless --no-guard
        assert reports[0]["judged"] == "the trees alone"
        if guard == "--guard":
            assert len(reports[0]["guarded"]["success"]) == 3 and reports[0]["guard"]
        else:
            assert reports[0]["guarded"] is None and reports[0]["guard"] is None


@pytest.mark.slow
def test_a_tree_with_goals_judged_on_a_pool_is_judged_as_in_this_process(tmp_path):
    from client.behaviour.goals import GoalPolicy
    from lab.behaviours import get, world_of
    from lab.goals import evaluate_goals, guarded
    from lab.practice import Runner

    b = get("red-green")
    spec = world_of(b, "goals-red-green")
    tree = GoalPolicy.load(_goal_tree(tmp_path))
    for on in (True, False):
        here = evaluate_goals(spec, guarded(tree, on), b, episodes=2, seconds=8.0)
        with Runner(workers=2) as runner:
            there = evaluate_goals(spec, guarded(tree, on), b, episodes=2, seconds=8.0,
                                   runner=runner)
        assert there["learner"] == here["learner"] and there["teacher"] == here["teacher"]
        assert there["guard"] == here["guard"]
