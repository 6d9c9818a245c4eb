"""Teaching by hand at ``rhbl console``, in a real headless Chromium against a real server,
learner and console process: what a person at the page needs to teach well.

- labels given before any learner is up are kept, the page says so, and a learner that comes up
  gets every one of them (its default ``--teacher auto`` learns them by the person rule);
- episodes (record, stop, discard) and undo withdraw labels: the learner rebuilds its tree
  without them and its journal keeps them out;
- the keys 1-9 put the robot at a start pose, dragging it on the map moves it, Home resets;
- in correct mode, a controller looping rot-left/rot-right is marked on the map and the page
  says "the robot is stuck here: show it the way"; a key takes over and the prompt goes; so
  does a real ``rhbl controller`` whose loop guard holds the robot from a loop (its
  decisions say so);
- where a tree's refinement by practice could not fix it (``rhbl refine``), a learner
  extending the refined tree makes the page list the places ("the robot asks"): one click puts
  the robot there, and the labels given from there count as shown;
- at 1200x800 the side panel never overflows sideways, with long tree ids and big numbers.

Keys are pressed as a person presses them (selenium's key events); tests wait on events (a
State, a DOM attribute, a notice), never on fixed sleeps. Skipped with the reason when no
Chromium is installed, except in CI (``CI=true``).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("aiohttp")

from browser import ConsoleProcess, chromium, close_chromium, find_chromium  # noqa: E402
from test_console import Watch, _errors, _keys, _open, _rhbl, _wait_learner  # noqa: E402
from test_withdraw import _Notices  # noqa: E402
from waiting import Timeout, eventually  # noqa: E402

from client.journal import Journal, journal_path  # noqa: E402
from client.player import PlayerClient  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Decision, Scan, TreeNotice  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


@pytest.fixture(scope="module")
def env(start_module_server):
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint)
    console.wait_url()
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        sim = PlayerClient(session=session, source="test").simulation
        starts = sim.get_world().starts
        yield {"srv": srv, "console": console, "session": session, "sim": sim,
               "watch": Watch(session), "starts": starts}
    rc = console.stop()
    assert rc == 0, console.output()


def _until(browser, pred, timeout: float = 20.0, what: str = ""):
    """``pred(browser)`` once it is true (an element not there yet: not yet); a failure says
    what the page shows."""
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException

    try:
        return eventually(lambda: pred(browser), timeout, what,
                          ignore=(NoSuchElementException, StaleElementReferenceException))
    except Timeout as exc:
        seen = {k: _text(browser, k) for k in ("learner", "labels", "episode", "hold", "info",
                                                "error", "stuck")}
        raise Timeout(f"{exc}; the page says {seen}") from None


def _attr(browser, el: str, name: str) -> str:
    return browser.find_element("id", el).get_attribute(f"data-{name}") or ""


def _int(browser, el: str, name: str) -> int:
    return int(_attr(browser, el, name) or 0)


def _text(browser, el: str) -> str:
    return browser.find_element("id", el).text


def _press(browser, key: str) -> None:
    """A key pressed and released as a person does (a letter, a digit or a Keys name)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    k = getattr(Keys, key) if len(key) > 1 else key
    ActionChains(browser).key_down(k).key_up(k).perform()


def _fresh(browser) -> None:
    """Wait for a ``teach`` message composed after now (they come every 0.5 s at least)."""
    seq = _int(browser, "learner", "seq")
    _until(browser, lambda d: _int(d, "learner", "seq") >= seq + 2, 10, "a fresh teach message")


def _near(pose, target, tol: float = 0.05) -> bool:
    return math.hypot(pose[0] - target[0], pose[1] - target[1]) < tol


def _hold_until(browser, key: str, pred, what: str, timeout: float = 15.0) -> None:
    _keys(browser, ("down", key))
    try:
        _until(browser, pred, timeout, what)
    finally:
        _keys(browser, ("up", key))


def _learner(env, tmp: Path, name: str):
    out = tmp / f"{name}.rhbl"
    p = _rhbl(name, tmp, "learner", "--features", "wall", "--out", str(out),
              "--snapshot-every", "0.3", "--connect", env["srv"].endpoint)
    p.out = out
    return p


def test_labels_before_any_learner_are_kept_shown_and_delivered(env, browser, tmp_path):
    w = env["watch"]
    env["sim"].set_pose2d(*env["starts"][0])
    _open(browser, env["console"].url)
    _until(browser, lambda d: _attr(d, "learner", "up") == "0", 20, "the page: no learner up")
    assert "no learner is up" in _text(browser, "learner")
    given0 = _int(browser, "labels", "given")
    _keys(browser, ("down", "ARROW_UP"))
    try:
        _until(browser, lambda d: "no learner is up" in _text(d, "hold"), 10,
               "the page says, while driving, that no learner is up")
        _until(browser, lambda d: _int(d, "labels", "given") - given0 >= 10, 15, "ten labels")
    finally:
        _keys(browser, ("up", "ARROW_UP"))
    w.wait(Watch.stopped, 5, "the robot stops")
    _fresh(browser)
    given = _int(browser, "labels", "given")
    _until(browser, lambda d: _int(d, "labels", "waiting") >= given - given0, 5,
           "every label given waits for a learner")
    assert _int(browser, "labels", "held") == 0
    learner = _learner(env, tmp_path, "late")
    try:
        _wait_learner(env, learner)
        _until(browser, lambda d: _attr(d, "learner", "up") == "1", 20, "the page: a learner")
        _until(browser, lambda d: _int(d, "labels", "waiting") == 0
               and _int(d, "labels", "held") == _int(d, "labels", "given") >= given, 30,
               "the learner holds every label given before it was up")
        given = _int(browser, "labels", "given")
        assert "a learner is listening" in _text(browser, "learner")
    finally:
        rc = learner.stop()
    assert rc == 0, learner.output()
    with Journal.open(journal_path(learner.out), readonly=True) as j:
        assert len(list(j.standing())) == given
        # the learner's default --teacher auto: the page's labels are a person's, so the new
        # lineage learns by the person rule, and its journal's header says so
        assert j.header["meta"]["learning"]["rule"] == "person"
    assert "the first label came from 'console'" in learner.output()
    assert _errors(browser) == []


def test_discarding_an_episode_and_undo_withdraw_labels_from_the_learner(env, browser,
                                                                         tmp_path):
    w, session = env["watch"], env["session"]
    notices = _Notices(session)
    learner = _learner(env, tmp_path, "episodes")
    try:
        _wait_learner(env, learner)
        env["sim"].set_pose2d(*env["starts"][0])
        _open(browser, env["console"].url)
        _until(browser, lambda d: _attr(d, "learner", "up") == "1", 20, "a learner is up")
        base = _int(browser, "labels", "held")
        if _attr(browser, "episode", "state") == "recording":  # the first key's episode
            _press(browser, "r")
            _until(browser, lambda d: _attr(d, "episode", "state") == "stopped", 10, "stopped")
        n0 = _attr(browser, "episode", "n")
        _press(browser, "r")  # record: a new episode
        _until(browser, lambda d: _attr(d, "episode", "state") == "recording"
               and _attr(d, "episode", "n") != n0, 10, "an episode records")
        first = _attr(browser, "episode", "n")
        _hold_until(browser, "ARROW_UP", lambda d: _int(d, "episode", "labels") >= 10,
                    "ten fwd labels in the episode")
        w.wait(Watch.stopped, 5, "the robot stops")
        _fresh(browser)
        _press(browser, "r")  # stop it
        _until(browser, lambda d: _attr(d, "episode", "state") == "stopped", 10, "stopped")
        fwd = _int(browser, "episode", "labels")
        _press(browser, "r")  # the next episode, taught rot-left: discarded
        _until(browser, lambda d: _attr(d, "episode", "state") == "recording"
               and _attr(d, "episode", "n") != first, 10, "a second episode records")
        _hold_until(browser, "ARROW_LEFT", lambda d: _int(d, "episode", "labels") >= 5,
                    "five rot-left labels")
        w.wait(Watch.stopped, 5, "the robot stops")
        _fresh(browser)
        left = _int(browser, "episode", "labels")
        withdrawn0 = _int(browser, "labels", "withdrawn")
        _press(browser, "x")  # discard it
        _until(browser, lambda d: _attr(d, "episode", "state") == "discarded", 10, "discarded")
        _until(browser, lambda d: _int(d, "labels", "withdrawn") - withdrawn0 == left, 10,
               "the page counts the episode's labels withdrawn")
        notices.wait(lambda n: n.vectors == fwd, 30,
                     f"the learner's tree rebuilt without the episode: {fwd} vectors")
        # undo: the last 3 s of teaching, well after the fwd labels (sim time, on the clock)
        t_fwd = w.state.ts
        w.wait(lambda w: w.state.ts > t_fwd + 6, 20, "six seconds of sim time")
        given = _int(browser, "labels", "given")
        _hold_until(browser, "ARROW_RIGHT", lambda d: _int(d, "labels", "given") - given >= 5,
                    "five rot-right labels")
        w.wait(Watch.stopped, 5, "the robot stops")
        _fresh(browser)
        right = _int(browser, "labels", "given") - given
        # the tree the console holds learned fwd only: it disagrees with every rot-right key
        _until(browser, lambda d: _int(d, "agreement", "n") >= right, 10, "the keys scored")
        assert float(_attr(browser, "agreement", "value")) < 1.0
        assert "the tree agrees with" in _text(browser, "agreement")
        notices.wait(lambda n: n.vectors == fwd + right, 30,
                     f"the rot-right labels learned ({fwd} fwd, {right} rot-right)")
        box = browser.find_element("id", "undo-seconds")
        box.clear()
        box.send_keys("3")
        browser.find_element("id", "view").click()
        withdrawn1 = _int(browser, "labels", "withdrawn")
        _press(browser, "z")
        _until(browser, lambda d: _int(d, "labels", "withdrawn") - withdrawn1 == right, 10,
               "undo withdraws exactly the rot-right labels")
        assert "undone" in _text(browser, "info")
        notices.wait(lambda n: n.vectors == fwd, 30, "the tree rebuilt without them")
        _until(browser, lambda d: _int(d, "labels", "held") - base >= fwd + left + right, 10,
               "every label acknowledged")
    finally:
        notices.sub.undeclare()
        rc = learner.stop()
    assert rc == 0, learner.output()
    with Journal.open(journal_path(learner.out), readonly=True) as j:
        standing = [r.label for r in j.standing()]
    assert standing == ["fwd"] * fwd
    assert _errors(browser) == []


def _screen(browser, x: float, y: float) -> tuple[int, int]:
    """The offset from the canvas's centre of the world point (x, y), in CSS pixels."""
    c = browser.find_element("id", "view")
    cx, cy, scale = (float(c.get_attribute(f"data-{k}")) for k in ("cx", "cy", "scale"))
    return round((x - cx) * scale), round(-(y - cy) * scale)


def test_keys_put_the_robot_at_a_start_dragging_moves_it_and_home_resets(env, browser,
                                                                         tmp_path):
    # a learner listening: after an earlier test's learner went away the console holds the
    # robot (labels would go nowhere) until one is back
    learner = _learner(env, tmp_path, "places")
    try:
        _wait_learner(env, learner)
        _places(env, browser)
    finally:
        learner.stop()


def _places(env, browser) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    w, starts = env["watch"], env["starts"]
    _open(browser, env["console"].url)
    _press(browser, "3")  # start pose 3
    w.wait(lambda w: _near(w.state.truth, starts[2]), 10, "the robot at start pose 3")
    assert abs(w.state.truth[2] - starts[2][2]) < 0.05
    _until(browser, lambda d: _near([float(_attr(d, "pose", k)) for k in ("x", "y")],
                                    starts[2]), 10, "the page draws it there")
    # re-record: an episode from here, a few labels, then E: they go, the robot comes back
    if _attr(browser, "episode", "state") == "recording":
        _press(browser, "r")
        _until(browser, lambda d: _attr(d, "episode", "state") == "stopped", 10, "stopped")
    _press(browser, "r")
    _until(browser, lambda d: _attr(d, "episode", "state") == "recording", 10, "recording")
    n = _attr(browser, "episode", "n")
    # held until 5 labels and the robot moved (a loaded machine may label faster than it moves)
    _hold_until(browser, "ARROW_UP", lambda d: _int(d, "episode", "labels") >= 5
                and not _near(w.state.truth, starts[2], 0.2), "5 labels, the robot moved")
    w.wait(Watch.stopped, 5, "the robot stops")
    _fresh(browser)
    withdrawn, labels = _int(browser, "labels", "withdrawn"), _int(browser, "episode", "labels")
    _press(browser, "e")
    w.wait(lambda w: _near(w.state.truth, starts[2]), 10, "back where the episode started")
    _until(browser, lambda d: _int(d, "labels", "withdrawn") - withdrawn == labels
           and _attr(d, "episode", "state") == "recording" and _attr(d, "episode", "n") != n,
           10, "its labels withdrawn, a new episode recording")
    # drag it by its body into the middle of the room
    canvas = browser.find_element("id", "view")
    x0, y0 = starts[2][0], starts[2][1]
    ox, oy = _screen(browser, x0, y0)
    tx, ty = _screen(browser, 6.0, 4.5)
    (ActionChains(browser).move_to_element_with_offset(canvas, ox, oy).click_and_hold()
     .move_by_offset((tx - ox) // 2, (ty - oy) // 2).move_by_offset(tx - ox - (tx - ox) // 2,
                                                                    ty - oy - (ty - oy) // 2)
     .release().perform())
    scale = float(canvas.get_attribute("data-scale"))
    w.wait(lambda w: _near(w.state.truth, (6.0, 4.5), 3.0 / scale + 0.02), 10,
           "the robot where it was dropped")
    assert abs(w.state.truth[2] - starts[2][2]) < 0.05  # moved, not turned
    _press(browser, "HOME")  # reset: r0 back at its start pose, 1
    w.wait(lambda w: _near(w.state.truth, starts[0]), 10, "reset: the robot at start pose 1")
    _until(browser, lambda d: "start pose (reset)" in _text(d, "info"), 10, "the page says so")
    assert _int(browser, "trouble", "markers") == 0
    assert _errors(browser) == []


def _purple_near(browser, x: float, y: float) -> bool:
    """A pixel of the loop colour (#9b3fd5) within 3 px of the world point (x, y) on the map."""
    ox, oy = _screen(browser, x, y)
    return browser.execute_script("""
        const c = document.getElementById("view"), dpr = window.devicePixelRatio || 1;
        const px = (c.clientWidth / 2 + arguments[0]) * dpr, py = (c.clientHeight / 2 + arguments[1]) * dpr;
        const d = c.getContext("2d").getImageData(px - 3 * dpr, py - 3 * dpr, 7 * dpr, 7 * dpr).data;
        for (let i = 0; i < d.length; i += 4)
          if (Math.abs(d[i] - 155) < 30 && Math.abs(d[i + 1] - 63) < 30 && Math.abs(d[i + 2] - 213) < 30) return true;
        return false;""", ox, oy)


def _ring_then_show_the_way(browser, w) -> dict:
    """The loop's mark drawn on the map (a purple ring of 0.18 m about it), then the person
    shows the way: the prompt goes while they drive. The loop's marker."""
    loop = next(m for m in browser.execute_script("return window.rhbl.view().markers")
                if m["kind"] == "loop")
    _until(browser, lambda d: _purple_near(d, loop["x"] + 0.18, loop["y"]), 5,
           "the loop's ring on the canvas")
    _keys(browser, ("down", "ARROW_UP"))
    try:
        w.wait(lambda w: w.state.driver == "teacher", 5, "the person takes over")
        _until(browser, lambda d: not d.find_element("id", "stuck").is_displayed(), 10,
               "the prompt goes while the person drives")
    finally:
        _keys(browser, ("up", "ARROW_UP"))
    return loop


class _Looper:
    """A stand-in for a learned robot that loops: a controller-source client answering every
    scan of r0, two scans rot-left then two rot-right (a rot-left/rot-right alternation)."""

    def __init__(self, session):
        self.client = PlayerClient(session=session, robot="r0", source="controller")
        self.n = 0
        self.sub = session.declare_subscriber(keys.scan_key("r0"), self._on_scan)

    def _on_scan(self, sample):
        scan = Scan.decode(sample.payload.to_bytes())
        self.client.answer(scan, 0.0, 0.8 if (self.n // 2) % 2 == 0 else -0.8)
        self.n += 1

    def close(self):
        self.sub.undeclare()
        self.client.close()


def test_correct_mode_marks_a_loop_and_asks_the_person_to_show_the_way(env, browser):
    w = env["watch"]
    env["sim"].set_pose2d(*env["starts"][0])
    _open(browser, env["console"].url)
    _press(browser, "c")  # correct mode, by its key
    _until(browser, lambda d: d.find_element("css selector", "#modes input[value=correct]")
           .is_selected(), 5, "correct mode")
    markers0 = _int(browser, "trouble", "loops")
    looper = _Looper(env["session"])
    try:
        w.wait(lambda w: w.state.driver.startswith("controller"), 10, "the looper drives")
        _until(browser, lambda d: _attr(d, "stuck", "why") == "loop", 20, "the stuck prompt")
        assert "the robot is stuck here" in _text(browser, "stuck")
        assert "show it the way" in _text(browser, "stuck")
        assert _int(browser, "trouble", "loops") > markers0
        assert browser.find_element("id", "stuck").is_displayed()
        _ring_then_show_the_way(browser, w)
    finally:
        looper.close()
    w.wait(Watch.stopped, 5, "the robot stops")
    _press(browser, "t")
    assert _errors(browser) == []


def _looping_tree(path: Path, pose) -> Path:
    """A learned tree that sends the robot at ``pose`` into a rot-left/rot-right loop: taught
    there, heading by heading, rot-left and rot-right in bands of 15 degrees (each rotation
    brings the robot into a band of the other)."""
    from client.behaviour.actions import DEFAULT_ACTIONS
    from client.behaviour.features import FEATURES
    from client.behaviour.learning import DemonstrationLearner
    from lab.harness import resolve_world
    from server.world import World

    world = World(resolve_world("room"))
    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following")
    for k in range(720):
        yaw = -math.pi + 2 * math.pi * k / 720
        world.set_pose(0, (pose[0], pose[1], yaw))
        learner.observe(world.scan(0), yaw, "rot-left" if int(math.degrees(yaw + math.pi) // 15)
                        % 2 else "rot-right")
    learner.save(path)
    return path


def test_the_controllers_loop_guard_asks_the_person_to_show_the_way(env, browser, tmp_path):
    """A real ``rhbl controller`` (its loop guard on, the default) drives a tree that loops: the
    guard keeps the loop off the bus (no rot-left/rot-right alternation for the console's own
    detector), and its decisions say it stepped in; in correct mode the page says "the robot
    is stuck here: show it the way" there, and marks the place."""
    w = env["watch"]
    start = env["starts"][0]
    tree = _looping_tree(tmp_path / "loop.rhbl", start)
    env["sim"].set_pose2d(*start)
    _open(browser, env["console"].url)
    _press(browser, "c")
    _until(browser, lambda d: d.find_element("css selector", "#modes input[value=correct]")
           .is_selected(), 5, "correct mode")
    _press(browser, "HOME")  # no marks of earlier tests
    _until(browser, lambda d: _int(d, "trouble", "markers") == 0, 10, "no trouble marks")
    ctl = _rhbl("controller", tmp_path, "controller", "--tree", str(tree), "--connect",
                env["srv"].endpoint, "--stats", str(tmp_path / "controller.json"))
    try:
        w.wait(lambda w: w.state.driver.startswith("controller"), 30, "the controller drives")
        _until(browser, lambda d: _attr(d, "stuck", "why") == "guard", 30,
               "the guard's stuck prompt")
        text = _text(browser, "stuck")
        assert "the robot is stuck here" in text and "show it the way" in text
        assert "loop guard" in text
        _until(browser, lambda d: _attr(d, "decision", "looping") == "1", 10,
               "the decision panel: the guard stepped in")
        loop = _ring_then_show_the_way(browser, w)
        assert _near((loop["x"], loop["y"]), start, 0.2)  # where the robot turns in place
    finally:
        rc = ctl.stop()
    assert rc == 0, ctl.output()
    stats = json.loads((tmp_path / "controller.json").read_text())
    assert stats["overruled"] > 0, stats  # it was the guard that stepped in
    _press(browser, "t")
    assert _errors(browser) == []


def test_a_remote_teacher_over_tls_with_a_token_teaches_the_same(env, tmp_path):
    """https and wss with a token: the page, its files and its WebSocket answer, the learner's
    status shows, the keys put the robot at a start pose, drive, record and undo."""
    import shutil
    import subprocess

    if shutil.which("openssl") is None:
        pytest.skip("openssl is needed to make a test certificate")
    found = find_chromium()
    if isinstance(found, str):
        pytest.skip(found)
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-subj", "/CN=localhost", "-addext", "subjectAltName=IP:127.0.0.1",
                    "-keyout", str(key), "-out", str(cert)], check=True, capture_output=True)
    console = ConsoleProcess(env["srv"].endpoint, "--tls-cert", str(cert), "--tls-key", str(key),
                             "--token", "rem0te-teacher-t0ken")
    b = chromium("--ignore-certificate-errors")
    w, starts = env["watch"], env["starts"]
    try:
        url = console.wait_url()
        assert url.startswith("https://") and url.endswith("?token=rem0te-teacher-t0ken")
        _open(b, url)
        _until(b, lambda d: _attr(d, "learner", "up") in ("0", "1"), 20, "the learner status")
        _press(b, "2")
        w.wait(lambda w: _near(w.state.truth, starts[1]), 10, "the robot at start pose 2")
        given = _int(b, "labels", "given")
        _hold_until(b, "ARROW_UP", lambda d: _int(d, "labels", "given") - given >= 5,
                    "five labels over TLS")
        w.wait(Watch.stopped, 5, "the robot stops")
        _fresh(b)
        withdrawn = _int(b, "labels", "withdrawn")
        _press(b, "z")
        _until(b, lambda d: _int(d, "labels", "withdrawn") > withdrawn, 10, "undo over TLS")
        assert _errors(b) == []
    finally:
        close_chromium(b)
        assert console.stop() == 0, console.output()


def _refined_ahead(tmp: Path) -> tuple[Path, list]:
    """A tree that only drives ahead (it collides), refined by ``rhbl refine`` for a few
    seconds: the refined snapshot and the asks it keeps."""
    from client.behaviour.learning import TreePolicy
    from lab.cli import main
    from rhbl import HypersphereClassifier

    tree = TreePolicy.load(Path(__file__).resolve().parents[1] / "rhbl" / "data" /
                           "room-1200.rhbl")
    clf = HypersphereClassifier(default_label="fwd")
    clf.partial_fit([[1.0] * tree.features.dim], ["fwd"])
    ahead, refined = tmp / "ahead.rhbl", tmp / "refined.rhbl"
    clf.save(str(ahead), metadata={"features": tree.features.to_dict(),
                                   "actions": tree.actions.to_dict()})
    assert main(["refine", "--behaviour", "wall-following", "--tree", str(ahead), "--out",
                 str(refined), "--seconds", "10", "--scales", "none", "--minutes", "0.02",
                 "--workers", "1"]) == 0
    asks = TreePolicy.load(refined).metadata["refinement"][-1]["asks"]
    return refined, [a for a in asks if a["world"] == "room" and a["scale"] == 1.0]


def test_the_robot_asks_to_be_shown_where_practice_could_not_fix_it(env, browser, tmp_path):
    w = env["watch"]
    refined, asks = _refined_ahead(tmp_path)
    assert asks, "refining a tree that only drives ahead for seconds fixes every start?"
    _open(browser, env["console"].url)  # before the learner: its tree comes when it is up
    learner = _rhbl("asks", tmp_path, "learner", "--resume", str(refined), "--out",
                    str(tmp_path / "corrected.rhbl"), "--snapshot-every", "0.3", "--connect",
                    env["srv"].endpoint)
    try:
        _wait_learner(env, learner)
        _until(browser, lambda d: _int(d, "asks", "n") == len(asks), 20,
               f"the page lists the {len(asks)} asks, no label given")
        assert not browser.find_element("id", "asks").get_attribute("hidden")
        n = len(asks)  # the last one: the robot is put where it went wrong
        browser.find_element("css selector",
                             f"#asks-list li[data-n='{n}'] button").click()
        pose = asks[-1]["pose"]
        w.wait(lambda w: _near(w.state.truth, pose) and abs(w.state.truth[2] - pose[2]) < 0.05,
               10, "the robot where the tree asks")
        _until(browser, lambda d: _attr(d, "asks", "asking") == str(n), 10, "asking there")
        browser.find_element("id", "view").click()  # keys to the page again
        _hold_until(browser, "ARROW_LEFT", lambda d: int(d.find_element(
            "css selector", f"#asks-list li[data-n='{n}']").get_attribute("data-shown")
            or 0) >= 3, "three labels shown there")
        w.wait(Watch.stopped, 5, "the robot stops")
        _press(browser, "HOME")  # put elsewhere: the labels count for no ask now
        _until(browser, lambda d: _attr(d, "asks", "asking") == "", 10, "no ask now")
        assert _errors(browser) == []
    finally:
        assert learner.stop() == 0, learner.output()


def test_side_panel_never_overflows_at_1200x800(env, browser):
    session = env["session"]
    browser.set_window_size(1200, 800)
    _open(browser, env["console"].url)
    long_id = "learner-r0-123456:" + "ab12" * 30 + ":2415"
    notice = TreeNotice(seq=999999, nodes=2415123, height=4321, vectors=24151234,
                        snapshot_id=long_id, ts=time.time())
    session.put(keys.learner_notice_key("r0"), notice.encode())
    decision = Decision(scan_id=123456789, ts=1.0, action="fwd-right",
                        snapshot_id=long_id, nodes=2415123,
                        path=[(i, i, 0.123456, "fwd-right") for i in range(40)])
    session.put(keys.controller_decision_key("r0"), decision.encode())
    _until(browser, lambda d: "2415123 nodes" in _text(d, "tree"), 10, "the notice drawn")
    _until(browser, lambda d: long_id[:20] in _text(d, "decision"), 10, "the decision drawn")
    over = browser.execute_script("""
        const aside = document.querySelector("aside"), right = aside.getBoundingClientRect().right;
        const out = [];
        if (aside.scrollWidth > aside.clientWidth) out.push("aside scrolls sideways");
        for (const el of aside.querySelectorAll("*")) {
          const r = el.getBoundingClientRect();
          if (r.width && r.right > right + 0.5) out.push(el.id || el.tagName);
          if (el.scrollWidth > el.clientWidth + 1 && getComputedStyle(el).overflowX === "hidden"
              && el !== aside) out.push((el.id || el.tagName) + " cut");
        }
        return out;""")
    assert over == []
    tree = browser.find_element("id", "tree")
    assert tree.text.endswith("24151234 vectors")  # the whole line, wrapped, not cut
    assert browser.execute_script("return innerWidth") <= 1200
    assert _errors(browser) == []
