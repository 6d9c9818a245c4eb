"""Episodes run anywhere give the same results (``lab.practice``): in this process, on a pool
of processes, on a local Dask cluster the test starts on 127.0.0.1; a worker killed (by PID)
while it runs episodes loses none of them."""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import pytest
from waiting import eventually

from client.behaviour.learning import TreePolicy
from lab.cli import main
from lab.practice import EpisodeTask, Runner, run_episode, run_episodes, tree_bytes

WALL_TREE = Path(__file__).resolve().parents[1] / "rhbl" / "data" / "room-1200.rhbl"
STARTS = [(3.0, 0.7, 0.0), (8.0, 0.7, 0.0), (11.3, 6.5, 1.5708), (10.0, 8.3, 3.14159)]


def _tasks(seconds: float = 20.0, n: int = 8) -> list[EpisodeTask]:
    data = tree_bytes(TreePolicy.load(WALL_TREE))
    return [EpisodeTask("wall-following", "room", data, STARTS[k % len(STARTS)], seed=k,
                        seconds=seconds) for k in range(n)]


def _judged(results: list[dict]) -> list:
    """What a result says, without the trace."""
    return [(r["success"], r["metrics"], r["teacher"], r["steps"], r["stalls"]) for r in results]


@pytest.fixture(scope="module")
def serial() -> list:
    return _judged([run_episode(t) for t in _tasks()])


def test_an_episode_is_judged_as_evaluate_judges_it(tmp_path):
    out = tmp_path / "report.json"
    assert main(["evaluate", "--behaviour", "wall-following", "--tree", str(WALL_TREE),
                 "--episodes", "2", "--seconds", "20", "--workers", "1",
                 "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    data = tree_bytes(TreePolicy.load(WALL_TREE))
    from lab.behaviours import get, teaching_world

    starts = teaching_world(get("wall-following")).start_poses
    for k in range(2):
        r = run_episode(EpisodeTask("wall-following", "room", data, starts[k], seed=k,
                                    seconds=20.0))
        assert r["metrics"] == report["learner"][k]
        assert r["teacher"] == report["teacher"][k]


@pytest.mark.slow
def test_evaluate_on_a_pool_reports_what_it_reports_here(tmp_path):
    reports = []
    for workers in ("1", "2"):
        out = tmp_path / f"report-{workers}.json"
        assert main(["evaluate", "--behaviour", "wall-following", "--tree", str(WALL_TREE),
                     "--episodes", "4", "--seconds", "15", "--workers", workers,
                     "--json", str(out)]) == 0
        reports.append(json.loads(out.read_text()))
    assert reports[0] == reports[1]


def test_a_trace_names_the_sphere_of_every_step():
    task = _tasks(seconds=5.0, n=1)[0]
    traced = run_episode(EpisodeTask(**{**task.__dict__, "trace": True}))
    plain = run_episode(task)
    assert _judged([traced]) == _judged([plain])
    clf = TreePolicy.load(WALL_TREE).classifier
    assert len(traced["winners"]) == traced["steps"] == len(traced["states"])
    names = [str(clf.classes_[clf.tree_.label[w]]) for w in traced["winners"]]
    assert names == traced["actions"]


@pytest.mark.slow
def test_the_pool_gives_the_serial_results(serial):
    assert _judged(run_episodes(_tasks(), workers=2)) == serial


@pytest.mark.slow
def _cpu_seconds(pid: int) -> float:
    """The CPU time process ``pid`` has used (user and system), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_a_pool_worker_killed_loses_no_episode():
    tasks = _tasks(seconds=300.0, n=24)  # long enough to be killed in the middle of
    serial = _judged([run_episode(t) for t in tasks])
    with Runner(workers=2) as runner:
        runner.map(tasks[:2])  # the pool's processes are up
        pids = runner.worker_pids()
        assert len(pids) == 2
        import threading

        got: dict = {}
        before = _cpu_seconds(pids[0])
        t = threading.Thread(target=lambda: got.update(r=runner.map(tasks)))
        t.start()
        # killed while it runs an episode of this map (its CPU time grows), not before
        eventually(lambda: _cpu_seconds(pids[0]) > before + 0.05,
                   what=f"worker {pids[0]} running an episode")
        os.kill(pids[0], signal.SIGKILL)
        t.join(timeout=120)
        assert not t.is_alive()
        assert runner.rerun >= 1
        assert _judged(got["r"]) == serial


def test_a_pool_worker_that_died_between_runs_loses_nothing(serial):
    tasks = _tasks()
    with Runner(workers=2) as runner:
        runner.map(tasks[:2])
        pid = runner.worker_pids()[0]
        os.kill(pid, signal.SIGKILL)  # idle: the pool breaks, no episode of it is lost
        eventually(lambda: not Path(f"/proc/{pid}").exists()
                   or Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z",
                   what=f"worker {pid} gone")
        assert _judged(runner.map(tasks)) == serial
        assert pid not in runner.worker_pids()


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  protocol="tcp") as c:
        yield c


@pytest.mark.slow
def test_a_cluster_gives_the_serial_results(cluster, serial):
    assert _judged(run_episodes(_tasks(), cluster=cluster.scheduler_address)) == serial


@pytest.mark.slow
def test_a_cluster_worker_killed_loses_no_episode(cluster, serial):
    from distributed import Client

    tasks = _tasks(seconds=60.0, n=8)
    expected = _judged([run_episode(t) for t in tasks])
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        client.wait_for_workers(2)
        pids = client.run(os.getpid)  # worker address -> its process id
        futures = client.map(run_episode, tasks, pure=False)
        # the first worker that is running an episode is killed while it runs it
        busy = eventually(lambda: [w for w, keys in client.processing().items() if keys],
                          what="a worker running an episode")
        os.kill(pids[busy[0]], signal.SIGKILL)
        results = client.gather(futures)
        assert _judged(results) == expected
        eventually(lambda: len(client.scheduler_info(n_workers=-1)["workers"]) == 2,
                   what="the nanny's new worker")


def test_a_cluster_that_is_not_there_is_named():
    with pytest.raises(ValueError, match="127.0.0.1:9"):
        Runner(cluster="tcp://127.0.0.1:9")


@pytest.mark.slow
def test_refine_on_a_tiny_budget_writes_a_tree_that_drives_with_its_lineage(tmp_path):
    import hashlib

    from lab.behaviours import get, teaching_world
    from lab.evaluate import evaluate

    out, report = tmp_path / "refined.rhbl", tmp_path / "refine.json"
    assert main(["refine", "--behaviour", "wall-following", "--tree", str(WALL_TREE),
                 "--out", str(out), "--seconds", "15", "--scales", "none", "--minutes",
                 "0.5", "--workers", "2", "--validation", "1", "--json", str(report)]) == 0
    policy = TreePolicy.load(out)  # loads, with its features and actions
    b = get("wall-following")
    rep = evaluate(teaching_world(b), policy, episodes=1, seconds=5, behaviour=b)
    assert rep["learner"][0]["seconds"] == 5  # it drives
    lineage = policy.classifier.metadata["refinement"][-1]
    assert lineage["parent"] == str(WALL_TREE)
    assert lineage["parent_sha256"] == hashlib.sha256(WALL_TREE.read_bytes()).hexdigest()
    assert lineage["episodes"] >= 6
    assert lineage["after"]["nodes"] == policy.classifier.node_count_
    assert lineage["after"]["fitness"] >= lineage["before"]["fitness"]
    assert set(lineage["worlds_after"]) == {"room", *b.held_out}
    assert json.loads(report.read_text())["after"] == lineage["after"]
    val = lineage["validation"]  # one drawn world of seed 501, no worse after than before
    assert val["worlds"] == 1 and val["episodes"] >= 1
    assert val["after"]["fitness"] >= val["before"]["fitness"]


def test_the_size_step_leaves_room_for_repairs_that_add_spheres():
    from lab.behaviours import get
    from lab.refine import refine

    policy = TreePolicy.load(WALL_TREE)
    assert policy.classifier.node_count_ > 40
    with Runner(workers=1) as runner:
        clf, report = refine(get("wall-following"), policy, runner, max_nodes=40, room=6,
                             budget=1.0, scales=(), seconds=10.0, validate=False,
                             prune="none", say=lambda text: None)
    assert report["sized"]["nodes"] == 34 and report["room"] == 6
    assert report["sized"]["nodes"] <= clf.node_count_ <= 40  # repairs only add, up to 40
    assert report["after"]["nodes"] == clf.node_count_


def test_more_drawn_worlds_join_the_practice_set_once_it_is_met():
    from lab.behaviours import get
    from lab.practice import PRACTICE_SEED, drawn_name, practice_tasks
    from lab.refine import _more_worlds, _Practice, refine

    policy = TreePolicy.load(WALL_TREE)
    b = get("wall-following")
    with Runner(workers=1) as runner:
        pr = _Practice(b, policy, runner, practice_tasks(b, (0,), (), 5.0, drawn=("rooms", 1)))
        pr.results = pr.run(policy.classifier)
        assert all(r["success"] for r in pr.results)  # met: 5 s from every start
        n = len(pr.tasks)
        joined = _more_worlds(pr, policy.classifier, b, "rooms", 1, 2, (0,), 5.0, 0, (0.0, 0.0))
        assert joined == len(pr.tasks) - n == len(pr.results) - n > 0
        assert {t.world for t in pr.tasks[n:]} <= {drawn_name("rooms", PRACTICE_SEED, i)
                                                   for i in (1, 2)}  # the next two drawn
        assert _judged(pr.results[n:]) == _judged(pr.run(policy.classifier, range(n, len(pr.tasks))))
        clf, report = refine(b, policy, runner, budget=2.0, scales=(), seconds=5.0,
                             validate=False, prune="none", drawn=("rooms", 1), more=1,
                             say=lambda text: None)
    kind, drawn = report["practice"]["drawn"]
    assert kind == "rooms" and drawn > 1 and report["moves"]["worlds drawn"] == drawn - 1
    assert report["practice"]["episodes"] > n


def test_refine_moves_keep_an_rhbl_tree():
    from lab.refine import added, leaves, relabelled, without

    clf = TreePolicy.load(WALL_TREE).classifier
    s = leaves(clf)[0]
    other = next(str(a) for a in clf.classes_ if a != clf.classes_[clf.tree_.label[s]])
    assert str(relabelled(clf, s, other).classes_[relabelled(clf, s, other).tree_.label[s]]) == other
    assert without(clf, s).node_count_ == clf.node_count_ - 1
    x = clf.tree_arrays()["centers"][s] * 0.999
    grown = added(clf, x, other)
    assert grown.predict_one(x) == other


@pytest.mark.slow
def test_a_prune_pass_leaves_the_results_of_the_pruned_tree():
    """The leaves kept out together give exactly the episodes each gave alone (credit is
    only ever taken from episodes in which a sphere decided)."""
    from lab.behaviours import get
    from lab.practice import practice_tasks
    from lab.refine import _Practice, _prune_pass, without

    policy = TreePolicy.load(WALL_TREE)
    with Runner(workers=1) as runner:
        pr = _Practice(get("wall-following"), policy, runner,
                       practice_tasks(get("wall-following"), (0,), (), seconds=8.0))
        pr.results = pr.run(policy.classifier)
        gone = _prune_pass(pr, policy.classifier)
        assert gone
        pruned = without(policy.classifier, gone)
        fresh = pr.run(pruned)
    assert _judged(fresh) == _judged(pr.results)
    for a, b in zip(fresh, pr.results, strict=True):
        assert a["winners"].tolist() == b["winners"].tolist()


def _validation_set(runner, policy, worlds: int = 2, seconds: float = 8.0):
    """A validation set as ``refine(validation=N)`` makes it, practised by ``policy``."""
    from lab.behaviours import get
    from lab.refine import _validation_set as made

    return made(get("wall-following"), policy, runner, policy.classifier, worlds, "rooms", (0,),
                seconds, (0.0, 0.0))


def test_the_validation_set_is_drawn_worlds_only_with_their_own_seed():
    from lab.behaviours import get
    from lab.practice import DRAWN, PRACTICE_SEED, practice_tasks
    from lab.refine import VALIDATION_SEED

    b = get("wall-following")
    tasks = practice_tasks(b, (0,), (0.85,), drawn=("rooms", 2), drawn_seed=VALIDATION_SEED,
                            teach=False)
    assert tasks and all(t.world.startswith(f"{DRAWN}:rooms:{VALIDATION_SEED}:") for t in tasks)
    practised = {t.world for t in practice_tasks(b, (0,), (), drawn=("rooms", 2))}
    assert practised.isdisjoint(t.world for t in tasks)
    assert VALIDATION_SEED != PRACTICE_SEED


@pytest.mark.slow
def test_a_move_that_lowers_the_validation_fitness_is_not_kept():
    """``_validated`` keeps the best move that leaves the validation set no worse: a tree that
    only drives forward (offered as a relabel of the validation episodes' busiest sphere) is
    refused and leaves the validation results as they were; the tree itself passes."""
    from collections import Counter

    import numpy as np

    from lab.refine import _classifier, _validated

    policy = TreePolicy.load(WALL_TREE)
    clf = policy.classifier
    arr, classes = clf.tree_arrays(), [str(c) for c in clf.classes_]
    forward = _classifier(clf, arr["centers"], arr["radii"], arr["parent"],
                          np.full_like(arr["label"], classes.index("fwd")), classes)
    with Runner(workers=1) as runner:
        val = _validation_set(runner, policy)
        before, results = val.fitness, list(val.results)
        busiest, _n = Counter(w for r in val.results for w in r["winners"].tolist()
                              if w >= 0).most_common(1)[0]
        bad = (("relabel", busiest, "fwd"), forward, [], [])
        assert _validated(val, [bad], clf, 2, lambda: 60.0) is None
        assert val.fitness == before and val.results == results
        same = (("relabel", busiest, "x"), clf, [], [])
        assert _validated(val, [bad, same], clf, 2, lambda: 60.0) is same
    assert val.fitness == pytest.approx(before)


@pytest.mark.slow
def test_a_prune_pass_with_a_validation_set_leaves_both_sets_results_of_the_pruned_tree():
    from lab.behaviours import get
    from lab.practice import practice_tasks
    from lab.refine import _Practice, _prune_pass, without

    policy = TreePolicy.load(WALL_TREE)
    with Runner(workers=1) as runner:
        pr = _Practice(get("wall-following"), policy, runner,
                       practice_tasks(get("wall-following"), (0,), (), seconds=8.0))
        pr.results = pr.run(policy.classifier)
        val = _validation_set(runner, policy)
        fit, vfit = pr.fitness, val.fitness
        gone = _prune_pass(pr, policy.classifier, val=val)
        assert gone
        pruned = without(policy.classifier, gone)
        fresh, vfresh = pr.run(pruned), val.run(pruned)
    assert pr.fitness >= fit - 1e-9 and val.fitness >= vfit - 1e-9
    for got, kept in ((fresh, pr.results), (vfresh, val.results)):
        assert _judged(got) == _judged(kept)
        for a, b in zip(got, kept, strict=True):
            assert a["winners"].tolist() == b["winners"].tolist()


@pytest.mark.slow
def test_a_sphere_added_changes_only_the_episodes_it_reaches():
    from lab.behaviours import get
    from lab.practice import practice_tasks
    from lab.refine import _Practice, added

    policy = TreePolicy.load(WALL_TREE)
    clf = policy.classifier
    with Runner(workers=1) as runner:
        pr = _Practice(get("wall-following"), policy, runner,
                       practice_tasks(get("wall-following"), (0,), (), seconds=8.0))
        pr.results = pr.run(clf)
        r = pr.results[0]
        k = len(r["actions"]) // 2
        other = next(a for a in policy.actions.names if a != r["actions"][k])
        grown = added(clf, r["states"][k], other)
        assert grown.node_count_ > clf.node_count_
        idx = pr.reaching(grown, clf.node_count_)
        assert 0 in idx
        fresh = pr.run(grown)
    for i, (a, b) in enumerate(zip(fresh, pr.results, strict=True)):
        if i not in idx:
            assert _judged([a]) == _judged([b]) and a["winners"].tolist() == b["winners"].tolist()


def test_a_failure_refinement_cannot_fix_asks_from_before_it_went_wrong():
    """``lab.refine.ask``: a tree that only drives forward collides; the ask puts the robot
    where it was ``window // 2`` steps before the collision, on its own path."""
    import math

    from lab.behaviours import get
    from lab.refine import ask
    from rhbl import HypersphereClassifier

    policy = TreePolicy.load(WALL_TREE)
    d = policy.features.dim
    clf = HypersphereClassifier(default_label="fwd")
    clf.partial_fit([[1.0] * d], ["fwd"])
    ahead = TreePolicy(clf, policy.features, policy.actions)
    task = EpisodeTask("wall-following", "room", tree_bytes(ahead), STARTS[0], seconds=30.0,
                       trace=True)
    r = run_episode(task)
    assert not r["success"] and r["stalls"]
    a = ask(task, r, 30, get("wall-following"))
    assert a["why"] == "collision" and a["step"] == r["stalls"][0]
    assert a["pose"] == [round(float(v), 3) for v in r["poses"][a["step"] - 15]]
    assert math.dist(a["pose"][:2], STARTS[0][:2]) > 0.1  # on its way, not at its start
    assert (a["world"], a["scale"], a["start"]) == ("room", 1.0, list(STARTS[0]))
    json.dumps(a)  # it goes into the snapshot's metadata as it is


def test_practice_in_drawn_worlds_names_each_so_any_worker_draws_it_again():
    from lab.behaviours import get
    from lab.generated import generated
    from lab.practice import PRACTICE_SEED, drawn_name, practice_tasks, task_world

    b = get("left-wall")
    tasks = practice_tasks(b, (0,), (), drawn=("rooms", 2))
    drawn = [t for t in tasks if t.world.startswith("drawn:")]
    want = generated("rooms", 2, PRACTICE_SEED, "left")
    assert {t.world for t in drawn} == {drawn_name("rooms", PRACTICE_SEED, i, "left")
                                        for i in range(2)}
    assert len(drawn) == sum(len(w.start_poses) for w in want)
    for i, w in enumerate(want):
        spec = task_world("left-wall", drawn_name("rooms", PRACTICE_SEED, i, "left"))
        assert spec.walls == w.walls and spec.start_poses == w.start_poses
    assert len(tasks) - len(drawn) == len(practice_tasks(b, (0,), ()))
    r = run_episode(EpisodeTask("left-wall", drawn[0].world, tree_bytes(
        TreePolicy.load(WALL_TREE)), drawn[0].start, seconds=3.0))
    assert r["steps"] == 30


def test_the_size_step_holds_max_nodes_even_where_pruning_stops_above_it():
    from lab.refine import _to_size, leaves

    clf = TreePolicy.load(WALL_TREE).classifier
    X = clf.tree_arrays()["centers"][:400]
    small = _to_size(clf, X, 40)
    assert small.node_count_ == 40
    assert _to_size(small, X, 40) is small  # already small enough: as it is
    assert leaves(small)  # still a tree of spheres that answers
    assert small.predict(X[:5]).shape == (5,)


def test_the_pool_s_workers_end_when_the_process_that_made_it_is_killed(tmp_path):
    """A real process runs long episodes on a pool of 2, then is SIGKILLed: its workers (the
    forkserver's children, not its own) end by themselves instead of running on for nobody."""
    from lab.children import Child, running

    code = (
        "import sys, threading, time\n"
        "from pathlib import Path\n"
        f"sys.path[:0] = [{str(Path(__file__).resolve().parent)!r}, "
        f"{str(Path(__file__).resolve().parents[1])!r}]\n"
        "from test_practice import _tasks\n"
        "from lab.practice import Runner\n"
        "r = Runner(workers=2)\n"
        "r.map(_tasks(seconds=0.5, n=2))\n"
        "threading.Thread(target=r.map, args=(_tasks(seconds=600.0, n=4),), daemon=True).start()\n"
        "print('workers', *r.worker_pids(), flush=True)\n"
        "time.sleep(600)\n")
    parent = Child("pool-owner", [sys.executable, "-c", code], tmp_path,
                   cwd=str(Path(__file__).resolve().parents[2])).start()
    assert parent.wait_for_line("workers ", timeout=120), parent.output()
    pids = [int(v) for v in next(x for x in parent.lines if x.startswith("workers ")).split()[1:]]
    assert len(pids) == 2

    try:
        assert all(map(running, pids))
        parent.kill()
        eventually(lambda: not any(map(running, pids)), 30,
                   "the workers end without their owner")
    finally:
        for pid in pids:
            if running(pid):
                os.kill(pid, signal.SIGKILL)


def test_refine_to_a_size_refuses_a_margin_tree_by_name(tmp_path, capsys):
    """--max-nodes prunes by the paper's rule (rhbl.compaction): a tree bounded by the margin
    (rhbl train's default for a behaviour) is refused, one line naming --radius parent, before
    any episode runs; nothing is written."""
    tree, out = tmp_path / "m.rhbl", tmp_path / "out.rhbl"
    assert main(["train", "--behaviour", "wall-following", "--world", "corridor", "--seconds",
                 "20", "--rounds", "0", "--out", str(tree)]) == 0
    assert TreePolicy.load(tree).classifier.radius == "margin"
    capsys.readouterr()
    assert main(["refine", "--behaviour", "wall-following", "--tree", str(tree), "--out",
                 str(out), "--max-nodes", "5", "--minutes", "0.2", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "--radius parent" in err and "--max-nodes 5" in err, err
    assert not out.exists()
