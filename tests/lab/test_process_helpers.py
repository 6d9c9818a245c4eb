"""lab.processes: real child processes (small Python scripts), stopped by PID."""

from __future__ import annotations

import signal
import socket
import sys
import time

import pytest

from lab.processes import Child, free_port, rhbl_argv


def py(code: str) -> list[str]:
    return [sys.executable, "-c", code]


# prints "ready" once its handlers are in place, then sleeps until a signal it does not ignore
STUBBORN = """
import signal, sys, time
for name in sys.argv[1:]:
    signal.signal(getattr(signal, name), lambda *_: print("ignored", flush=True))
print("ready", flush=True)
while True:
    time.sleep(1)
"""


def test_free_port_is_bindable():
    port = free_port()
    assert 1024 <= port <= 65535
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


def test_rhbl_argv_runs_this_interpreter():
    assert rhbl_argv("server", "--lockstep") == [sys.executable, "-m", "lab.cli", "server",
                                                 "--lockstep"]


def test_lines_log_file_and_exit_status(tmp_path):
    child = Child("talker", py("print('one'); print('two'); raise SystemExit(3)"), tmp_path)
    assert child.pid == -1 and child.poll() is None and child.stop() is None
    child.start()
    assert child.wait_for_line("two", timeout=30)
    assert child.wait(30) == 3 and child.poll() == 3
    assert child.wait_for_line("one", timeout=0)  # printed before: still found
    assert not child.wait_for_line("three", timeout=30)  # ended without it: False at once
    assert list(child.lines) == ["one", "two"]
    assert child.tail(1) == "    two" and child.output() == "one\ntwo"
    log = (tmp_path / "talker.log").read_text().splitlines()
    assert log[0].startswith("$ ") and log[1:] == ["one", "two"]
    # started again: the same log, the lines go on
    child.start()
    assert child.wait(30) == 3 and child.starts == 2
    assert list(child.lines) == ["one", "two", "one", "two"]
    log = (tmp_path / "talker.log").read_text().splitlines()
    assert [ln[:2] for ln in log].count("$ ") == 2 and log.count("two") == 2


def test_wait_for_line_times_out_while_the_child_runs(tmp_path):
    with Child("quiet", [sys.executable, "-c", STUBBORN]) as child:
        assert child.wait_for_line("ready", timeout=30)
        t = time.monotonic()
        assert not child.wait_for_line("never printed", timeout=0.3)
        assert 0.25 <= time.monotonic() - t < 5
        assert child.poll() is None
    assert child.poll() == -signal.SIGTERM and child.expected_stop


def test_stop_escalates_to_sigkill(tmp_path):
    child = Child("stubborn", [sys.executable, "-c", STUBBORN, "SIGINT", "SIGTERM"]).start()
    assert child.wait_for_line("ready", timeout=30)
    assert child.stop(signal.SIGINT, timeout=0.5) == -signal.SIGKILL
    assert child.output().count("ignored") == 2  # SIGINT, then SIGTERM, then SIGKILL


def test_stop_without_escalation_goes_straight_to_sigkill(tmp_path):
    # SIGTERM would end it with 0: without escalation only SIGINT (ignored), then SIGKILL
    code = STUBBORN.replace("import signal, sys, time", "import signal, sys, time\n"
                            "signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))")
    child = Child("strict", py(code) + ["SIGINT"], stop_signal=signal.SIGINT, stop_timeout=0.5,
                  escalate=False).start()
    assert child.wait_for_line("ready", timeout=30)
    assert child.stop() == -signal.SIGKILL
    assert child.output().count("ignored") == 1


def test_kill_and_preexec_fn(tmp_path):
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_NOFILE, (64, 64))

    code = ("import resource; print('limit', resource.getrlimit(resource.RLIMIT_NOFILE)[0],"
            " flush=True)\n" + STUBBORN)
    child = Child("limited", py(code) + ["SIGTERM"], preexec_fn=limit).start()
    assert child.wait_for_line("ready", timeout=30)
    assert "limit 64" in child.output()
    assert child.kill() == -signal.SIGKILL and child.poll() == -signal.SIGKILL
    assert child.kill() == -signal.SIGKILL  # already ended: nothing sent


def test_stop_with_the_given_signal_first(tmp_path):
    code = ("import signal, sys\n"
            "signal.signal(signal.SIGINT, lambda *_: sys.exit(7))\n"
            "print('ready', flush=True)\nsignal.pause()")
    child = Child("polite", py(code)).start()
    assert child.wait_for_line("ready", timeout=30)
    assert child.stop(signal.SIGINT, timeout=30) == 7


def test_bad_command_lines():
    with pytest.raises(ValueError, match="empty command line"):
        Child("nothing", [])
    with pytest.raises(FileNotFoundError):
        Child("missing", ["/nonexistent/program"]).start()
    child = Child("twice", [sys.executable, "-c", STUBBORN]).start()
    try:
        with pytest.raises(RuntimeError, match="still running"):
            child.start()
    finally:
        child.stop()
