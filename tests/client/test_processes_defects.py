"""What a new user tripped on, each held: options checked before any connection, a recorder that
needs no server, the real default endpoint said, the log's last lines in order, counters as
data (``--stats``)."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually  # noqa: E402

from client.recording.mcap_file import RecordingError, read_recording  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from process import runtime  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]
ROOT = Path(__file__).resolve().parents[2]


def _run(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "lab.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_arguments_are_checked_before_any_connection(tmp_path, free_port):
    """Nothing listens on the endpoint: a bad argument is still one line, exit 2, naming it
    (record checked --out only after opening zenoh and said "connection refused", exit 3;
    replay said a zenoh error, exit 3, for a file that is no recording)."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    (tmp_path / "run.mcap").write_bytes(b"")
    (tmp_path / "tree.rhbl").write_bytes(b"\x82\xa1v\x01")
    for args, needle in [
        (("record", "--out", str(tmp_path / "run.mcap")), "exists: choose another file"),
        (("record", "--out", str(tmp_path)), "is a folder"),
        (("record", "--out", str(tmp_path / "x.mcap"), "--duration", "0"), "--duration"),
        (("replay", str(tmp_path / "tree.rhbl")), "tree.rhbl is not an MCAP recording"),
        (("replay", str(tmp_path / "none.mcap")), "none.mcap does not exist"),
        (("foxglove", "--port", "70000"), "--port must be an integer >= 0 and <= 65535"),
        (("controller", "--tree", str(tmp_path / "tree.rhbl"), "--stats",
          str(tmp_path / "run.mcap" / "s.json")), "--stats"),
    ]:
        r = _run(*args, "--connect", ep)
        assert r.returncode == 2, (args, r.stderr)
        assert needle in r.stderr and "connection refused" not in r.stderr, (args, r.stderr)


def test_the_help_says_the_real_default_endpoint():
    text = " ".join(_run("teacher", "--help").stdout.split())
    connect = text[text.index("endpoint to connect to"):text.index("endpoint to listen on")]
    assert "default: tcp/127.0.0.1:7447 in client mode" in connect, connect
    assert "none)" not in connect  # it said "(repeatable; default: none)"


def test_a_port_held_by_another_program_is_named_with_the_default(free_port):
    port = free_port()
    with socket.socket() as s:  # not a zenoh router
        s.bind(("127.0.0.1", port))
        s.listen()
        ep = f"tcp/127.0.0.1:{port}"
        (said,) = runtime._diagnose([ep], [], default=True)
    assert said.startswith(f"{ep} (the default endpoint: no --connect given): something listens")
    assert "another program holding that port" in said


def test_record_waits_for_a_router_and_its_last_lines_come_in_order(tmp_path, free_port,
                                                                   start_server):
    """``rhbl record`` needs no server up: it waits for one, then records (it exited 3 with
    "connection refused"); stopped, it says "stopping (signal)" before its last line (which
    it printed after it), and its counters are in --stats."""
    port = free_port()
    stats = tmp_path / "rec.json"
    rec = Child("recorder", rhbl_argv("record", "--out", str(tmp_path / "r.mcap"), "--connect",
                                      f"tcp/127.0.0.1:{port}", "--stats", str(stats)),
                tmp_path, cwd=ROOT, stop_signal=signal.SIGINT, escalate=False).start()
    try:
        assert rec.wait_for_line("waiting for a router", 30), rec.output()
        assert rec.poll() is None
        start_server("corridor", speedup=1, port=port)
        # recording: a message in the file (a chunk a second; not even its header at first)
        out = tmp_path / "r.mcap"
        eventually(lambda: out.exists() and next(iter(read_recording(out)), None), 30,
                   f"a message recorded in {out}", ignore=(RecordingError,), alive=[rec])
        assert rec.stop(timeout=30) == 0, rec.output()
    finally:
        rec.kill()
    text = rec.output()
    assert text.index("recorder stopping (signal)") < text.index("recorder stopped:"), text
    got = json.loads(stats.read_text())
    assert got["role"] == "recorder" and got["exit"] == 0 and got["messages"] > 0, got


def _tree(tmp_path) -> Path:
    import numpy as np

    from client.behaviour.features import FEATURES
    from client.behaviour.learning import DemonstrationLearner

    learner = DemonstrationLearner(FEATURES["wall"], task="wall-following", spawn="winner")
    learner.observe(np.full(360, 2.0, np.float32), 0.0, "fwd")
    return learner.save(tmp_path / "fwd.rhbl")


def test_a_stopped_controller_says_stopping_before_its_count_and_writes_it(tmp_path,
                                                                           start_server):
    srv = start_server("room", lockstep=True)
    stats = tmp_path / "ctl.json"
    c = Child("controller", rhbl_argv("controller", "--tree", str(_tree(tmp_path)), "--connect",
                                      srv.endpoint, "--stats", str(stats)),
              tmp_path, cwd=ROOT, stop_signal=signal.SIGINT, escalate=False).start()
    try:
        with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
            commands: list[bytes] = []
            sub = session.declare_subscriber(keys.cmd_vel_key("r0", source="controller"),
                                             lambda s: commands.append(s.payload.to_bytes()))
            eventually(lambda: len(commands), 60, "1000 commands of the controller",
                       until=lambda n: n >= 1000, alive=[c])
            sub.undeclare()
        assert c.stop(timeout=30) == 0, c.output()
    finally:
        c.kill()
    text = c.output()
    assert text.index("controller stopping (signal)") < text.index("controller stopped after")
    got = json.loads(stats.read_text())
    assert got["exit"] == 0 and got["commands"] >= 1000 and got["unanswered"] == 0, got
    assert f"controller stopped after {got['commands']} commands" in text


def test_a_lockstep_teacher_starts_without_saying_scans_stopped(tmp_path, start_server):
    """It skipped the scan the server waited on (before the learner subscribed), so the
    server stepped only after its timeout and the teacher warned "no scan for 1.1 s"."""
    srv = start_server("room", lockstep=True)
    learner = Child("learner", rhbl_argv("learner", "--features", "wall", "--out",
                                         str(tmp_path / "t.rhbl"), "--connect", srv.endpoint),
                    tmp_path, cwd=ROOT, stop_signal=signal.SIGINT, escalate=False).start()
    try:
        t = Child("teacher", rhbl_argv("teacher", "--seconds", "5", "--connect", srv.endpoint,
                                       "--stats", str(tmp_path / "t.json")),
                  tmp_path, cwd=ROOT).start()
        assert t.wait(120) == 0, t.output()
        assert learner.stop(timeout=30) == 0, learner.output()
    finally:
        learner.kill()
    assert "no scan on" not in t.output(), t.output()
    assert json.loads((tmp_path / "t.json").read_text())["labels"] >= 50
