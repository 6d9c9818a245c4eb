"""``rhbl console`` in a real headless Chromium against a real server, learner and console process.

The page loads without errors in the browser's console and draws the robot where the server has
it; holding ArrowUp teaches a real learner ``fwd``; releasing the key, the page losing focus and
the tab closing each stop the robot at once; a second page cannot drive while the first holds the
robot until it takes over explicitly; a foreign Origin and a wrong token are refused; malformed
WebSocket messages get an error and never crash the console. Tests wait on events (a State, a
label, a DOM attribute), never on fixed sleeps.

Skipped with the reason when no Chromium is installed, except in CI (``CI=true``): there a
missing browser fails.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
aiohttp = pytest.importorskip("aiohttp")

from browser import ConsoleProcess  # noqa: E402
from waiting import wait_token  # noqa: E402

from client.journal import Journal, journal_path  # noqa: E402
from client.player import PlayerClient  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import (  # noqa: E402
    Decision,
    DecisionGoal,
    State,
    TeacherAction,
    TreeNotice,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]
STOP_WITHIN = 0.5 + 1.0  # the server's watchdog (0.5 s) and a margin for a loaded machine


class Watch:
    """The server's States and the teacher's labels of r0, as they arrive."""

    def __init__(self, session):
        self.state: State | None = None
        self.labels: list[TeacherAction] = []
        self.notice: TreeNotice | None = None
        self.cond = threading.Condition()
        self._subs = [
            session.declare_subscriber(keys.state_key("r0"), self._on_state),
            session.declare_subscriber(keys.teacher_action_key("r0"), self._on_label),
            session.declare_subscriber(keys.learner_notice_key("r0"), self._on_notice),
        ]

    def _on_state(self, s):
        with self.cond:
            self.state = State.decode(s.payload.to_bytes())
            self.cond.notify_all()

    def _on_label(self, s):
        with self.cond:
            self.labels.append(TeacherAction.decode(s.payload.to_bytes()))
            self.cond.notify_all()

    def _on_notice(self, s):
        with self.cond:
            self.notice = TreeNotice.decode(s.payload.to_bytes())
            self.cond.notify_all()

    def wait(self, pred, timeout: float, what: str):
        with self.cond:
            if not self.cond.wait_for(lambda: self.state is not None and pred(self), timeout):
                raise AssertionError(f"not within {timeout:g} s: {what} (last state "
                                     f"{self.state}, {len(self.labels)} labels)")

    def stopped(self) -> bool:
        s = self.state
        return s.driver == "" and abs(s.vel[0]) < 1e-6 and abs(s.vel[2]) < 1e-6


def _driving(w: Watch) -> bool:
    return w.state.driver == "teacher" and w.state.vel[0] > 0.1


@pytest.fixture(scope="module")
def env(start_module_server):
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint)
    console.wait_url()
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        sim = PlayerClient(session=session, source="test").simulation
        yield {"srv": srv, "console": console, "session": session, "sim": sim,
               "watch": Watch(session), "start": sim.get_world().starts[0]}
    rc = console.stop()
    assert rc == 0, console.output()


def _home(env) -> None:
    env["sim"].set_pose2d(*env["start"])


def _open(browser, url: str) -> None:
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(url)
    WebDriverWait(browser, 20).until(
        lambda d: d.find_element("id", "link").get_attribute("data-state") == "open"
        and d.find_element("id", "pose").get_attribute("data-x"))
    browser.find_element("id", "view").click()  # the canvas has the focus: keys reach the page


def _keys(browser, *actions) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    chain = ActionChains(browser)
    for kind, key in actions:
        key = getattr(Keys, key)
        chain = chain.key_down(key) if kind == "down" else chain.key_up(key)
    chain.perform()


def _errors(browser) -> list:
    return [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def test_page_loads_without_errors_and_draws_the_robot_where_the_server_has_it(env, browser):
    from selenium.webdriver.support.ui import WebDriverWait

    _home(env)
    _open(browser, env["console"].url)
    WebDriverWait(browser, 10).until(
        lambda d: int(d.find_element("id", "view").get_attribute("data-walls") or 0) > 4)
    x0 = float(browser.find_element("id", "pose").get_attribute("data-x"))
    assert abs(x0 - env["start"][0]) < 0.05
    # the server's robot moves (a teleport to another start pose): the drawn robot follows
    x, y, yaw = env["sim"].get_world().starts[1]
    env["sim"].set_pose2d(x, y, yaw)
    WebDriverWait(browser, 10).until(lambda d: abs(
        float(d.find_element("id", "pose").get_attribute("data-x")) - x) < 0.01 and abs(
        float(d.find_element("id", "pose").get_attribute("data-y")) - y) < 0.01)
    assert _errors(browser) == []
    _home(env)


def _rhbl(name: str, logdir: Path, *args: str) -> Child:
    """``rhbl ARGS...`` logging to ``logdir/<name>.log``; stop() sends SIGINT and returns 0
    only if SIGINT alone ended it (else SIGKILL after 30 s)."""
    return Child(name, rhbl_argv(*args), logdir, cwd=ROOT, stop_signal=signal.SIGINT,
                 stop_timeout=30.0, escalate=False).start()


def _learner(out: Path, endpoint: str, logdir: Path) -> Child:
    return _rhbl("learner", logdir, "learner", "--features", "wall", "--out", str(out),
                 "--snapshot-every", "0.3", "--connect", endpoint)


def test_holding_arrow_up_teaches_the_learner_fwd_and_releasing_stops(env, browser, tmp_path):
    from selenium.webdriver.support.ui import WebDriverWait

    w, session = env["watch"], env["session"]
    out = tmp_path / "tree.rhbl"
    learner = _learner(out, env["srv"].endpoint, tmp_path)
    try:
        wait_token(session, keys.alive_key("learner", f"r0-{learner.pid}"), alive=[learner])
        _home(env)
        _open(browser, env["console"].url)
        before = len(w.labels)
        _keys(browser, ("down", "ARROW_UP"))
        w.wait(_driving, 5, "the teacher (the page) drives forward")
        # a second of holding: ten scans labelled at the server's 10 Hz
        w.wait(lambda w: len(w.labels) - before >= 10, 5, "ten labels")
        _keys(browser, ("up", "ARROW_UP"))
        t0 = time.monotonic()
        w.wait(Watch.stopped, STOP_WITHIN, "the robot stops after the key is released")
        assert time.monotonic() - t0 < STOP_WITHIN
        fresh = w.labels[before:]
        assert {a.action for a in fresh} == {"fwd"} and all(a.executed == "fwd" for a in fresh)
        assert len({a.scan_id for a in fresh}) == len(fresh)  # one label per scan
        n = len(fresh)
        w.wait(lambda w: w.notice is not None and w.notice.vectors >= n, 10,
               f"the learner's notice counts {n} vectors")
        WebDriverWait(browser, 10).until(
            lambda d: int(d.find_element("id", "tree").get_attribute("data-vectors") or 0) >= n)
    finally:
        rc = learner.stop()
    assert rc == 0, learner.output()
    with Journal.open(journal_path(out), readonly=True) as j:
        labels = [r.label for r in j.records()]
    assert len(labels) >= n and set(labels) == {"fwd"}
    # the controller drives that tree: its decisions reach the bus and the page
    decisions = []
    sub = session.declare_subscriber(keys.controller_decision_key("r0"),
                                     lambda s: decisions.append(Decision.decode(s.payload)))
    ctl = _rhbl("controller", tmp_path, "controller", "--tree", str(out), "--seconds", "2",
                "--connect", env["srv"].endpoint)
    try:
        # the tree's action and its sphere; the guard's, when it turned the order (a wall close
        # ahead of where the person drove the robot): "fwd (the guard commanded rot-left): ..."
        WebDriverWait(browser, 30).until(lambda d: re.match(
            r"fwd( \(the guard commanded [a-z-]+\))?: sphere #",
            d.find_element("id", "decision").text))
        assert ctl.wait(30) == 0, ctl.output()
    finally:
        ctl.kill()  # nothing if it ended
        sub.undeclare()
    assert decisions and all(d.action == "fwd" and d.path and d.path[0][0] == 0
                             and d.path[-1][3] == "fwd" for d in decisions)
    assert len({d.scan_id for d in decisions}) == len(decisions)
    assert decisions[-1].snapshot_id.endswith(f":{len(labels)}")
    w.wait(Watch.stopped, STOP_WITHIN + 1.0, "the robot stops after the controller")
    assert _errors(browser) == []


def _wait_learner(env, learner: Child) -> None:
    wait_token(env["session"], keys.alive_key("learner", f"r0-{learner.pid}"), alive=[learner])


def _mode(browser, mode: str) -> None:
    browser.find_element("css selector", f"#modes input[value={mode}]").click()
    browser.find_element("id", "view").click()  # keys go to the page again


def test_correct_mode_takes_over_and_hands_back_to_a_following_controller(env, browser, tmp_path):
    """demonstrate, then a controller --from-learner --follow drives; in correct mode a key takes
    over (its labels are learned) and releasing hands the robot back at once; the controller
    picks up the grown tree without stopping; in watch mode keys neither drive nor teach."""
    w = env["watch"]
    out = tmp_path / "tree.rhbl"
    learner = _learner(out, env["srv"].endpoint, tmp_path)
    ctl = None
    decisions: list[Decision] = []

    def on_decision(sample):
        with w.cond:
            decisions.append(Decision.decode(sample.payload))
            w.cond.notify_all()

    sub = env["session"].declare_subscriber(keys.controller_decision_key("r0"), on_decision)
    try:
        _wait_learner(env, learner)
        _home(env)
        _open(browser, env["console"].url)
        before = len(w.labels)
        _keys(browser, ("down", "ARROW_UP"))
        w.wait(lambda w: len(w.labels) - before >= 10, 10, "ten demonstrated labels")
        _keys(browser, ("up", "ARROW_UP"))
        w.wait(Watch.stopped, STOP_WITHIN, "stopped after the demonstration")
        demonstrated = len(w.labels) - before
        w.wait(lambda w: w.notice is not None and w.notice.vectors >= demonstrated, 10,
               "the learner learned the demonstration")
        ctl = _rhbl("controller", tmp_path, "controller", "--from-learner", "--follow",
                    "--connect", env["srv"].endpoint)
        w.wait(lambda w: w.state.driver == "controller", 30, "the controller drives")
        _mode(browser, "correct")
        mark = len(w.labels)
        _keys(browser, ("down", "ARROW_LEFT"))
        w.wait(lambda w: w.state.driver == "teacher", 5, "a key takes over from the controller")
        w.wait(lambda w: len(w.labels) - mark >= 5, 10, "five corrections")
        _keys(browser, ("up", "ARROW_LEFT"))
        t0 = time.monotonic()
        w.wait(lambda w: w.state.driver == "controller", STOP_WITHIN,
               "releasing hands the robot back to the controller")
        assert time.monotonic() - t0 < STOP_WITHIN
        corrections = w.labels[mark:]
        assert {a.action for a in corrections} == {"rot-left"}
        total = demonstrated + len(corrections)
        # the following controller swaps in the grown tree and keeps driving
        w.wait(lambda w: w.notice.vectors >= total, 10, "the corrections are learned")
        w.wait(lambda w: any(d.snapshot_id.endswith(f":{total}") for d in decisions[-20:]),
               30, "the controller decides with the grown tree")
        assert ctl.poll() is None, ctl.output()
        assert ctl.wait_for_line("swapped in a newer tree", 5), ctl.output()  # 5 s: the pipe
        # watch: keys neither drive nor teach
        _mode(browser, "watch")
        mark, seq = len(w.labels), w.state.seq
        _keys(browser, ("down", "ARROW_UP"))
        w.wait(lambda w: w.state.seq >= seq + 10, 10, "ten ticks")
        _keys(browser, ("up", "ARROW_UP"))
        assert len(w.labels) == mark and w.state.driver == "controller"
        assert ctl.poll() is None
        _mode(browser, "demonstrate")
    finally:
        sub.undeclare()
        for p in (ctl, learner):
            if p is not None:
                p.stop()  # SIGINT, SIGKILL after 30 s
    w.wait(Watch.stopped, STOP_WITHIN + 2.0, "the robot stops when the controller stops")
    assert _errors(browser) == []


@pytest.mark.parametrize("key", ["SPACE", "ESCAPE"])
def test_space_or_escape_releases_the_robot_with_the_arrow_still_down(env, browser, key):
    w = env["watch"]
    _home(env)
    _open(browser, env["console"].url)
    _keys(browser, ("down", "ARROW_UP"))
    try:
        w.wait(_driving, 5, "the page drives")
        _keys(browser, ("down", key), ("up", key))
        w.wait(Watch.stopped, STOP_WITHIN, f"{key} releases the robot")
    finally:
        _keys(browser, ("up", "ARROW_UP"))


def test_zoom_pan_and_follow(env, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.support.ui import WebDriverWait

    _home(env)
    _open(browser, env["console"].url)
    view = browser.find_element("id", "view")
    scale = float(view.get_attribute("data-scale"))
    ActionChains(browser).scroll_from_origin(ScrollOrigin.from_element(view), 0, -300).perform()
    WebDriverWait(browser, 5).until(lambda d: float(view.get_attribute("data-scale")) > scale)
    cx = float(view.get_attribute("data-cx"))
    ActionChains(browser).click_and_hold(view).move_by_offset(120, 0).release().perform()
    WebDriverWait(browser, 5).until(lambda d: float(view.get_attribute("data-cx")) < cx - 0.1)
    browser.find_element("id", "follow").click()
    x = float(browser.find_element("id", "pose").get_attribute("data-x"))
    WebDriverWait(browser, 5).until(lambda d: abs(float(view.get_attribute("data-cx")) - x) < 0.01)
    browser.find_element("id", "follow").click()  # off again for the next tests


def test_on_screen_buttons_drive_while_pressed(env, browser):
    from selenium.webdriver.common.action_chains import ActionChains

    w = env["watch"]
    _home(env)
    _open(browser, env["console"].url)
    button = browser.find_element("css selector", "#pad button[data-action=fwd]")
    ActionChains(browser).click_and_hold(button).perform()
    try:
        w.wait(_driving, 5, "the page drives while the button is pressed")
        assert w.labels[-1].action == "fwd"
    finally:
        ActionChains(browser).release(button).perform()
    w.wait(Watch.stopped, STOP_WITHIN, "the robot stops when the button is released")


def test_losing_focus_stops_the_robot(env, browser):
    w = env["watch"]
    _home(env)
    _open(browser, env["console"].url)
    first = browser.current_window_handle
    _keys(browser, ("down", "ARROW_UP"))
    w.wait(_driving, 5, "the page drives")
    browser.switch_to.new_window("tab")  # the console's tab loses the focus, the key stays down
    t0 = time.monotonic()
    try:
        w.wait(Watch.stopped, STOP_WITHIN, "the robot stops when the page loses the focus")
        assert time.monotonic() - t0 < STOP_WITHIN
    finally:
        browser.close()
        browser.switch_to.window(first)
        _keys(browser, ("up", "ARROW_UP"))


def test_closing_the_tab_stops_the_robot(env, browser):
    w = env["watch"]
    _home(env)
    browser.get("about:blank")  # an earlier page in this tab would still hold the robot
    first = browser.current_window_handle
    browser.switch_to.new_window("tab")
    _open(browser, env["console"].url)
    _keys(browser, ("down", "ARROW_UP"))
    w.wait(_driving, 5, "the page in the second tab drives")
    browser.close()  # the tab closes with the key still down
    t0 = time.monotonic()
    browser.switch_to.window(first)
    w.wait(Watch.stopped, STOP_WITHIN, "the robot stops when the tab closes")
    assert time.monotonic() - t0 < STOP_WITHIN + 1.0  # switch_to.window's round trip included


def test_a_second_page_cannot_drive_until_it_takes_over(env, browser):
    from selenium.webdriver.support.ui import WebDriverWait

    w = env["watch"]
    _home(env)
    _open(browser, env["console"].url)
    first = browser.current_window_handle
    _keys(browser, ("down", "ARROW_LEFT"))
    w.wait(lambda w: w.state.driver == "teacher", 5, "the first page drives")
    _keys(browser, ("up", "ARROW_LEFT"))
    w.wait(Watch.stopped, STOP_WITHIN, "the first page released the key (and still holds)")
    browser.switch_to.new_window("tab")
    try:
        _open(browser, env["console"].url)
        hold = browser.find_element("id", "hold")
        WebDriverWait(browser, 10).until(lambda d: hold.get_attribute("data-holder") == "other")
        labels = len(w.labels)
        _keys(browser, ("down", "ARROW_UP"))
        WebDriverWait(browser, 10).until(
            lambda d: "holds robot" in d.find_element("id", "error").text)
        assert len(w.labels) == labels and w.state.driver == ""
        _keys(browser, ("up", "ARROW_UP"))
        browser.find_element("id", "take").click()
        WebDriverWait(browser, 10).until(lambda d: hold.get_attribute("data-holder") == "me")
        browser.find_element("id", "view").click()
        _keys(browser, ("down", "ARROW_UP"))
        w.wait(_driving, 5, "the second page drives after taking over")
        _keys(browser, ("up", "ARROW_UP"))
        w.wait(Watch.stopped, STOP_WITHIN, "stopped")
    finally:
        browser.close()
        browser.switch_to.window(first)
    assert _errors(browser) == []


async def _handshake(url: str, **kw) -> int:
    async with aiohttp.ClientSession() as s:
        try:
            async with s.ws_connect(url, **kw) as ws:
                msg = await ws.receive(timeout=10)
                assert json.loads(msg.data)["t"] == "hello"
                return 101
        except aiohttp.WSServerHandshakeError as exc:
            return exc.status


async def _get(url: str) -> int:
    async with aiohttp.ClientSession() as s, s.get(url) as r:
        return r.status


def test_foreign_origin_and_wrong_token_are_refused(env):
    console = ConsoleProcess(env["srv"].endpoint, "--token", "s3cret-console-t0ken")
    try:
        url = console.wait_url()
        assert url.endswith("/?token=s3cret-console-t0ken")
        base = console.base
        own = base.rstrip("/")
        ok = f"{base}ws?token=s3cret-console-t0ken"
        assert asyncio.run(_handshake(ok, origin=own)) == 101
        assert asyncio.run(_handshake(ok, origin="http://evil.example")) == 403
        assert asyncio.run(_handshake(f"{base}ws?token=wrong", origin=own)) == 401
        assert asyncio.run(_handshake(f"{base}ws", origin=own)) == 401
        assert asyncio.run(_get(f"{base}?token=wrong")) == 401
        assert asyncio.run(_get(url)) == 200
    finally:
        assert console.stop() == 0, console.output()


async def _bad_messages(url: str) -> list[str]:
    errors = []
    async with aiohttp.ClientSession() as s, s.ws_connect(url) as ws:
        for bad in ("not json", "[1, 2]", json.dumps({"t": "fly"}),
                    json.dumps({"t": "drive", "action": "jump", "scan_id": 1}),
                    json.dumps({"t": "drive", "action": "fwd", "scan_id": "x"}),
                    json.dumps({"t": "drive", "action": "fwd", "scan_id": 10**30}),
                    json.dumps({"t": "mode", "mode": 3}), json.dumps({"t": "view", "robot": []})):
            await ws.send_str(bad)
        await ws.send_bytes(b"\x00\x01")
        end = time.monotonic() + 20
        while len(errors) < 9 and time.monotonic() < end:
            m = json.loads((await ws.receive(timeout=10)).data)
            if m["t"] == "error":
                errors.append(m["error"])
        assert not ws.closed
        await ws.send_str("x" * 5000)  # over the 4 KiB limit: this connection ends
        end = time.monotonic() + 20
        while not ws.closed and time.monotonic() < end:
            await ws.receive(timeout=10)
        assert ws.closed
    async with aiohttp.ClientSession() as s, s.ws_connect(url) as ws:  # the console serves on
        assert json.loads((await ws.receive(timeout=10)).data)["t"] == "hello"
    return errors


def test_a_foreign_host_name_is_refused_without_a_token(env):
    """DNS rebinding: a site whose name points at 127.0.0.1 reaches the console under its own
    name (and its own origin); without a token only loopback names are served."""
    base = env["console"].base

    async def status(host: str, path: str) -> int:
        async with aiohttp.ClientSession() as s, s.get(base + path, headers={"Host": host}) as r:
            return r.status

    assert asyncio.run(status("evil.example:80", "")) == 403
    assert asyncio.run(status("evil.example:80", "ws")) == 403
    port = base.rsplit(":", 1)[1].strip("/")
    assert asyncio.run(status(f"localhost:{port}", "")) == 200
    assert asyncio.run(status(f"127.0.0.1:{port}", "")) == 200


def test_malformed_messages_get_an_error_and_the_console_lives_on(env):
    errors = asyncio.run(_bad_messages(env["console"].base + "ws"))
    assert len(errors) == 9 and all(errors), errors
    assert any("bad message" in e for e in errors) and any("unknown action" in e for e in errors)
    assert env["console"].poll() is None
    env["watch"].wait(lambda w: w.state.driver == "", 5, "nothing drove")


def test_view_only_publishes_nothing(env):
    console = ConsoleProcess(env["srv"].endpoint, "--view-only")
    try:
        console.wait_url()

        async def drive() -> str:
            async with aiohttp.ClientSession() as s, s.ws_connect(console.base + "ws") as ws:
                await ws.send_str(json.dumps({"t": "drive", "action": "fwd", "scan_id": 1}))
                end = time.monotonic() + 20
                while time.monotonic() < end:
                    m = json.loads((await ws.receive(timeout=10)).data)
                    if m["t"] == "hello":
                        assert m["view_only"] is True
                    if m["t"] == "error":
                        return m["error"]
                return "no error within 20 s"

        assert "view-only" in asyncio.run(drive())
        tokens = [str(r.ok.key_expr) for r in env["session"].liveliness().get(
            keys.alive_key("*", "*"), timeout=1.0) if r.ok is not None]
        assert any(f"-{env['console'].pid}" in t for t in tokens)  # a driving console's
        assert not any(f"-{console.pid}" in t for t in tokens), tokens
    finally:
        assert console.stop() == 0, console.output()


def test_screenshot_of_the_page(env, browser):
    """docs/console.png is this screenshot (written there with RHBL_UPDATE_SCREENSHOT=1)."""
    from selenium.webdriver.support.ui import WebDriverWait

    x, y, yaw = env["sim"].get_world().starts[1]
    env["sim"].set_pose2d(x, y, yaw)
    _open(browser, env["console"].url)
    WebDriverWait(browser, 10).until(
        lambda d: abs(float(d.find_element("id", "pose").get_attribute("data-x")) - x) < 0.01
        and int(d.find_element("id", "view").get_attribute("data-walls") or 0) > 4)
    # a short drive so the trail and the driver show (fwd-left: a curve)
    _keys(browser, ("down", "ARROW_UP"), ("down", "ARROW_LEFT"))
    env["watch"].wait(lambda w: w.state.driver == "teacher", 5, "the page drives")
    n = len(env["watch"].labels)
    env["watch"].wait(lambda w: len(w.labels) - n >= 20, 10, "two seconds of labels (a trail)")
    # what a learner and a controller would say (their real messages, so the panels show)
    env["session"].put(keys.learner_notice_key("r0"), TreeNotice(
        seq=1, nodes=1391, height=9, vectors=5210, snapshot_id="demo:5210").encode())
    env["session"].put(keys.controller_decision_key("r0"), Decision(
        scan_id=env["watch"].labels[-1].scan_id, action="fwd-left", snapshot_id="demo:5210",
        nodes=1391, path=((0, 0, 2.9, "fwd"), (12, 1, 1.1, "fwd-left"),
                          (377, 2, 0.42, "fwd-left"))).encode())
    WebDriverWait(browser, 10).until(
        lambda d: d.find_element("id", "decision").text.startswith("fwd-left")
        and d.find_element("id", "tree").get_attribute("data-nodes") == "1391")
    if os.environ.get("RHBL_UPDATE_SCREENSHOT") == "1":
        path = ROOT / "docs" / "console.png"
    else:
        path = Path(tempfile.mkdtemp(prefix="rhbl-console-")) / "console.png"
    assert browser.save_screenshot(str(path))
    _keys(browser, ("up", "ARROW_LEFT"), ("up", "ARROW_UP"))
    env["watch"].wait(Watch.stopped, STOP_WITHIN, "stopped")
    assert path.stat().st_size > 10_000
    _home(env)


def test_the_decision_trace_shows_the_goal_and_why_it_changed(env, browser):
    """A controller driving a tree with goals (docs/goals.md): its decisions say the goal
    pursued and why the last one changed, and the page shows both beside the decision; a
    decision without a goal clears it."""
    from selenium.webdriver.support.ui import WebDriverWait

    _open(browser, env["console"].url)
    why = ("goal 1/2 (beacon 1) done at 12.3 s: completion tree: sphere 95 (depth 91) says "
           "done at beacon 1 (range 0.59 m, bearing 5 deg)")
    pursued = lambda d: d.find_element("id", "pursued")  # noqa: E731
    env["session"].put(keys.controller_decision_key("r0"), Decision(
        scan_id=1, action="fwd", path=((0, 0, 2.9, "fwd"),), goal=DecisionGoal(1, 2, 2),
        goal_why=why).encode())
    WebDriverWait(browser, 10).until(lambda d: pursued(d).get_attribute("data-index") == "1")
    assert pursued(browser).text == f"goal 2/2 (beacon 2); last change: {why}"
    assert pursued(browser).get_attribute("data-beacon") == "2"
    view = browser.execute_script("return window.rhbl.view()")
    assert view["pursued"] == {"index": 1, "count": 2, "beacon": 2, "why": why}
    env["session"].put(keys.controller_decision_key("r0"), Decision(
        scan_id=2, action="fwd", path=((0, 0, 2.9, "fwd"),)).encode())
    WebDriverWait(browser, 10).until(lambda d: pursued(d).get_attribute("data-index") == "")
    assert pursued(browser).text == "-"
    assert browser.execute_script("return window.rhbl.view()")["pursued"] is None
    assert _errors(browser) == []


def test_tls_with_a_token(env, tmp_path):
    """--tls-cert/--tls-key: the page and its WebSocket over TLS (https, wss), token in the URL."""
    import shutil
    import ssl

    if shutil.which("openssl") is None:
        pytest.skip("openssl is needed to make a test certificate")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
                    "-subj", "/CN=localhost", "-addext", "subjectAltName=IP:127.0.0.1",
                    "-keyout", str(key), "-out", str(cert)], check=True, capture_output=True)
    console = ConsoleProcess(env["srv"].endpoint, "--tls-cert", str(cert), "--tls-key", str(key),
                             "--token", "t0k-tls-console-26")
    try:
        url = console.wait_url()
        assert url.startswith("https://127.0.0.1:") and url.endswith("/?token=t0k-tls-console-26")
        trust = ssl.create_default_context(cafile=str(cert))

        async def check() -> tuple[int, int, int]:
            async with aiohttp.ClientSession() as s:
                async with s.get(url, ssl=trust) as r:
                    page = r.status
                wss = url.replace("https://", "wss://").replace("/?", "/ws?")
                async with s.ws_connect(wss, ssl=trust, origin=console.base.rstrip("/")) as ws:
                    hello = json.loads((await ws.receive(timeout=10)).data)
                try:  # plain HTTP on the TLS port is no page
                    async with s.get(url.replace("https://", "http://")) as r:
                        plain = r.status
                except aiohttp.ClientError:
                    plain = -1
            return page, hello["t"] == "hello", plain

        page, hello, plain = asyncio.run(check())
        assert page == 200 and hello and plain != 200
    finally:
        assert console.stop() == 0, console.output()


def test_robot_selector_views_and_drives_another_robot(start_server, browser):
    """A server with two robots: the page lists both; selecting r1 draws r1 and drives r1."""
    from selenium.webdriver.support.ui import Select, WebDriverWait

    srv = start_server("room", robots=2)
    console = ConsoleProcess(srv.endpoint)
    try:
        url = console.wait_url()
        with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
            states: dict[str, State] = {}
            cond = threading.Condition()

            def on_state(s):
                with cond:
                    states[str(s.key_expr).split("/")[1]] = State.decode(s.payload)
                    cond.notify_all()

            sub = session.declare_subscriber("rhbl/*/position2d/0/data/state", on_state)
            with cond:
                assert cond.wait_for(lambda: {"r0", "r1"} <= set(states), 10)
            r1 = states["r1"].truth
            _open(browser, url)
            WebDriverWait(browser, 10).until(lambda d: [o.get_attribute("value") for o in Select(
                d.find_element("id", "robot")).options] == ["r0", "r1"])
            Select(browser.find_element("id", "robot")).select_by_value("r1")
            WebDriverWait(browser, 10).until(lambda d: abs(
                float(d.find_element("id", "pose").get_attribute("data-x") or 1e9) - r1[0]) < 0.01)
            browser.find_element("id", "view").click()
            _keys(browser, ("down", "ARROW_UP"))
            with cond:
                assert cond.wait_for(lambda: states["r1"].driver == "teacher", 5), states
                assert states["r0"].driver == ""
            _keys(browser, ("up", "ARROW_UP"))
            with cond:
                assert cond.wait_for(lambda: states["r1"].driver == "", STOP_WITHIN), states
            sub.undeclare()
        browser.get("about:blank")
        assert _errors(browser) == []
    finally:
        assert console.stop() == 0, console.output()


def test_the_console_dying_stops_the_robot_and_the_page_says_so(env, browser):
    """The link drops the hard way (the console process is killed): no more commands, the
    server's watchdog stops the robot, and the page shows it is disconnected."""
    from selenium.webdriver.support.ui import WebDriverWait

    w = env["watch"]
    _home(env)
    console = ConsoleProcess(env["srv"].endpoint)
    try:
        _open(browser, console.wait_url())
        _keys(browser, ("down", "ARROW_UP"))
        w.wait(_driving, 5, "the page drives through the second console")
        console.send_signal(signal.SIGKILL)  # by PID, no wait: the clock starts now
        t0 = time.monotonic()
        w.wait(Watch.stopped, STOP_WITHIN, "the robot stops when the console dies")
        assert time.monotonic() - t0 < STOP_WITHIN
        WebDriverWait(browser, 10).until(
            lambda d: d.find_element("id", "link").get_attribute("data-state") == "closed")
        _keys(browser, ("up", "ARROW_UP"))
    finally:
        console.stop()
    browser.get("about:blank")
    browser.get_log("browser")  # the refused reconnections are expected here
