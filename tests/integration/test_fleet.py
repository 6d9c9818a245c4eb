"""A fleet spread over two ``rhbl server`` processes joined into one zenoh network.

Server A (a router) hosts robots a0 and a1; server B (a router connected to A) hosts b0 and b1.
One ``rhbl controller`` process per robot, each connected to the *other* robot's server, drives
its robot by name: every robot is driven by its controller and moves. Each server's liveliness
tokens say which robots it hosts (``rhbl/alive/server/<ident>/<robot>``, the ident unique by
default), and a third server asked to host a robot already hosted is refused with a clear error.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")

from process.session import make_config  # noqa: E402
from protocol.messages import DriverState, State  # noqa: E402
from server.node import hosted_robots  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    from lab.harness import make_learner, resolve_world
    from lab.recipe import recipe_for
    from lab.train import train

    path = tmp_path_factory.mktemp("fleet") / "tree.rhbl"
    spec = resolve_world("room")
    learner = make_learner("wall-following")
    train(spec, learner, recipe_for("wall-following").replace(seconds=30.0), seed=0)
    learner.save(path)
    return path


class Watch:
    """Drivers and positions of every robot on the network, from one client session."""

    def __init__(self, session) -> None:
        self.cond = threading.Condition()
        self.driver: dict[str, str] = {}
        self.first: dict[str, tuple[float, float]] = {}
        self.last: dict[str, tuple[float, float]] = {}
        self.subs = [
            session.declare_subscriber("rhbl/*/position2d/0/data/driver", self._on_driver),
            session.declare_subscriber("rhbl/*/position2d/0/data/state", self._on_state),
        ]

    def _on_driver(self, sample) -> None:
        robot = str(sample.key_expr).split("/")[1]
        with self.cond:
            self.driver[robot] = DriverState.decode(sample.payload.to_bytes()).source
            self.cond.notify_all()

    def _on_state(self, sample) -> None:
        robot = str(sample.key_expr).split("/")[1]
        pos = State.decode(sample.payload.to_bytes()).pos
        with self.cond:
            self.first.setdefault(robot, pos[:2])
            self.last[robot] = pos[:2]
            self.cond.notify_all()

    def moved(self, robot: str) -> float:
        if robot not in self.first:
            return 0.0
        (x0, y0), (x1, y1) = self.first[robot], self.last[robot]
        return ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5

    def wait(self, pred, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(pred, timeout)


def test_robots_on_two_servers_are_driven_by_name_wherever_they_run(start_server, tree):
    a = start_server("room", "--robot", "a0", "--robot", "a1", "--ident", "server-a")
    b = start_server("room", "--robot", "b0", "--robot", "b1", "--connect", a.endpoint)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    controllers: list[subprocess.Popen] = []
    try:
        with zenoh.open(make_config(mode="client", connect=[a.endpoint])) as session:
            hosted = hosted_robots(session)
            assert hosted["a0"] == ["server-a"] and hosted["a1"] == ["server-a"]
            # B's default ident is unique (<host>-<pid>) and differs from A's
            assert hosted["b0"] == hosted["b1"] and hosted["b0"][0].endswith(f"-{b.pid}")
            watch = Watch(session)
            for robot, endpoint in [("a0", b.endpoint), ("a1", b.endpoint),
                                    ("b0", a.endpoint), ("b1", a.endpoint)]:
                controllers.append(subprocess.Popen(
                    [sys.executable, "-m", "lab.cli", "controller", "--tree", str(tree),
                     "--robot", robot, "--connect", endpoint, "--log-level", "WARNING"],
                    cwd=ROOT, env=env, start_new_session=True,
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            robots = ["a0", "a1", "b0", "b1"]
            ok = watch.wait(lambda: all(watch.driver.get(r) == "controller" for r in robots)
                            and all(watch.moved(r) > 0.3 for r in robots), timeout=90)
            assert ok, f"drivers {watch.driver}, moved { {r: watch.moved(r) for r in robots} }"
            assert all(c.poll() is None for c in controllers)
    finally:
        for c in controllers:
            if c.poll() is None:
                os.kill(c.pid, signal.SIGINT)
        for c in controllers:
            try:
                c.wait(15)
            except subprocess.TimeoutExpired:
                os.kill(c.pid, signal.SIGKILL)
                c.wait(5)


def test_a_robot_hosted_twice_is_refused(start_server, free_port):
    a = start_server("room", "--robot", "a0", "--ident", "server-a")
    t0 = time.monotonic()
    dup = subprocess.run(
        [sys.executable, "-m", "lab.cli", "server", "--world", "room", "--robot", "x9",
         "--robot", "a0", "--listen", f"tcp/127.0.0.1:{free_port()}", "--connect", a.endpoint],
        cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert dup.returncode == 2, dup.stdout + dup.stderr
    assert "robot 'a0' is hosted by server server-a" in dup.stderr
    assert "x9" not in dup.stderr.split("refusing")[1]  # only the robot taken is named
    assert time.monotonic() - t0 < 30
    # the first server is unaffected
    assert a.proc.poll() is None
