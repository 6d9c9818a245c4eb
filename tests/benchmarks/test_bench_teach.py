"""A CI-sized run of ``benchmarks/bench_teach.py``: one person model (``steady``) drives the
real console page in a real headless Chromium for a short budget (demonstrating, then
correcting a ``--follow`` controller), against a real server, learner, console and controller;
then the learner's saved tree is evaluated in the room it was taught in.

The learner runs with its defaults (``--teacher auto``: the page's labels are a person's, so
lag pairing and majority labels) and the controller keeps its loop guard (on by default); the
session is recorded and the paper's literal algorithm retrained from it as the baseline. The harness must work every time (the
labels given at the page all reach the learner's journal, the controller drove in correct mode,
a tree came out); the learned robot must not loop nor leave the wall. A 45-second budget is far
below the issue's 4 + 2 minutes and does not always teach the whole room: when the learned
robot loops or leaves the wall, that part is an expected failure, said with the figures
(``benchmarks/bench_teach.py`` measures the full budget).
"""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("selenium")

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(420)]


@pytest.fixture(scope="module")
def bench():
    """``benchmarks/bench_teach.py`` (it puts ``benchmarks/`` and the browser helpers on the
    path itself)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    return importlib.import_module("bench_teach")


def test_a_short_person_teaches_a_robot_that_follows_the_wall(bench, tmp_path):
    from browser import find_chromium, in_ci

    found = find_chromium()
    if isinstance(found, str):
        if in_ci():
            pytest.fail(f"CI=true and {found}")
        pytest.skip(found)
    r, lit = bench.run_one("steady", 0, demo=45.0, correct=20.0, unseen=(), eval_episodes=2,
                           eval_seconds=60.0, literal=bench.LITERAL, workdir=tmp_path,
                           guards=("default",), log=lambda s: None)
    # the learner's default (--teacher auto) took the person rule for the page's labels
    assert r["rule"] == "person"
    # the literal baseline: the same session's labels (its recording), the paper's rule
    assert lit["learner"] == "literal" and lit["labels"] == r["labels"]
    assert lit["labels_standing"] >= r["labels"]["given"] - r["labels"]["withdrawn"] - 5
    assert lit["tree"]["nodes"] >= 2 and lit["eval"]["room"]["episodes"] == 2
    # what the person saw: the page kept drawing and the person kept deciding
    assert r["demonstrate"]["page_fps"] > 0 and r["demonstrate"]["person_hz"] > 0
    # the harness: a person at the real page, every label delivered and kept
    assert r["demonstrate"]["seconds"] >= 45.0 and r["correct"]["seconds"] >= 20.0
    assert r["demonstrate"]["presses"] > 5 and r["demonstrate"]["frames_with_a_key"] > 0
    assert r["labels"]["given"] >= 200  # 45 s at 10 Hz, minus hesitations
    assert r["labels"]["waiting"] == 0
    assert r["labels"]["held"] == r["labels"]["given"]
    assert r["labels_standing"] == r["labels"]["given"] - r["labels"]["withdrawn"]
    assert r["tree"]["nodes"] >= 2
    ev = r["eval"]["room"]
    assert ev["episodes"] == 2
    # the learned robot: no loop, on the wall
    if r["loops"] or ev["wall_band"] < 0.8 or ev["collisions"]:
        pytest.xfail(f"45 s of teaching did not teach the room: {r['loops']} loops, "
                     f"wall band {ev['wall_band']:.2f}, {ev['collisions']} collisions, success "
                     f"{ev['success_rate']:.0%} ({r['tree']['nodes']} nodes, "
                     f"{r['labels']['given']} labels)")


def test_evaluate_again_names_a_bad_file_or_a_missing_tree(bench, tmp_path, capsys):
    """``--evaluate-again`` (no session) refuses with one line and exit 2 what it cannot use."""
    assert bench.main(["--evaluate-again", str(tmp_path / "none.json")]) == 2
    assert "--evaluate-again" in capsys.readouterr().err
    runs = tmp_path / "runs.json"
    runs.write_text('[{"tree_path": "%s"}]' % (tmp_path / "gone.rhbl"))
    assert bench.main(["--evaluate-again", str(runs)]) == 2
    err = capsys.readouterr().err
    assert "trees not found" in err and "gone.rhbl" in err


def test_a_person_teaches_another_behaviour_at_the_page(bench, tmp_path):
    """A person for any behaviour (``calm``, the corridor-centring expert's intent in a
    person's hands) teaches corridor centring at the real page, briefly; the tree is evaluated
    alone and through the guard in its teaching world and one held-out corridor. The harness
    must work every time; what 45 s teaches is not asserted (bench_teach.py measures that)."""
    from browser import find_chromium, in_ci

    found = find_chromium()
    if isinstance(found, str):
        if in_ci():
            pytest.fail(f"CI=true and {found}")
        pytest.skip(found)
    (r,) = bench.run_one("calm", 0, demo=45.0, correct=20.0, behaviour="corridor-centring",
                         unseen=("eval-corridor-narrow",), eval_episodes=1, eval_seconds=30.0,
                         workdir=tmp_path, log=lambda s: None)
    assert r["behaviour"] == "corridor-centring" and r["world"] == "corridor-winding"
    assert r["rule"] == "person"
    # the person drove: keys pressed and every label delivered and kept
    assert r["demonstrate"]["presses"] > 5 and r["demonstrate"]["frames_with_a_key"] > 0
    assert r["labels"]["given"] >= 200 and r["labels"]["waiting"] == 0
    assert r["labels_standing"] == r["labels"]["given"] - r["labels"]["withdrawn"]
    assert r["tree"]["nodes"] >= 2
    # both evaluations, in both worlds, the guard's interventions counted
    for mode in ("alone", "guard"):
        assert set(r["evals"][mode]) == {"corridor-winding", "eval-corridor-narrow"}
        assert all(e["episodes"] == 1 for e in r["evals"][mode].values())
        assert 0.0 <= r[f"success_taught_{mode}"] <= 1.0
    assert r["evals"]["alone"]["corridor-winding"]["guard"] is None
    assert r["evals"]["guard"]["corridor-winding"]["guard"] is not None
    # rhbl evaluate judges the tree alone and reports the run through the guard beside it: the
    # guard's figures are that run's, the tree alone's its own
    for mode in ("alone", "guard"):
        for world, e in r["evals"][mode].items():
            (path,) = Path(r["workdir"]).glob(f"eval*-{mode}-{world}.json")
            rep = json.loads(path.read_text())
            driven = rep["guarded"] if mode == "guard" else rep
            assert e["success_rate"] == driven["success_rate"]
            if mode == "guard":
                assert e["collisions"] == rep["guarded"]["collisions"]
    assert isinstance(r["interventions_guard"], int) and r["interventions_alone"] == 0
    assert r["success_taught"] == r["success_taught_alone"]  # the summary: the tree alone
    assert "corridor-centring | calm (dev)" in bench.table([r])


def test_a_model_of_the_right_hand_wall_teaches_nothing_else(bench, capsys):
    """Refused before anything starts, with one line naming the models that can."""
    assert bench.main(["--behaviour", "wandering", "--people", "steady"]) == 2
    err = capsys.readouterr().err
    assert "right-hand wall only" in err and "calm" in err
    assert bench.main(["--behaviour", "no-such-behaviour"]) == 2
    assert "no-such-behaviour" in capsys.readouterr().err
    assert bench.main(["--people", "nobody"]) == 2
    assert "unknown 'nobody'" in capsys.readouterr().err


def _descendants(pid: int) -> set[int]:
    """Every living process below ``pid`` (from /proc: each process's parent)."""
    parents = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            parents[int(d.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parents.items() if pp == p]
        out.update(kids)
        todo.extend(kids)
    return out


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def test_a_stopped_benchmark_ends_every_process_it_started(bench, tmp_path):
    """SIGTERM while a person is at the page: the session stops its server, learner, console
    and browser, the runs not begun are not begun, and the benchmark exits 1 saying so."""
    import signal
    import subprocess

    from browser import find_chromium, in_ci
    from waiting import eventually, patience

    found = find_chromium()
    if isinstance(found, str):
        if in_ci():
            pytest.fail(f"CI=true and {found}")
        pytest.skip(found)
    root = Path(__file__).resolve().parents[2]
    bench = subprocess.Popen(
        [sys.executable, str(root / "benchmarks" / "bench_teach.py"), "--behaviour",
         "wall-following", "--people", "calm,rushed", "--quick", "--workdir", str(tmp_path)],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the person is at the page: the learner journals their labels
        eventually(lambda: (tmp_path / "wall-following-calm-0" / "tree.rhbl.journal").exists()
                   or bench.poll() is not None, timeout=120, what="a label journaled")
        assert bench.poll() is None, bench.communicate()
        started = _descendants(bench.pid)
        assert len(started) >= 4  # server, learner, console, the browser's driver and more
        bench.send_signal(signal.SIGTERM)
        _out, err = bench.communicate(timeout=patience(120))
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.communicate()
    assert bench.returncode == 1, err
    assert "stopped by a signal; every process it started has ended" in err
    assert not [p for p in started if _alive(p)]
    assert not (tmp_path / "wall-following-rushed-0").exists()  # not begun
