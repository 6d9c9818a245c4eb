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
import os
import sys
import threading
import time
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
from lab.children import free_port  # noqa: E402
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


def _observer(scenario, role="learner") -> zenoh.Config:
    """A reader with one of the scenario's own credentials (the router refuses anyone else)."""
    return scenario.client_config(role)


def test_compose_scenario_ends_with_a_learned_tree_driving_the_robot(tmp_path):
    compose_local = _module("compose_local")
    healthcheck = _module("healthcheck")
    env = dict(os.environ, RHBL_TEACH_SECONDS=str(TEACH_SECONDS),
               RHBL_DEMONSTRATE_SECONDS=str(DEMONSTRATE_SECONDS), RHBL_LOG_LEVEL="INFO")
    scenario = compose_local.Scenario(tmp_path, free_port(), env=env)
    drivers: list[tuple[float, str]] = []
    recent: list[tuple[str, float]] = []  # (driver, |vx| + |va|) a second after the hand-over
    lock = threading.Lock()
    teacher_gone = threading.Event()
    handed_over = threading.Event()  # the first Driver message naming the controller after it
    enough = threading.Event()  # 30 states from then on
    handover_at: list[float] = []

    def on_driver(sample):
        source = DriverState.decode(sample.payload.to_bytes()).source
        with lock:
            drivers.append((time.monotonic(), source))
            if teacher_gone.is_set() and source == "controller" and not handover_at:
                handover_at.append(time.monotonic())
                handed_over.set()

    def on_state(sample):
        s = State.decode(sample.payload.to_bytes())
        with lock:
            if handover_at and time.monotonic() > handover_at[0] + 1.0:
                recent.append((s.driver, abs(s.vel[0]) + abs(s.vel[2])))
                if len(recent) >= 30:
                    enough.set()

    def logs():
        return "\n".join(
            f"--- {p.name} (exits {p.exits}):\n{p.child.tail(30)}" for p in scenario.procs.values()
        )

    with scenario, zenoh.open(_observer(scenario)) as session:
        subs = [
            session.declare_subscriber(keys.driver_key(ROBOT), on_driver),
            session.declare_subscriber(keys.state_key(ROBOT), on_state),
        ]
        # docker's part: restart services as their policy says (the controller exits until
        # the learner has a first tree)
        done = threading.Event()

        def supervise():
            while not done.wait(0.2):
                scenario.poll(restart_delay=1.0)

        supervisor = threading.Thread(target=supervise, daemon=True)
        supervisor.start()
        try:
            # the teacher demonstrates, corrects, then ends by itself; the controller drives on
            ended = scenario.procs["teacher"].child.wait(TEACH_SECONDS + 45)
            teacher_gone.set()
            assert ended is not None, f"the teacher did not end\n{logs()}"
            assert handed_over.wait(15), f"driver never became the controller: {drivers}\n{logs()}"
            assert enough.wait(15), f"{len(recent)} states after the hand-over\n{logs()}"
        finally:
            done.set()
            supervisor.join(10)
            for sub in subs:
                sub.undeclare()
        scenario.poll(restart_delay=1.0)  # the teacher's exit, if the supervisor missed it

        # the teacher demonstrated, corrected and stopped by itself
        assert scenario.procs["teacher"].exits == [0], logs()
        assert "correcting from" in scenario.procs["teacher"].log.read_text(), logs()
        assert "teacher" in [d for _, d in drivers], logs()
        # after the hand-over the controller alone drives, and the robot moves
        assert {d for d, _ in recent} == {"controller"}, logs()
        assert max(v for _, v in recent) > 0.05, logs()
        for name in ("server", "learner", "controller", "console"):
            assert scenario.running(name), logs()
            ok, why = healthcheck.check(scenario.procs[name].child.pid)
            assert ok, why

    # the learned tree is on the data volume, and a snapshot loads
    from rhbl import load

    tree = load(str(scenario.data / "tree.rhbl"))
    assert tree.node_count_ > 1
    assert tree.metadata.get("features")
