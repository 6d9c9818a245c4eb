"""lab.children: real child processes (small Python scripts), stopped by PID."""

from __future__ import annotations

import signal
import socket
import sys
import time
from pathlib import Path

import pytest
from waiting import eventually, patience

from lab.children import Child, free_port, rhbl_argv, running, stop_all


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


def _state(pid: int) -> str:
    """The process state letter of /proc/<pid>/stat ("T": stopped)."""
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()[0]


# prints "tick N" every 20 ms until stopped
TICKER = """
import itertools, time
for i in itertools.count():
    print("tick", i, flush=True)
    time.sleep(0.02)
"""


def test_pause_resume_and_lines_since_a_mark(tmp_path):
    child = Child("ticker", py(TICKER), tmp_path).start()
    try:
        assert child.started_at is not None and child.started_at <= time.monotonic()
        assert child.wait_for_line("tick 3", timeout=30)
        child.pause()
        assert child.paused
        # the kernel says it is stopped ...
        eventually(lambda: _state(child.pid), 30, "the stopped state (T) of the paused child",
                   until=lambda state: state == "T", every=0.01)
        deadline = time.monotonic() + patience(30)
        mark = child.mark()  # ... and what it printed before has been read: quiet for 0.2 s
        while child.wait_for_line("tick", timeout=0.2, since=mark):
            assert time.monotonic() < deadline
            mark = child.mark()
        assert not child.wait_for_line("tick", timeout=0.5, since=mark)  # frozen
        assert child.wait_for_line("tick 3", timeout=0)  # without since: the old lines count
        child.resume()
        assert not child.paused
        assert child.wait_for_line("tick", timeout=30, since=mark)  # going again
        assert child.rss_kib() > 0
        child.pause()
        # stop() resumes a paused child first, so that SIGTERM can end it
        assert child.stop(timeout=30) == -signal.SIGTERM
    finally:
        child.kill()
    assert child.rss_kib() == -1


def test_rss_kib_of_this_process_and_of_none():
    import os

    from lab.children import rss_kib

    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs /proc")
    assert rss_kib(os.getpid()) > 1000
    assert rss_kib(2**22 + 12345) == -1  # beyond pid_max: no such process


def test_started_again_the_same_command_keeps_counting_lines(tmp_path):
    child = Child("again", py("print('hello', flush=True)"), tmp_path).start()
    assert child.wait(30) == 0
    first = child.started_at
    mark = child.mark()
    child.start()
    assert child.wait(30) == 0 and child.started_at > first
    assert child.wait_for_line("hello", timeout=0, since=mark)
    assert not child.wait_for_line("hello", timeout=0, since=child.mark())


@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid") or __import__("os").geteuid() != 0,
                    reason="for root (any other user is refused by permissions anyway)")
def test_without_file_override_root_is_refused_by_permissions(tmp_path):
    from lab.children import without_file_override

    folder = tmp_path / "ro"
    folder.mkdir(mode=0o555)
    folder.chmod(0o555)
    code = ("import sys\ntry:\n    open(sys.argv[1] + '/x', 'w')\nexcept PermissionError as e:\n"
            "    print('refused', e.errno, flush=True)\nelse:\n    print('written', flush=True)")
    child = Child("root", py(code) + [str(folder)]).start()
    assert child.wait(30) == 0 and "written" in child.output()  # root writes anyway
    (folder / "x").unlink()
    child = Child("dropped", py(code) + [str(folder)], preexec_fn=without_file_override).start()
    assert child.wait(30) == 0 and "refused 13" in child.output(), child.output()
    assert not (folder / "x").exists()


def test_a_child_started_to_die_with_its_parent_ends_when_the_parent_is_killed(tmp_path):
    """A parent (a real process) starts two children that would sleep for a minute, one with
    ``die_with_parent``, then is SIGKILLed: that child ends (SIGTERM), the other runs on."""
    import os

    parent = Child("parent", py(
        "import sys, time\n"
        "from lab.children import Child\n"
        "for die in (True, False):\n"
        "    c = Child('sleeper', [sys.executable, '-c', 'import time; time.sleep(60)'],\n"
        "              die_with_parent=die).start()\n"
        "    print('child', die, c.pid, flush=True)\n"
        "time.sleep(60)\n"), cwd=str(Path(__file__).resolve().parents[2])).start()
    assert parent.wait_for_line("child False", timeout=30), parent.output()
    pids = {x.split()[1]: int(x.split()[2]) for x in parent.lines if x.startswith("child ")}
    try:
        assert running(pids["True"]) and running(pids["False"])
        parent.kill()
        eventually(lambda: not running(pids["True"]), patience(10), "the child ends with its parent")
        assert running(pids["False"])  # no such child: it runs on without its parent
    finally:
        for pid in pids.values():
            if running(pid):
                os.kill(pid, signal.SIGKILL)


def test_stop_all_stops_every_child_and_a_ctrl_c_while_they_stop_kills_the_rest():
    sleeper = [sys.executable, "-c", "import time; time.sleep(120)"]
    calm = [Child(f"calm{k}", sleeper).start() for k in range(2)]
    stop_all(calm)
    assert all(c.poll() is not None for c in calm)

    class Interrupted(Child):
        """Its gentle stop is where the user's second Ctrl-C lands."""

        def stop(self, sig=None, timeout=None):
            if sig != signal.SIGKILL:
                raise KeyboardInterrupt
            return super().stop(sig, timeout)

    first = Interrupted("first", sleeper).start()
    rest = Child("rest", sleeper, stop_timeout=60.0).start()
    with pytest.raises(KeyboardInterrupt):
        stop_all([first, rest])
    assert first.poll() == -signal.SIGKILL and rest.poll() == -signal.SIGKILL
