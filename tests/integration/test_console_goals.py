"""Teaching goals in order by hand at ``rhbl console --behaviour red-green``, in a real headless
Chromium against a real server, learner and console process: the page says which goal the
person drives to; G says it is reached (the next label carries the mark and is for the next
goal); putting the robot at a start begins the goals again; the learner journals each label
with the goal, the mark and what the fiducial finder saw, and its snapshot holds both trees."""

from __future__ import annotations

from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("aiohttp")

from browser import ConsoleProcess  # noqa: E402
from test_console import Watch, _errors, _keys, _open, _rhbl, _wait_learner  # noqa: E402
from test_console_teach import _attr, _fresh, _int, _press, _until  # noqa: E402

from client.journal import Journal, journal_path  # noqa: E402
from client.player import PlayerClient  # noqa: E402
from process.session import make_config  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


@pytest.fixture(scope="module")
def env(start_module_server):
    srv = start_module_server("goals-red-green")
    console = ConsoleProcess(srv.endpoint, "--behaviour", "red-green")
    console.wait_url()
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        sim = PlayerClient(session=session, source="test").simulation
        yield {"srv": srv, "console": console, "session": session, "sim": sim,
               "watch": Watch(session), "starts": sim.get_world().starts}
    rc = console.stop()
    assert rc == 0, console.output()


def _drive(browser, n: int, what: str) -> None:
    """Hold the up arrow until ``n`` more labels were given."""
    given = _int(browser, "labels", "given")
    _keys(browser, ("down", "ARROW_UP"))
    try:
        _until(browser, lambda d: _int(d, "labels", "given") >= given + n, 15, what)
    finally:
        _keys(browser, ("up", "ARROW_UP"))


def test_the_person_marks_each_goal_reached_and_the_learner_learns_both_trees(env, browser,
                                                                           tmp_path: Path):
    from client.behaviour.goals import DONE, GoalPolicy, load_policy

    out = tmp_path / "rg.rhbl"
    learner = _rhbl("learner", tmp_path, "learner", "--behaviour", "red-green", "--out",
                    str(out), "--snapshot-every", "0.3", "--connect", env["srv"].endpoint)
    try:
        _wait_learner(env, learner)
        env["sim"].set_pose2d(*env["starts"][0])
        _open(browser, env["console"].url)
        _until(browser, lambda d: _attr(d, "learner", "up") == "1", 20, "a learner is up")
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "1", 20,
               "the page: your goal is beacon 1")
        assert "goal 1/2: beacon 1" in browser.find_element("id", "yourgoal").text
        _drive(browser, 5, "five labels for goal 1")
        env["watch"].wait(Watch.stopped, 5, "the robot stops")
        _press(browser, "g")  # goal 1 reached
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "2", 10,
               "the page: your goal is beacon 2")
        assert "goal 1 (beacon 1) reached: now goal 2/2: beacon 2" in \
            browser.find_element("id", "info").text
        _drive(browser, 5, "five labels for goal 2")
        env["watch"].wait(Watch.stopped, 5, "the robot stops")
        _press(browser, "g")  # goal 2 reached: the last; the goals from the first again
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "1", 10,
               "after the last goal, the first again")
        _drive(browser, 3, "three labels for goal 1 again, the mark of goal 2 with the first")
        env["watch"].wait(Watch.stopped, 5, "the robot stops")
        _press(browser, "g")  # goal 1 marked ...
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "2", 10, "beacon 2")
        _press(browser, "1")  # ... but the robot is put at a start: the goals begin again
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "1", 10,
               "put at a start: goal 1 again")
        _drive(browser, 3, "three labels after the robot was put at a start")
        env["watch"].wait(Watch.stopped, 5, "the robot stops")
        _press(browser, "g")  # two goals marked before the next label: both marks kept, each
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "2", 10, "beacon 2")
        _press(browser, "g")  # carried by a label in turn
        _until(browser, lambda d: _attr(d, "yourgoal", "beacon") == "1", 10, "beacon 1")
        _drive(browser, 3, "three labels carrying the two marks")
        env["watch"].wait(Watch.stopped, 5, "the robot stops")
        _fresh(browser)
        _until(browser, lambda d: _int(d, "labels", "waiting") == 0
               and _int(d, "labels", "held") == _int(d, "labels", "given"), 30,
               "the learner holds every label")
        given = _int(browser, "labels", "given")
    finally:
        rc = learner.stop()
    assert rc == 0, learner.output()
    with Journal.open(journal_path(out), readonly=True) as j:
        recs = list(j.standing())
    assert len(recs) == given >= 19
    goals = [r.goal for r in recs]
    marks = [(k, r.reached) for k, r in enumerate(recs) if r.reached is not None]
    # the first label after each G carries the goal reached and is for the next one; the mark
    # given before the robot was put at a start is not carried (that goal was not reached)
    assert [m for _, m in marks] == [1, 2, 1, 2], marks
    k1, k2, k3, k4 = (k for k, _ in marks)
    assert set(goals[:k1]) == {1} and goals[k1] == 2 and set(goals[k1:k2]) == {2}
    assert goals[k2] == 1 and set(goals[k2:k3]) == {1}
    assert k4 == k3 + 1 and set(goals[k3:]) == {1}  # the two marks on two labels in a row
    assert all(r.seen is not None for r in recs)
    policy = load_policy(out)
    assert isinstance(policy, GoalPolicy) and DONE in policy.completion.classes_
    assert policy.metadata["provenance"]["marks"] == 4
    assert _errors(browser) == []


def test_g_without_goals_is_refused_by_name(env):
    """Marking a goal reached needs a behaviour with goals: a console teaching wall following
    in the same world refuses the page's message by name (the page hides its button there)."""
    import json

    from test_console_edges import _frame, _messages, _ws

    console = ConsoleProcess(env["srv"].endpoint, "--behaviour", "wall-following")
    try:
        console.wait_url()
        s = _ws(console)
        try:
            s.sendall(_frame(json.dumps({"t": "reached"})))
            got = _messages(s, lambda m: any(x.get("t") == "error" for x in m))
        finally:
            s.close()
        err = next(x["error"] for x in got if x.get("t") == "error")
        assert "has no goals in order" in err, err
    finally:
        assert console.stop() == 0, console.output()
