"""The processes report clearly: router unreachable, credentials refused, server not up,
a tree that does not fit, scans that stop. Each runs a real process for a second or two."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually, patience, wait_token  # noqa: E402

from lab.children import Child, rhbl_argv  # noqa: E402
from process.runtime import EXIT_NO_SERVER, EXIT_UNREACHABLE, EXIT_USAGE  # noqa: E402
from process.session import make_config  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]
ROOT = Path(__file__).resolve().parents[2]


def _run(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "lab.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_unreachable_router_names_the_endpoint(free_port):
    ep = f"tcp/127.0.0.1:{free_port()}"
    r = _run("teacher", "--connect", ep)
    assert r.returncode == EXIT_UNREACHABLE
    assert ep in r.stderr and "connection refused" in r.stderr and "Traceback" not in r.stderr


def test_refused_credentials(free_port, tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    users = tmp_path / "users.txt"
    users.write_text("teacher:right\n")
    cfg = make_config(mode="router", listen=[ep])
    cfg.insert_json5("transport/auth/usrpwd", json.dumps(
        {"user": "router", "password": "x", "dictionary_file": str(users)}))
    client = tmp_path / "teacher.json5"
    client.write_text(json.dumps({
        "mode": "client", "connect": {"endpoints": [ep]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"auth": {"usrpwd": {"user": "teacher", "password": "wrong"}}}}))
    with zenoh.open(cfg):
        r = _run("teacher", "--zenoh-config", str(client))
    assert r.returncode == EXIT_UNREACHABLE
    assert "refused the zenoh session" in r.stderr and "credentials" in r.stderr


def test_server_not_up(free_port):
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[ep])):
        r = _run("controller", "--connect", ep, "--tree", "x.rhbl", "--wait-server", "1")
        assert r.returncode == EXIT_USAGE and "argument --tree: x.rhbl does not exist" in r.stderr
        r = _run("teacher", "--connect", ep, "--wait-server", "1.5")
    assert r.returncode == EXIT_NO_SERVER, r.stderr
    assert "the server is not up" in r.stderr and "rhbl/r0/laser/0/data/scan" in r.stderr


def _tree(tmp_path, features="wall") -> Path:
    from client.behaviour.features import FEATURES
    from client.behaviour.learning import DemonstrationLearner

    learner = DemonstrationLearner(FEATURES[features], task="t")
    rng = np.random.default_rng(0)
    for _ in range(30):
        learner.observe(rng.uniform(0.2, 3, 360).astype(np.float32), 0.0,
                        str(rng.choice(["fwd", "rot-left"])))
    return learner.save(tmp_path / "t.rhbl")


def test_controller_refuses_a_tree_with_other_features(start_server, tmp_path):
    srv = start_server("room", speedup=1)
    r = _run("controller", "--connect", srv.endpoint, "--tree", str(_tree(tmp_path)),
             "--features", "maze")
    assert r.returncode == EXIT_USAGE
    assert "other features" in r.stderr and "beams" in r.stderr


def test_controller_reports_when_scans_stop(start_server, tmp_path):
    from protocol import keys

    srv = start_server("room", speedup=1)
    p = Child("controller", rhbl_argv("controller", "--connect", srv.endpoint, "--tree",
                                      str(_tree(tmp_path))), tmp_path, cwd=ROOT).start()
    try:
        with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
            commands: list[bytes] = []
            sub = session.declare_subscriber(keys.cmd_vel_key("r0", source="controller"),
                                             lambda s: commands.append(s.payload.to_bytes()))
            eventually(lambda: commands, 30, "the controller's first command (it drives)",
                       alive=[p])
            sub.undeclare()
        srv.stop()
        p.wait_for_line("not commanding", 10)
        assert "no scan on rhbl/r0/laser/0/data/scan" in p.output()
        assert p.stop(signal.SIGTERM, 20) == 0  # SIGTERM, then SIGKILL (-9) after 20 s
    finally:
        p.kill()  # nothing if it ended


@contextlib.contextmanager
def _answering_controller(free_port, tmp_path):
    """A real ``rhbl controller`` on a router of this process, answering good scans already:
    yields ``(put, answered, p, until)``: ``put(payload)`` publishes a scan's bytes, ``answered``
    the scan ids of its commands so far, ``p`` the process, ``until(cond, what)`` waits."""
    from protocol import keys
    from protocol.messages import Scan, VelCmd

    ep = f"tcp/127.0.0.1:{free_port()}"
    answered: list[int] = []
    with zenoh.open(make_config(mode="router", listen=[ep])) as session:
        session.declare_subscriber(keys.cmd_vel_key("r0", source="controller"),
                                   lambda s: answered.append(
                                       VelCmd.decode(s.payload.to_bytes()).scan_id))
        pub = session.declare_publisher(keys.scan_key("r0"))
        p = Child("controller", rhbl_argv("controller", "--connect", ep, "--tree",
                                          str(_tree(tmp_path)), "--stats",
                                          str(tmp_path / "controller.json")),
                  tmp_path, cwd=ROOT).start()
        p.stats_file = tmp_path / "controller.json"
        try:
            def until(cond, what):
                eventually(cond, 30, what, alive=[p])

            sid = 0

            def warm_up() -> list[int]:  # the first scans also tell it the server is up
                nonlocal sid
                sid += 1
                pub.put(Scan(ts=0.1 * sid, id=sid, ranges=GOOD).encode())
                return answered

            eventually(warm_up, 30, "a command answering a warm-up scan", every=0.1, alive=[p])
            yield pub.put, answered, p, until
            assert p.stop(signal.SIGTERM, 20) == 0, p.output()  # then SIGKILL (-9) after 20 s
        finally:
            p.kill()  # nothing if it ended


GOOD = np.full(360, 2.0, np.float32)
FIRST = 1000  # the scan ids the tests send after the controller answers (below: warm-up)


def test_controller_survives_a_scan_its_tree_cannot_use(free_port, tmp_path):
    """A well-formed scan with one beam (features need more): no command for it, a warning,
    and the next good scan is answered (before: the controller died)."""
    from protocol.messages import Scan

    with _answering_controller(free_port, tmp_path) as (put, answered, p, until):
        put(Scan(ts=0.1 * FIRST, id=FIRST, ranges=np.ones(1, np.float32)).encode())
        # the controller keeps only the latest scan and answers nothing for this one: its
        # warning is the one sign that it was read before the next is sent
        assert p.wait_for_line("not answered", patience(30)), f"the warning:\n{p.output()}"
        put(Scan(ts=0.1 * (FIRST + 1), id=FIRST + 1, ranges=GOOD).encode())
        until(lambda: FIRST + 1 in answered, "the next scan answered")
        assert FIRST not in answered and p.poll() is None
    assert json.loads(p.stats_file.read_text())["unanswered"] == 1  # counted (--stats)


def test_controller_answers_a_scan_in_any_valid_layout_and_drops_a_malformed_one(free_port,
                                                                                tmp_path):
    """The controller reads a scan laid out as ``Scan.encode`` writes it in place (its hot
    path, ``PayloadReader``); one laid out otherwise (the fields in another order, a float32
    number, a negative fixint version... any valid msgpack) is decoded and answered the same;
    a malformed one (a NaN range, a truncated map) gets no command and the next is answered."""
    import msgpack

    from protocol.messages import Scan

    def scan(sid, ranges=GOOD):
        return Scan(ts=0.1 * sid, id=sid, ranges=ranges)

    with _answering_controller(free_port, tmp_path) as (put, answered, p, until):
        fields = {"v": 1, **scan(FIRST).to_map()}
        put(msgpack.packb(dict(reversed(list(fields.items()))), use_bin_type=True))
        until(lambda: FIRST in answered, "a scan with its fields in another order answered")
        fields = {"v": 1, **scan(FIRST + 1).to_map()}
        put(msgpack.packb(fields, use_bin_type=True, use_single_float=True))
        until(lambda: FIRST + 1 in answered, "a scan of float32 numbers answered")
        # the controller keeps only the latest scan and answers nothing for a malformed one:
        # its warning is the one sign that it was read before the next is sent
        put(scan(FIRST + 2, np.r_[GOOD[:-1], np.nan].astype(np.float32)).encode())
        assert p.wait_for_line("dropped a malformed scan (1 so far)", patience(30)), p.output()
        put(scan(FIRST + 3).encode()[:-5])
        assert p.wait_for_line("dropped a malformed scan (2 so far)", patience(30)), p.output()
        put(scan(FIRST + 4).encode())
        until(lambda: FIRST + 4 in answered, "the next good scan answered")
        assert FIRST + 2 not in answered and FIRST + 3 not in answered and p.poll() is None
    assert json.loads(p.stats_file.read_text())["dropped"] == {"scan": 2}  # counted (--stats)


def test_a_robot_name_that_is_not_a_key_chunk_is_bad_input():
    r = _run("teacher", "--robot", "a/b", "--connect", "tcp/127.0.0.1:1")
    assert r.returncode == EXIT_USAGE, r.stderr
    assert "--robot must be" in r.stderr and "'a/b'" in r.stderr and "Traceback" not in r.stderr


def test_correcting_needs_a_scripted_teacher(free_port):
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[ep])):
        r = _run("teacher", "--connect", ep, "--policy", "keyboard", "--correct")
        assert r.returncode == EXIT_USAGE and "--correct needs a scripted expert" in r.stderr
        r = _run("teacher", "--connect", ep, "--correct", "--takeover", "-1")
        assert r.returncode == EXIT_USAGE and ">= 0" in r.stderr
    assert "Traceback" not in r.stderr


def test_controller_waits_for_a_tree_as_long_as_told(free_port):
    """--wait-tree bounds the wait for the learner's first tree: then the last reason, exit 4
    (without --wait-tree and without --follow: a single query)."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[ep])):
        t = time.monotonic()
        r = _run("controller", "--connect", ep, "--from-learner", "--follow", "--wait-tree", "2")
        waited = time.monotonic() - t
    assert r.returncode == EXIT_NO_SERVER, r.stderr
    assert "waiting for the learner's first tree" in r.stderr
    assert "no learner answered" in r.stderr and "--wait-tree 2 s" in r.stderr
    assert waited >= 2.0 and "Traceback" not in r.stderr


def test_a_learner_waiting_for_the_server_stops_on_sigterm(free_port, tmp_path):
    """SIGTERM ends the (endless) wait for the server at once: exit 0, the journal closed."""
    from protocol import keys

    ep = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[ep])) as session:
        p = Child("learner", rhbl_argv("learner", "--connect", ep, "--features", "wall", "--out",
                                       str(tmp_path / "t.rhbl"), "--wait-server", "0"),
                  tmp_path, cwd=ROOT).start()
        try:
            wait_token(session, keys.alive_key("learner", f"r0-{p.pid}"), alive=[p])
            assert p.stop(signal.SIGTERM, 10) == 0, p.output()  # then SIGKILL (-9) after 10 s
        finally:
            p.kill()  # nothing if it ended
    assert "stopped: 0 labeled vectors" in p.output()
    assert "server is up" not in p.output()
