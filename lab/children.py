"""Child processes, one way for everyone: ``rhbl demo``, ``docker/compose_local.py``, the tests
and the benchmarks start, watch and stop their processes with these helpers.

    child = Child("server", rhbl_argv("server", "--listen", f"tcp/127.0.0.1:{free_port()}"),
                  logdir=Path("logs")).start()
    if not child.wait_for_line("listening on", timeout=30):
        raise RuntimeError(f"the server did not start:\\n{child.tail()}")
    ...
    child.stop(signal.SIGINT)     # by PID; SIGTERM, then SIGKILL if it does not end in time

For fault campaigns: :meth:`Child.pause` and :meth:`Child.resume` (SIGSTOP, SIGCONT),
:meth:`Child.kill` (SIGKILL), :meth:`Child.start` again (the same command, the same log),
:attr:`Child.started_at` (when it last started), :meth:`Child.mark` with ``since=`` (only the
lines printed after a moment), :meth:`Child.rss_kib` (resident memory) and
:func:`without_file_override` (a ``preexec_fn``: a child of root refused by file permissions as
any other user is).

A child runs in its own session (``start_new_session``: a Ctrl-C in the terminal reaches only
the parent, which stops its children itself). A thread reads its merged stdout and stderr line
by line: into ``lines`` (the last ``keep``), into ``logdir/<name>.log`` when a folder is given,
and wakes whoever waits for a line or for the exit, so nobody polls.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import itertools
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

__all__ = ["Child", "free_port", "rhbl_argv", "rss_kib", "running", "stop_all",
           "without_file_override"]

log = logging.getLogger(__name__)


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that was free a moment ago (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def rss_kib(pid: int) -> int:
    """Resident memory of process ``pid`` in KiB (VmRSS of /proc/<pid>/status); -1 when it is
    gone or unknown (no /proc, a kernel thread)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return -1


def running(pid: int) -> bool:
    """Process ``pid`` runs: it is there and not a zombie waiting to be reaped (Linux's /proc;
    elsewhere, whether the kernel knows it)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True


# loaded here, in the parent: a preexec_fn runs between fork and exec, no place to load a library
try:
    _LIBC = ctypes.CDLL(None, use_errno=True)
except OSError:  # pragma: no cover - no C library to ask (not Linux)
    _LIBC = None
_PR_CAPBSET_DROP = 24
_PR_SET_PDEATHSIG = 1
# CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER (linux/capability.h)
_FILE_OVERRIDES = (1, 2, 3)


def without_file_override() -> None:
    """A ``preexec_fn`` (Linux): drop the capabilities that let root read, write and chmod
    files regardless of their permissions from the child's bounding set, so the command it runs
    has none of them (a folder of mode 0555 refuses its writes with EACCES, as for any user).
    Needs CAP_SETPCAP (root has it); raises OSError where it cannot."""
    if _LIBC is None:
        raise OSError("cannot drop capabilities here (no C library)")
    for cap in _FILE_OVERRIDES:
        if _LIBC.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"prctl(PR_CAPBSET_DROP, {cap}): {os.strerror(err)}")


def _dying_with(parent: int, then: Callable[[], None] | None) -> Callable[[], None]:
    """A ``preexec_fn`` (Linux): the child gets SIGTERM when the thread that started it ends
    (``PR_SET_PDEATHSIG``), at once if ``parent`` already ended; then ``then``."""
    def preexec() -> None:
        if _LIBC is not None:
            _LIBC.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent:  # the parent died before the line above
            os.kill(os.getpid(), signal.SIGTERM)
        if then is not None:
            then()
    return preexec


def stop_all(children: Sequence[Child]) -> None:
    """Stop each child by PID, in the order given (``Child.stop``: its stop signal, then
    SIGTERM and SIGKILL); one that fails to stop does not keep the rest running. A Ctrl-C while
    they stop (the second of an impatient user) kills the rest at once, then goes on: no child
    is left running."""
    pending = list(children)
    try:
        while pending:
            with contextlib.suppress(Exception):
                pending[0].stop()
            pending.pop(0)
    except KeyboardInterrupt:
        for c in pending:
            with contextlib.suppress(Exception):
                c.kill()
        raise


def rhbl_argv(*args: str) -> list[str]:
    """The command line of ``rhbl ARGS...`` run by this interpreter (no PATH lookup)."""
    return [sys.executable, "-m", "lab.cli", *args]


class Child:
    """One child process: started by :meth:`start`, stopped by PID by :meth:`stop`.

    ``name`` names it in messages and its log file (``logdir/<name>.log``, appended to: a child
    started again keeps one log). ``env`` replaces the environment (default: this process's);
    ``PYTHONUNBUFFERED=1`` is added so Python children's lines arrive as they are printed.
    ``stop_signal`` is what :meth:`stop` sends first (SIGINT for a process that saves its work
    on Ctrl-C) and ``stop_timeout`` how long it waits for each signal. ``escalate=False`` makes
    :meth:`stop` go from that signal straight to SIGKILL (no SIGTERM in between), so an exit
    status of 0 means the first signal alone ended the process (for tests of how it stops).
    ``preexec_fn`` runs in the child before the command (e.g. to set a resource limit).
    ``die_with_parent``: the child gets SIGTERM when this process dies, even by SIGKILL (Linux;
    start it from a thread that lives as long as this process, the main thread): a parent that
    cannot stop its children itself leaves none running.
    """

    def __init__(self, name: str, argv: Sequence[str], logdir: Path | None = None, *,
                 env: Mapping[str, str] | None = None, cwd: str | Path | None = None,
                 stop_signal: int = signal.SIGTERM, stop_timeout: float = 10.0,
                 escalate: bool = True, preexec_fn: Callable[[], None] | None = None,
                 keep: int = 10_000, die_with_parent: bool = False) -> None:
        if not argv:
            raise ValueError(f"{name}: empty command line")
        self.name = name
        self.argv = [str(a) for a in argv]
        self.logfile: Path | None = Path(logdir) / f"{name}.log" if logdir is not None else None
        self.env = dict(os.environ if env is None else env)
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        self.cwd = cwd
        self.stop_signal = stop_signal
        self.stop_timeout = stop_timeout
        self.escalate = escalate
        self.preexec_fn = preexec_fn
        self.die_with_parent = die_with_parent
        self.lines: collections.deque[str] = collections.deque(maxlen=keep)
        self.proc: subprocess.Popen | None = None
        self.rc: int | None = None
        self.expected_stop = False  # stop() was called: an exit from now on is no surprise
        self.starts = 0
        self.started_at: float | None = None  # time.monotonic() of the last start
        self.paused = False  # SIGSTOPped by pause(), not resumed yet
        self._changed = threading.Condition()  # a line arrived or the output ended
        self._count = 0  # lines read since the first start
        self._eof = True
        self._reader: threading.Thread | None = None

    # ---- starting ---------------------------------------------------------------------------
    def start(self) -> Child:
        """Start the process (again, if it ended: the same log, ``lines`` go on)."""
        if self.proc is not None and self.poll() is None:
            raise RuntimeError(f"{self.name} (pid {self.pid}) is still running")
        logf = None
        if self.logfile is not None:
            self.logfile.parent.mkdir(parents=True, exist_ok=True)
            logf = open(self.logfile, "a", encoding="utf-8", errors="replace")  # noqa: SIM115
            logf.write(f"$ {' '.join(self.argv)}\n")
            logf.flush()
        try:
            proc = subprocess.Popen(
                self.argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, env=self.env, cwd=self.cwd, start_new_session=True,
                preexec_fn=(_dying_with(os.getpid(), self.preexec_fn) if self.die_with_parent
                            else self.preexec_fn), text=True, encoding="utf-8", errors="replace", bufsize=1)
        except OSError:
            if logf is not None:
                logf.close()
            raise
        with self._changed:
            self.proc, self.rc, self.expected_stop, self._eof = proc, None, False, False
            self.starts += 1
            self.started_at, self.paused = time.monotonic(), False
        self._reader = threading.Thread(target=self._read, args=(proc, logf),
                                        name=f"child-{self.name}", daemon=True)
        self._reader.start()
        return self

    def _read(self, proc: subprocess.Popen, logf) -> None:
        assert proc.stdout is not None
        try:
            for raw in proc.stdout:
                line = raw.rstrip("\n")
                if logf is not None:
                    logf.write(raw)
                    logf.flush()
                with self._changed:
                    self.lines.append(line)
                    self._count += 1
                    self._changed.notify_all()
        finally:
            proc.stdout.close()
            if logf is not None:
                logf.close()
            with self._changed:
                if self.proc is proc:
                    self._eof = True
                self._changed.notify_all()

    # ---- watching ---------------------------------------------------------------------------
    @property
    def pid(self) -> int:
        return self.proc.pid if self.proc is not None else -1

    def poll(self) -> int | None:
        """The exit status once the process ended, else None."""
        if self.proc is not None and self.rc is None:
            self.rc = self.proc.poll()
        return self.rc

    def wait(self, timeout: float | None = None) -> int | None:
        """Wait up to ``timeout`` seconds for the exit; its status, or None if still running.
        Once it returned a status, ``lines`` hold everything the process printed."""
        if self.proc is None:
            return None
        try:
            self.rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None
        if self._reader is not None:  # its last lines, unless a grandchild holds the pipe open
            self._reader.join(2.0)
        return self.rc

    def mark(self) -> int:
        """How many lines were read so far (since the first start): pass it as ``since`` to
        look only at the lines printed after this moment."""
        with self._changed:
            return self._count

    def wait_for_line(self, text: str, timeout: float = 10.0, since: int = 0) -> bool:
        """True as soon as a line containing ``text`` was printed (now or before: among the
        lines kept, after the :meth:`mark` ``since``); False after ``timeout`` seconds, or once
        the output ended without it."""
        deadline = time.monotonic() + timeout
        with self._changed:
            # lines older than the kept ones are gone
            checked = max(since, self._count - len(self.lines))
            while True:
                new = min(self._count - checked, len(self.lines))
                if new and any(text in ln for ln in itertools.islice(
                        self.lines, len(self.lines) - new, None)):
                    return True
                checked = self._count
                left = deadline - time.monotonic()
                if self._eof or left <= 0:
                    return False
                self._changed.wait(left)

    def rss_kib(self) -> int:
        """Its resident memory in KiB (:func:`rss_kib`); -1 when not running."""
        return rss_kib(self.proc.pid) if self.proc is not None and self.poll() is None else -1

    def output(self) -> str:
        """Every line kept, joined."""
        with self._changed:
            return "\n".join(self.lines)

    def tail(self, n: int = 15, indent: str = "    ") -> str:
        """The last ``n`` lines, indented (for error messages)."""
        with self._changed:
            lines = list(self.lines)[-n:]
        return "\n".join(indent + ln for ln in lines)

    # ---- stopping ---------------------------------------------------------------------------
    def send_signal(self, sig: int) -> None:
        """Send ``sig`` to the PID (nothing if it already ended); marks the stop as expected."""
        if self.proc is None or self.poll() is not None:
            return
        self.expected_stop = True
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.proc.pid, sig)

    def pause(self) -> None:
        """SIGSTOP by PID (nothing if it already ended): it stays, frozen, until :meth:`resume`."""
        if self.proc is not None and self.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGSTOP)
            self.paused = True

    def resume(self) -> None:
        """SIGCONT by PID after :meth:`pause` (nothing if it already ended)."""
        if self.proc is not None and self.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGCONT)
        self.paused = False

    def stop(self, sig: int | None = None, timeout: float | None = None) -> int | None:
        """Send ``sig`` (default ``stop_signal``) by PID and wait ``timeout`` seconds (default
        ``stop_timeout``); then SIGTERM (if ``sig`` was gentler and ``escalate``) and SIGKILL,
        each with its own wait (a paused child is resumed first, so that it can end).
        Returns the exit status (None if never started)."""
        if self.proc is None:
            return None
        if self.paused and sig != signal.SIGKILL:
            self.resume()
        sig = self.stop_signal if sig is None else sig
        timeout = self.stop_timeout if timeout is None else timeout
        later = (signal.SIGTERM, signal.SIGKILL) if self.escalate else (signal.SIGKILL,)
        steps = [sig] + [s for s in later if s != sig]
        if sig == signal.SIGKILL:
            steps = [sig]
        for i, s in enumerate(steps):
            if self.poll() is not None:
                break
            if i:
                log.warning("%s (pid %d) did not end after %s: sending %s", self.name, self.pid,
                            signal.Signals(steps[i - 1]).name, signal.Signals(s).name)
            self.send_signal(s)
            self.wait(timeout if s != signal.SIGKILL else max(timeout, 5.0))
        return self.poll()

    def kill(self) -> int | None:
        """SIGKILL by PID and wait for the exit (nothing if it already ended); its status."""
        return self.stop(signal.SIGKILL)

    def __enter__(self) -> Child:
        return self.start() if self.proc is None else self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"Child({self.name!r}, pid={self.pid}, rc={self.rc})"
