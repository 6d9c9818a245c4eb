"""Stop signals of every rhbl process (``process.runtime``), with a real process and real
signals: a SIGTERM that lands where code swallows the ``SystemExit`` it raises (a signal during
numpy's first lazy import of ``numpy.random`` was lost that way) is delivered again until the
process stops."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

from lab.children import Child

ROOT = Path(__file__).resolve().parents[2]


def _program(name: str, code: str, tmp_path: Path) -> Child:
    """``code`` run by this Python with the repository importable, started."""
    return Child(name, [sys.executable, "-c", code], tmp_path, cwd=ROOT,
                 env={**os.environ, "PYTHONPATH": str(ROOT)}, escalate=False).start()

# the first SystemExit is swallowed, as library code can; only a second one ends the program
PROGRAM = """
import sys, time
from process.runtime import install_signal_handlers
install_signal_handlers()
try:
    print("ready", flush=True)  # inside: a signal right after it must land in this block
    while True:
        time.sleep(0.01)
except SystemExit:
    print("swallowed", flush=True)
try:
    while True:
        time.sleep(0.01)
except SystemExit:
    print("stopped", flush=True)
    sys.exit(0)
"""


def test_a_swallowed_stop_signal_is_delivered_again(tmp_path):
    p = _program("swallower", PROGRAM, tmp_path)
    try:
        assert p.wait_for_line("ready", 30), p.output()
        p.send_signal(signal.SIGTERM)  # once
        assert p.wait_for_line("swallowed", 10), p.output()
        assert p.wait_for_line("stopped", 10), p.output()
        assert p.wait(10) == 0, p.output()
    finally:
        p.stop(signal.SIGKILL)


import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _own_signal_handlers():
    """run_process installs its stop-signal handlers, then ignores the signals: the test
    process gets its own back."""
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def _args(tmp_path, port: int, **kw):
    import argparse

    return argparse.Namespace(mode="peer", listen=[f"tcp/127.0.0.1:{port}"], connect=None,
                              zenoh_config=None, multicast_scouting=False, namespace=None,
                              log_level="WARNING", **kw)


def test_counters_are_written_at_exit_whatever_the_path(tmp_path, free_port):
    """``--stats FILE``: the counters the body reported, its role and exit code, as JSON; also
    when the body fails (the exit code says so)."""
    import json

    from process.runtime import EXIT_NO_SERVER, ProcessError, run_process

    def body(ctx):
        ctx.report(lambda: {"labels": 7, "dropped": {"scan": 1}})
        return 0

    stats = tmp_path / "ok.json"
    assert run_process("tester", _args(tmp_path, free_port(), stats=str(stats)), body) == 0
    assert json.loads(stats.read_text()) == {"role": "tester", "exit": 0, "labels": 7,
                                             "dropped": {"scan": 1}}

    def failing(ctx):
        ctx.report(lambda: {"labels": 2})
        raise ProcessError("no server", EXIT_NO_SERVER)

    stats = tmp_path / "failed.json"
    assert run_process("tester", _args(tmp_path, free_port(), stats=str(stats)),
                       failing) == EXIT_NO_SERVER
    assert json.loads(stats.read_text()) == {"role": "tester", "exit": EXIT_NO_SERVER,
                                             "labels": 2}


def test_a_stats_file_that_cannot_be_written_is_bad_input_before_any_session(tmp_path):
    from process.runtime import EXIT_USAGE, run_process

    opened = []
    (tmp_path / "file").write_text("")  # its folder cannot be made: a file is in its place
    args = _args(tmp_path, 1, stats=str(tmp_path / "file" / "s.json"))  # port 1: no session
    assert run_process("tester", args, lambda ctx: opened.append(ctx)) == EXIT_USAGE
    assert opened == []
    os.mkfifo(tmp_path / "fifo")  # nor a FIFO (it would block or be replaced)
    args = _args(tmp_path, 1, stats=str(tmp_path / "fifo"))
    assert run_process("tester", args, lambda ctx: opened.append(ctx)) == EXIT_USAGE
    assert opened == [] and (tmp_path / "fifo").is_fifo()


# a stop signal that arrives while ``__del__`` runs (as one can while the import machinery's lock
# callbacks run): raised there, Python would print "Exception ignored in ..." with a traceback
# and swallow it
IN_DEL = """
import signal, time
from process.runtime import install_signal_handlers
install_signal_handlers()

class Finaliser:
    def __del__(self):
        signal.raise_signal(signal.SIGTERM)
        for _ in range(3):  # the handler runs between these bytecodes, inside __del__
            pass

print("ready", flush=True)
try:
    obj = Finaliser()
    del obj
    while True:
        time.sleep(0.01)
except SystemExit:
    print("stopped", flush=True)
    raise
"""


def test_a_stop_signal_in_a_finaliser_stops_without_a_traceback(tmp_path):
    p = _program("finaliser", IN_DEL, tmp_path)
    try:
        assert p.wait_for_line("stopped", 30), p.output()
        assert p.wait(10) == 0, p.output()
        assert "Exception ignored" not in p.output() and "Traceback" not in p.output()
    finally:
        p.stop(signal.SIGKILL)


# a stop signal inside ``uninterrupted()``: every statement of the block runs, then it stops
IN_BLOCK = """
import signal, time
from process.runtime import install_signal_handlers, uninterrupted
install_signal_handlers()
done = 0
try:
    with uninterrupted():
        signal.raise_signal(signal.SIGTERM)  # the handler runs at once, inside the block
        for _ in range(1000):
            done += 1
        print("block ended", done, flush=True)
    while True:
        time.sleep(0.01)
except SystemExit:
    print("stopped after", done, flush=True)
    raise
"""


def test_a_stop_signal_in_an_uninterrupted_block_lands_after_it(tmp_path):
    p = _program("uninterrupted", IN_BLOCK, tmp_path)
    try:
        assert p.wait_for_line("stopped after 1000", 30), p.output()
        assert "block ended 1000" in p.output()
        assert p.wait(10) == 0, p.output()
    finally:
        p.stop(signal.SIGKILL)
