"""The real teacher, learner and controller processes over zenoh on loopback (lock-step server).

One module-scoped server; the tests run in order and share the learner's output folder:
the tree grows and its snapshot loads; a learner killed with SIGKILL mid-lineage and restarted has
lost no labeled vector (its rebuilt tree equals the journal replayed in-process); after a
corrective round (the controller drives, ``rhbl teacher --correct`` labels) the controller drives
without collision; ``--from-learner --follow`` swaps trees; ``--resume`` extends a tree; in
correcting mode every label is journaled while the controller drives and the teacher takes over
near a wall.
"""

from __future__ import annotations

import json
import signal
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually, patience, wait_token  # noqa: E402

from client.behaviour.learning import DemonstrationLearner, load_snapshot  # noqa: E402
from client.journal import Journal, journal_path  # noqa: E402
from client.player import PlayerClient  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Decision, DriverState, State, TeacherAction, VelCmd  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def env(start_module_server, tmp_path_factory):
    srv = start_module_server("room", lockstep=True)
    tmp = tmp_path_factory.mktemp("processes")
    procs: list[Child] = []

    def start(name, *args):
        # SIGINT, then SIGKILL after 30 s: stop() returns 0 only if SIGINT alone ended it;
        # its counters at exit in a file of its own (--stats)
        stats = tmp / f"{name}-{len(procs)}.stats.json"
        p = Child(name, rhbl_argv(*args, "--connect", srv.endpoint, "--stats", str(stats)), tmp,
                  cwd=ROOT, stop_signal=signal.SIGINT, stop_timeout=30.0, escalate=False).start()
        p.stats_file = stats
        procs.append(p)
        return p

    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        pose = PlayerClient(session=session, source="test").simulation.get_pose2d()
        yield {"srv": srv, "tmp": tmp, "start": start, "session": session, "start_pose": pose,
               "procs": procs}
        for p in procs:
            p.kill()


@pytest.fixture(autouse=True)
def _no_leftovers(env):
    """A process a failed test left running (a wait that timed out) does not drive on into the
    next test: SIGKILL by PID after each test."""
    yield
    for p in env["procs"]:
        p.kill()


def _wait_token(session, role: str, proc: Child, timeout: float = 30.0) -> None:
    wait_token(session, keys.alive_key(role, f"r0-{proc.pid}"), timeout, alive=[proc])


def _stats(p: Child) -> dict:
    """The counters a process wrote at exit (``--stats``)."""
    assert p.poll() is not None, f"{p.name} is still running"
    return json.loads(p.stats_file.read_text())


def _teach(env, seconds: float, seed: int = 0) -> int:
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--seconds",
                     str(seconds), "--seed", str(seed))
    assert t.wait(60) == 0, t.output()
    return _stats(t)["labels"]


def _journal_len(out: Path) -> int:
    with Journal.open(journal_path(out), readonly=True) as j:
        return len(j)


def _wait_snapshot_file(out: Path, labeled: int, timeout: float = 20.0) -> dict:
    """The metadata of the snapshot at ``out`` once it includes ``labeled`` journal records."""
    return eventually(lambda: load_snapshot(out)[3] if out.exists() else {}, timeout,
                      f"a snapshot {out} of {labeled} labeled vectors",
                      until=lambda meta: meta and meta["provenance"]["labeled"] >= labeled)


def _wait_journal(out: Path, n: int, timeout: float = 20.0, alive: list[Child] = ()) -> None:
    eventually(lambda: _journal_len(out) if journal_path(out).exists() else 0, timeout,
               f"{n} records in the journal of {out}", until=lambda have: have >= n,
               alive=alive)


def test_teacher_waits_for_a_learner_and_no_label_is_lost(env):
    sim = PlayerClient(session=env["session"], source="test").simulation
    start = sim.get_pose2d()  # put back at the end: the later tests drive from the start pose
    # no learner: a bounded wait, then a clear message and exit status 5
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower",
                     "--wait-learner-timeout", "1.5")
    assert t.wait(30) == 5, t.output()
    assert "no learner is up" in t.output() and "--no-wait-learner" in t.output()
    assert "first label" not in t.output()

    # a teacher started before the learner waits, saying so, and demonstrates once it is up
    out = env["tmp"] / "first.rhbl"
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--seconds", "5",
                     "--wait-learner-timeout", "60")
    # its token comes before it looks for a learner (and waits for the server first): its
    # saying so is the one sign that it waits, and the learner must come after that
    assert t.wait_for_line("waiting for a learner", patience(30)), t.output()
    assert t.poll() is None and "first label" not in t.output(), t.output()
    learner = env["start"]("learner", "learner", "--features", "wall", "--out", str(out))
    assert t.wait(patience(60)) == 0, t.output()
    first, n = _stats(t)["first_label_scan"], _stats(t)["labels"]
    _wait_journal(out, n)
    assert learner.stop() == 0, learner.output()
    with Journal.open(journal_path(out), readonly=True) as j:
        records = list(j.records())
    assert records[0].scan_id == first, (first, [r.scan_id for r in records[:3]])
    assert len(records) == n  # every label the teacher published is in the journal

    # pure teleop: --no-wait-learner demonstrates with nobody recording
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--seconds", "2",
                     "--no-wait-learner")
    assert t.wait(30) == 0, t.output()
    assert "first label" in t.output()
    sim.set_pose2d(*start)


def test_learner_grows_a_tree_and_survives_sigkill(env):
    out = env["tmp"] / "tree.rhbl"
    args = ("learner", "--features", "wall", "--out", str(out), "--snapshot-every", "0.3")
    learner = env["start"]("learner", *args)
    _wait_token(env["session"], "learner", learner)
    n1 = _teach(env, 40)
    _wait_journal(out, n1)
    meta = _wait_snapshot_file(out, n1)  # a periodic snapshot with every journaled vector
    clf = load_snapshot(out)[0]
    assert clf.node_count_ > 5
    assert meta["provenance"]["labeled"] == n1

    # SIGKILL: no final snapshot; the journal holds every labeled vector
    learner.kill()
    assert _journal_len(out) == n1
    learner = env["start"]("learner", *args)
    _wait_token(env["session"], "learner", learner)  # after its recovery
    n2 = _teach(env, 15, seed=1)
    _wait_journal(out, n1 + n2)
    assert learner.stop() == 0, learner.output()
    assert "recovered lineage" in learner.output(), learner.output()

    clf, _f, _a, meta = load_snapshot(out)
    prov = meta["provenance"]
    assert prov["labeled"] == n1 + n2 == prov["journal"]["records"]
    assert "unmatched labels" in learner.output() and " 0 unmatched" in learner.output()
    # the tree equals every journaled vector learned in one go, in-process
    from client.behaviour.features import FEATURES

    ref = DemonstrationLearner(FEATURES["wall"], task="wall-following", spawn="winner")
    with Journal.open(journal_path(out), readonly=True) as j:
        for rec in j.records():
            ref.observe(rec.ranges, rec.yaw, rec.label)
    assert ref.classifier.tree_equal(clf)


def test_controller_drives_without_collision(env):
    """The recipe over zenoh: the demonstrated tree (tests above) plus, from each start pose of
    the world, a demonstration and two corrective rounds (the controller drives the learner's
    latest tree, the teacher labels and takes over near walls), close to what `rhbl demo` does;
    then the corrected tree alone drives without collision."""
    from lab.harness import resolve_world

    out = env["tmp"] / "tree.rhbl"  # the learner continues the lineage
    session = env["session"]
    n0 = _journal_len(out)
    learner = env["start"]("learner", "learner", "--features", "wall", "--out", str(out),
                           "--snapshot-every", "0.3")
    _wait_token(session, "learner", learner)
    _wait_snapshot(session)
    follow = env["start"]("controller", "controller", "--from-learner", "--follow")
    _wait_token(session, "controller", follow)
    sim = PlayerClient(session=session, source="test").simulation
    labels = 0
    # first pass: 60 s demonstration then 60 s correcting; second pass: correcting only
    for phase in (("--demonstrate", "60", "--seconds", "120"), ("--seconds", "60")):
        for pose in resolve_world("room").start_poses:
            sim.set_pose2d(*pose)
            t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--correct",
                             *phase)
            assert t.wait(120) == 0, t.output()
            labels += _stats(t)["labels"]
    _wait_journal(out, n0 + labels)
    assert follow.stop() == 0, follow.output()
    assert _stats(follow)["swaps"] >= 1, follow.output()  # it drove the newer trees
    assert learner.stop() == 0, learner.output()
    # the corrected tree drives from the world's start pose, as the recipe is measured (the
    # correcting run may have ended anywhere, mid-takeover next to a wall)
    sim.set_pose2d(*env["start_pose"])
    states, cmds = [], []
    subs = [
        session.declare_subscriber(keys.state_key("r0"), lambda s: states.append(
            State.decode(s.payload.to_bytes()))),
        session.declare_subscriber(keys.cmd_vel_key("r0", source="controller"), lambda s: cmds.append(
            VelCmd.decode(s.payload.to_bytes()))),
    ]
    c = env["start"]("controller", "controller", "--tree", str(out), "--seconds", "60")
    assert c.wait(90) == 0, c.output()
    for s in subs:
        s.undeclare()
    assert len(cmds) >= 550, c.output()
    assert all(m.source == "controller" and m.scan_id is not None for m in cmds)
    hits = [st for st in states if st.stall]
    assert not hits, f"the learned robot collided (first at t={hits[0].ts:.1f} s, odometry " \
        f"{hits[0].pos}):\n{c.output()}"


def test_controller_follows_the_learner(env):
    out = env["tmp"] / "follow.rhbl"
    learner = env["start"]("learner", "learner", "--features", "wall", "--out", str(out),
                           "--snapshot-every", "0.2")
    _wait_token(env["session"], "learner", learner)
    _teach(env, 5)
    _wait_journal(out, 40)
    trees: list[str] = []  # the trees the controller decided with, as it publishes them
    sub = env["session"].declare_subscriber(keys.controller_decision_key("r0"), lambda s: (
        trees.append(Decision.decode(s.payload.to_bytes()).snapshot_id)))
    try:
        c = env["start"]("controller", "controller", "--from-learner", "--follow")
        _wait_token(env["session"], "controller", c)
        first = eventually(lambda: trees[:1], 30, "a decision of the controller",
                           alive=[c])[0]
        _teach(env, 20, seed=2)  # the teacher outranks the controller while it demonstrates
        eventually(lambda: trees[-1], 20, f"a decision with a newer tree than {first}",
                   until=lambda tree: tree != first, alive=[c])
    finally:
        sub.undeclare()
    assert c.stop() == 0, c.output()
    assert _stats(c)["swaps"] >= 1, c.output()
    assert learner.stop() == 0, learner.output()


def test_resume_extends_a_tree(env):
    base = env["tmp"] / "tree.rhbl"
    out = env["tmp"] / "tree2.rhbl"
    clf0, _f, _a, meta0 = load_snapshot(base)
    learner = env["start"]("learner", "learner", "--resume", str(base), "--out", str(out))
    _wait_token(env["session"], "learner", learner)
    n = _teach(env, 10, seed=3)
    _wait_journal(out, n)
    assert learner.stop() == 0, learner.output()
    clf, _f, _a, meta = load_snapshot(out)
    prov = meta["provenance"]
    assert prov["parent"] == str(base.resolve())
    assert prov["vectors"] == meta0["provenance"]["vectors"] + n
    assert clf.node_count_ >= clf0.node_count_
    # the parent is untouched
    assert load_snapshot(base)[0].tree_equal(clf0)


def test_processes_exit_cleanly_on_sigterm(env):
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower")
    _wait_token(env["session"], "teacher", t)
    assert t.stop(signal.SIGTERM) == 0, t.output()
    assert "Traceback" not in t.output()


def test_teacher_pauses_while_no_learner_is_up(env):
    """A learner stopped mid-demonstration: the teacher pauses (no commands, no labels) until a
    learner is up again, so every label it published is in the journal."""
    sim = PlayerClient(session=env["session"], source="test").simulation
    start = sim.get_pose2d()
    out = env["tmp"] / "pause.rhbl"
    args = ("learner", "--features", "wall", "--out", str(out))
    learner = env["start"]("learner", *args)
    _wait_token(env["session"], "learner", learner)
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--wait-learner-timeout",
                     "60")
    _wait_journal(out, 5, alive=[t])  # demonstrating
    # what the bus carries from now on: scans, and the teacher's labels (the order kept)
    bus: list[str] = []
    subs = [env["session"].declare_subscriber(keys.scan_key("r0"), lambda _s: bus.append("scan")),
            env["session"].declare_subscriber(keys.teacher_action_key("r0"),
                                              lambda _s: bus.append("label"))]
    try:
        assert learner.stop(signal.SIGTERM) == 0, learner.output()
        # nobody records: the teacher pauses, nothing is demonstrated while the server goes
        # on (three scans in a row and no label: within a few scans of the learner's token
        # gone)
        eventually(lambda: bus[-3:], 30, "three scans in a row without a label (a pause)",
                   until=lambda last: last == ["scan"] * 3, alive=[t])
        paused = _journal_len(out)
        mark = len(bus)
        eventually(lambda: bus[mark:].count("scan"), 30, "two more scans",
                   until=lambda n: n >= 2, alive=[t])
        assert "label" not in bus[mark:], bus[mark:]
    finally:
        for sub in subs:
            sub.undeclare()
    learner = env["start"]("learner", *args)
    _wait_token(env["session"], "learner", learner)
    _wait_journal(out, paused + 20, alive=[t])  # demonstrating again
    assert t.stop() == 0, t.output()
    assert "pausing" in t.output(), t.output()  # it said why it stopped demonstrating
    ups = "INFO learner is up: "  # not "a learner is up: sending the labels ..." (a resend)
    assert t.output().count(ups) == 2, t.output()
    n = _stats(t)["labels"]
    _wait_journal(out, n)
    assert learner.stop() == 0, learner.output()
    assert _journal_len(out) == n > paused > 0
    sim.set_pose2d(*start)


def _wait_snapshot(session, timeout: float = 20.0) -> None:
    eventually(lambda: any(r.ok is not None for r in session.get(
        keys.learner_snapshot_key("r0"), timeout=2.0)), timeout,
        "the learner's snapshot (an answer to a query)", every=0.1)


def test_correcting_teacher_labels_while_the_controller_drives(env):
    """``rhbl teacher --correct``: every scan gets a label (journaled) while the controller
    drives; near a wall the teacher takes over with its label, then hands the robot back.
    The controller's tree here only knows 'fwd', so it drives into walls."""
    from client.behaviour.features import FEATURES

    session = env["session"]
    sim = PlayerClient(session=session, source="test").simulation
    start = sim.get_pose2d()
    fwd = DemonstrationLearner(FEATURES["wall"], task="wall-following", spawn="winner")
    fwd.observe(np.full(360, 2.0, np.float32), 0.0, "fwd")
    tree = fwd.save(env["tmp"] / "fwd.rhbl")
    out = env["tmp"] / "correcting.rhbl"
    learner = env["start"]("learner", "learner", "--features", "wall", "--out", str(out))
    _wait_token(session, "learner", learner)
    sim.set_pose2d(9.0, 0.7, 0.0)  # 3 m from the room's right wall, heading at it
    drivers, labels, states = [], [], []
    subs = [
        session.declare_subscriber(keys.driver_key("r0"), lambda s: drivers.append(
            DriverState.decode(s.payload.to_bytes()).source)),
        session.declare_subscriber(keys.teacher_action_key("r0"), lambda s: labels.append(
            TeacherAction.decode(s.payload.to_bytes()))),
        session.declare_subscriber(keys.state_key("r0"), lambda s: states.append(
            State.decode(s.payload.to_bytes()))),
    ]
    c = env["start"]("controller", "controller", "--tree", str(tree))
    _wait_token(session, "controller", c)
    t = env["start"]("teacher", "teacher", "--policy", "wall-follower", "--correct",
                     "--seconds", "40")
    assert t.wait(90) == 0, t.output()
    n = _stats(t)["labels"]
    _wait_journal(out, n)
    assert c.stop() == 0, c.output()
    assert learner.stop() == 0, learner.output()
    for sub in subs:
        sub.undeclare()
    sim.set_pose2d(*start)

    took = _stats(t)["taken_over"]
    assert 0 < took < n / 2, t.output()
    # every label the teacher published is journaled, tied to its scan
    with Journal.open(journal_path(out), readonly=True) as j:
        records = list(j.records())
    # 40 s at 10 Hz: each scan labelled or, when the teacher fell behind the lock-step
    # controller on a busy machine (its queue holds 64), counted as missed; none silently
    missed = _stats(t)["missed"]
    assert len(records) == n and n + missed >= 390 and n >= 100, (n, missed, t.output()[-600:])
    mine = [lb for lb in labels if lb.source == "teacher"]
    assert {r.scan_id for r in records} == {lb.scan_id for lb in mine}
    # taking over: the command is the label; otherwise no command (executed unset)
    over = [lb for lb in mine if lb.executed is not None]
    assert len(over) == took and all(lb.executed == lb.action for lb in over)
    assert any(lb.action.startswith("rot") or lb.action == "fwd-left" for lb in over)
    # the controller drives most of the time; the teacher only near walls
    ticks = [s.driver for s in states if s.driver]
    assert ticks.count("controller") > 0.5 * len(ticks), ticks.count("teacher")
    assert "teacher" in ticks and "teacher" in drivers and "controller" in drivers


def test_starting_order_does_not_matter_for_a_following_controller(env):
    """``rhbl controller --from-learner --follow`` started before the learner waits for its
    first tree (saying so), then drives; it never exits for want of a tree."""
    import threading

    session = env["session"]
    sim = PlayerClient(session=session, source="test").simulation
    start = sim.get_pose2d()
    commanded = threading.Event()
    sub = session.declare_subscriber(keys.cmd_vel_key("r0", source="controller"),
                                     lambda _s: commanded.set())
    try:
        c = env["start"]("controller", "controller", "--from-learner", "--follow")
        # its token comes before it asks for a tree: its saying so is the one sign that it
        # waits, and the learner must come after that
        assert c.wait_for_line("waiting for the learner's first tree", patience(30)), c.output()
        assert not commanded.is_set(), c.output()
        out = env["tmp"] / "order.rhbl"
        learner = env["start"]("learner", "learner", "--features", "wall", "--out", str(out),
                               "--snapshot-every", "0.3")
        _wait_token(session, "learner", learner)
        _teach(env, 5, seed=4)
        assert commanded.wait(patience(60)), c.output()
        assert c.poll() is None, c.output()
        assert c.stop() == 0, c.output()
        assert "tree loaded" in c.output(), c.output()  # it never exited for want of one
        assert learner.stop() == 0, learner.output()
    finally:
        sub.undeclare()
        sim.set_pose2d(*start)


def test_a_persons_learner_pairs_each_label_with_the_scan_lag_scans_earlier(env):
    """``rhbl learner --teacher person --lag 3``: every label learned with the scan three
    before the one it names (the teacher labels every scan, so the journal's scan ids are the
    labels' minus 3), the tree rebuilt by the neighbours' vote; the snapshot says so, a
    controller drives it through its loop guard and counts what the guard overruled."""
    session = env["session"]
    sim = PlayerClient(session=session, source="test").simulation
    start = sim.get_pose2d()
    out = env["tmp"] / "person.rhbl"
    try:
        learner = env["start"]("learner", "learner", "--features", "wall", "--teacher",
                               "person", "--lag", "3", "--out", str(out),
                               "--snapshot-every", "0.3")
        _wait_token(session, "learner", learner)
        labels = []
        sub = session.declare_subscriber(keys.teacher_action_key("r0"),
                                         lambda s: labels.append(
                                             TeacherAction.decode(s.payload.to_bytes()).scan_id))
        try:
            n = _teach(env, 6, seed=5)
        finally:
            sub.undeclare()
        _wait_journal(out, n)
        assert learner.stop() == 0, learner.output()
        pairing = _stats(learner)["pairing"]
        # every label paired, and more often only by the teacher's resends (a label the learner
        # had not acknowledged within 2 s comes again; the journal keeps it once: below);
        # all but the first few shifted
        paired = pairing["shifted"] + pairing["unshifted"]
        assert n <= paired <= n + pairing["resent"] and pairing["shifted"] >= paired - 3, pairing
        with Journal.open(journal_path(out), readonly=True) as j:
            learned = [r.scan_id for r in j.records()]
        # the labels this test saw (its subscription may miss the first few): each one's
        # scan three before is in the journal, and the newest scan learned is three before the
        # newest scan named
        named = set(labels)
        assert len(learned) == n and len(named) >= n // 2, (n, len(named))
        assert sum((s - 3) in set(learned) for s in named) >= len(named) - 3
        assert max(learned) <= max(named) - 3
        meta = load_snapshot(out)[3]
        assert meta["learning"]["rule"] == "person" and meta["learning"]["lag"] == 3
        c = env["start"]("controller", "controller", "--tree", str(out), "--seconds", "5")
        assert c.wait(60) == 0, c.output()
        st = _stats(c)
        assert st["commands"] > 0 and st["overruled"] >= 0 and st["unanswered"] == 0
        assert st["avoided"] >= 0
    finally:
        sim.set_pose2d(*start)


def test_a_persons_learner_with_lag_auto_journals_the_scans_before_each_label(env):
    """``rhbl learner --teacher person --lag auto``: each label journaled with its own scan and
    the features of the scans displayed before it (up to 6), the lag estimated from them; a
    restart with the same command rebuilds the same tree."""
    session = env["session"]
    sim = PlayerClient(session=session, source="test").simulation
    start = sim.get_pose2d()
    out = env["tmp"] / "auto.rhbl"
    argv = ("learner", "--features", "wall", "--teacher", "person", "--lag", "auto", "--out",
            str(out), "--snapshot-every", "0.3")
    try:
        learner = env["start"]("learner", *argv)
        _wait_token(session, "learner", learner)
        n = _teach(env, 6, seed=7)
        _wait_journal(out, n)
        assert learner.stop() == 0, learner.output()
        with Journal.open(journal_path(out), readonly=True) as j:
            recs = list(j.records())
        assert len(recs) == n
        assert sum(r.earlier is not None and r.earlier.shape == (6, 5) for r in recs) >= n - 7
        meta = load_snapshot(out)[3]
        assert meta["learning"]["lag"] is None and 0 <= meta["learning"]["estimated_lag"] <= 6
        tree = load_snapshot(out)[0]
        out.rename(out.with_suffix(".first"))  # a restart with the journal alone
        again = env["start"]("learner", *argv)
        _wait_token(session, "learner", again)
        assert again.stop() == 0, again.output()
        assert load_snapshot(out)[0].tree_equal(tree)
    finally:
        sim.set_pose2d(*start)


def test_a_learner_told_no_features_grows_a_tree_that_sees_all_round(env):
    """``rhbl learner --out PATH`` with no ``--features``: a new tree with the default perception
    (``around``: nine sector minima over the whole field of view), which its snapshot names; a
    restart continues it with the tree's own spec."""
    from client.behaviour.features import FEATURES

    session = env["session"]
    sim = PlayerClient(session=session, source="test").simulation
    start = sim.get_pose2d()
    out = env["tmp"] / "around.rhbl"
    try:
        learner = env["start"]("learner", "learner", "--out", str(out), "--snapshot-every", "0.3")
        _wait_token(session, "learner", learner)
        # 0.6 m short of the bottom wall's protrusion, facing it: the expert must turn as well
        # as go on, so the labels hold two actions wherever the earlier tests left the robot
        sim.set_pose2d(3.4, 0.7, 0.0)
        n = _teach(env, 4, seed=3)
        _wait_journal(out, n)
        assert learner.stop() == 0, learner.output()
        clf, features, _a, meta = load_snapshot(out)
        assert features == FEATURES["around"] and features.dim == 9
        assert meta["provenance"]["labeled"] == n and clf.node_count_ > 1
        again = env["start"]("learner", "learner", "--out", str(out))
        _wait_token(session, "learner", again)
        assert again.stop() == 0, again.output()
        assert load_snapshot(out)[1] == FEATURES["around"]
    finally:
        sim.set_pose2d(*start)
