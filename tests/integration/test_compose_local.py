"""docker/compose.yaml's scenario, run as local processes from the compose file itself.

Same commands and arguments as the containers (docker/compose_local.py maps /run/secrets and
/data to temporary directories and ``router`` to 127.0.0.1), a Python zenoh session in router
mode on the shipped router config standing in for the router image, secrets made by the
compose ``secrets`` service's own command. Only RHBL_TEACH_SECONDS and RHBL_DEMONSTRATE_SECONDS
are shortened. The teacher demonstrates, then corrects while the controller drives, then stops;
the scenario must end with a learned tree driving the robot.
"""

from __future__ import annotations

import importlib.util
import json
import os
import socket
import sys
import threading
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
from protocol import keys  # noqa: E402
from protocol.messages import DriverState, State  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
TEACH_SECONDS = 14
DEMONSTRATE_SECONDS = 8
ROBOT = "r0"


def _module(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "docker" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _observer(scenario, role="learner") -> zenoh.Config:
    """A reader with one of the scenario's own credentials (the router refuses anyone else)."""
    config = zenoh.Config.from_file(str(scenario.secrets / f"{role}.json5"))
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([f"tls/127.0.0.1:{scenario.port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def test_compose_scenario_ends_with_a_learned_tree_driving_the_robot(tmp_path):
    compose_local = _module("compose_local")
    healthcheck = _module("healthcheck")
    env = dict(os.environ, RHBL_TEACH_SECONDS=str(TEACH_SECONDS),
               RHBL_DEMONSTRATE_SECONDS=str(DEMONSTRATE_SECONDS), RHBL_LOG_LEVEL="INFO")
    scenario = compose_local.Scenario(tmp_path, _free_port(), env=env)
    drivers: list[tuple[float, str]] = []
    moving: list[tuple[float, str, float]] = []  # (time, driver, |vx|) from the state stream
    lock = threading.Lock()

    def on_driver(sample):
        with lock:
            drivers.append((time.monotonic(), DriverState.decode(sample.payload.to_bytes()).source))

    def on_state(sample):
        s = State.decode(sample.payload.to_bytes())
        with lock:
            moving.append((time.monotonic(), s.driver, abs(s.vel[0]) + abs(s.vel[2])))

    def logs():
        return "\n".join(
            f"--- {p.name} (exits {p.exits}):\n{p.log.read_text()[-1500:]}"
            for p in scenario.procs.values()
        )

    with scenario, zenoh.open(_observer(scenario)) as session:
        subs = [
            session.declare_subscriber(keys.driver_key(ROBOT), on_driver),
            session.declare_subscriber(keys.state_key(ROBOT), on_state),
        ]
        deadline = time.monotonic() + TEACH_SECONDS + 45
        handed_over = None
        while time.monotonic() < deadline:
            scenario.poll(restart_delay=1.0)
            teacher = scenario.procs["teacher"]
            with lock:
                recent = [d for t, d, v in moving if handed_over and t > handed_over + 1.0]
                driving = [v for t, d, v in moving if handed_over and t > handed_over + 1.0]
            if teacher.exits and handed_over is None:
                with lock:
                    if drivers and drivers[-1][1] == "controller":
                        handed_over = time.monotonic()
            if handed_over and len(recent) >= 30:
                break
            time.sleep(0.2)
        for sub in subs:
            sub.undeclare()

        # the teacher demonstrated, corrected and stopped by itself
        assert scenario.procs["teacher"].exits == [0], logs()
        assert "correcting from" in scenario.procs["teacher"].log.read_text(), logs()
        seen = [d for _, d in drivers]
        assert "teacher" in seen, logs()
        assert handed_over is not None, f"driver never became the controller: {seen}\n{logs()}"
        # after the hand-over the controller alone drives, and the robot moves
        assert recent and set(recent) == {"controller"}, logs()
        assert max(driving) > 0.05, logs()
        for name in ("server", "learner", "controller"):
            assert scenario.running(name), logs()
            ok, why = healthcheck.check(scenario.procs[name].popen.pid)
            assert ok, why

    # the learned tree is on the data volume, and a snapshot loads
    from rhbl import load

    tree = load(str(scenario.data / "tree.rhbl"))
    assert tree.node_count_ > 1
    assert tree.metadata.get("features")
