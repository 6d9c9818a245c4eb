"""The learner's default ``--teacher auto`` with real processes: a real server, a learner started
without ``--teacher``, and a scripted teacher (``rhbl teacher --policy wall-follower``) or a
person at a terminal (``rhbl teacher --policy keyboard`` on a pseudo-terminal, keys typed into
it). The new lineage takes the scripted rule for the first, the person rule for the second; its
journal's header keeps the rule and a restart keeps it. (The console's page: the person rule
too, tests/integration/test_console_teach.py.)"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually, wait_token  # noqa: E402

from client.journal import Journal, journal_path  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def procs(tmp_path):
    started: list[Child] = []

    def start(name, *args, preexec=None):
        p = Child(name, rhbl_argv(*args), tmp_path, cwd=ROOT, stop_signal=signal.SIGINT,
                  stop_timeout=30.0, escalate=False, preexec_fn=preexec).start()
        started.append(p)
        return p

    yield start
    for p in started:
        p.kill()


def _records(out: Path) -> int:
    if not journal_path(out).exists():
        return 0
    with Journal.open(journal_path(out), readonly=True) as j:
        return len(j)


def _wait_records(out: Path, n: int, *procs: Child, timeout: float = 60.0) -> None:
    eventually(lambda: _records(out), timeout, f"{n} records in the journal of {out}",
               until=lambda have: have >= n, alive=procs)


def _up(srv, p: Child) -> None:
    """Until ``p``'s liveliness token is seen (a learner's: it receives labels)."""
    role = p.argv[p.argv.index("lab.cli") + 1]
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        wait_token(session, keys.alive_key(role, f"r0-{p.pid}"), 60, alive=[p])


def _rule(out: Path) -> str | None:
    with Journal.open(journal_path(out), readonly=True) as j:
        return (j.header["meta"].get("learning") or {}).get("rule")


def _learner(procs, srv, out: Path, name: str = "learner"):
    p = procs(name, "learner", "--features", "wall", "--out", str(out), "--snapshot-every",
              "0.3", "--connect", srv.endpoint, "--stats", str(out.with_suffix(".json")))
    _up(srv, p)
    return p


def test_a_scripted_teachers_labels_give_the_scripted_rule(start_server, procs, tmp_path):
    srv = start_server("room")
    out = tmp_path / "script.rhbl"
    learner = _learner(procs, srv, out)
    assert not journal_path(out).exists()  # no lineage before its first label
    teacher = procs("teacher", "teacher", "--policy", "wall-follower", "--seconds", "3",
                    "--connect", srv.endpoint)
    assert teacher.wait(120) == 0, teacher.output()
    _wait_records(out, 5, learner)
    assert learner.stop() == 0, learner.output()
    assert _rule(out) != "person"
    assert json.loads(out.with_suffix(".json").read_text())["rule"] == "script"  # --stats
    assert "the first label came from 'teacher', so it learns by the scripted rule" in \
        learner.output()
    assert "its rule is chosen by the first label" in learner.output()  # it said it waited


def test_a_person_at_the_keyboard_gives_the_person_rule(start_server, procs, tmp_path):
    srv = start_server("room")
    out = tmp_path / "keys.rhbl"
    learner = _learner(procs, srv, out)
    master, slave = os.openpty()
    try:
        teacher = procs("keyboard", "teacher", "--policy", "keyboard", "--connect",
                        srv.endpoint, preexec=lambda: os.dup2(slave, 0))
        # rot-left, held until another key: the robot turns in place. Pressed until the
        # labels come: a key typed before the teacher reads its terminal (cbreak mode flushes
        # what was typed) is lost, and pressing it again changes nothing
        eventually(lambda: os.write(master, b"a") and _records(out), 60,
                   "10 journal records of the held key", until=lambda have: have >= 10,
                   alive=[learner, teacher], every=0.2)
        os.write(master, b" ")  # pause
        os.write(master, b"x")  # quit: the teacher stops as on Ctrl-C
        assert teacher.wait(60) == 0, teacher.output()
    finally:
        os.close(master)
        os.close(slave)
    assert learner.stop() == 0, learner.output()
    assert _rule(out) == "person"
    assert json.loads(out.with_suffix(".json").read_text())["rule"] == "person"
    assert "the first label came from 'keyboard', so it learns by the person rule" in \
        learner.output()
    # a restart keeps the person rule, even when told --teacher script
    stats = out.with_suffix(".again.json")
    again = procs("again", "learner", "--features", "wall", "--teacher", "script", "--out",
                  str(out), "--connect", srv.endpoint, "--stats", str(stats))
    _up(srv, again)  # after its recovery
    assert again.stop() == 0, again.output()
    assert json.loads(stats.read_text())["rule"] == "person"  # --stats
    assert "a person's labels" in again.output(), again.output()
