"""Shared fixtures: free ports, a real ``rhbl server`` process on loopback, zenoh client configs.

def test_something(start_server, client_config):
    srv = start_server("corridor", "--lockstep")      # world, then any extra CLI flags
    with zenoh.open(client_config(srv.endpoint)) as session:
        ...
    srv.stop()              # optional: SIGTERM by PID (teardown does it anyway)
    assert "stopped after" in srv.output()
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def find_free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def free_port() -> Callable[[], int]:
    """A function returning a free loopback TCP port."""
    return find_free_port


class ServerProcess:
    """A running ``rhbl server`` (stdout and stderr merged into ``lines``)."""

    def __init__(self, args: list[str], endpoint: str) -> None:
        self.args = args
        self.endpoint = endpoint
        self.lines: list[str] = []
        self._ready = threading.Event()
        self.proc = subprocess.Popen(
            args,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            cwd=ROOT,
            start_new_session=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
            if "listening on" in line:
                self._ready.set()
        self._ready.set()  # EOF: the process ended

    @property
    def pid(self) -> int:
        return self.proc.pid

    def wait_ready(self, timeout: float = 30.0) -> None:
        if not self._ready.wait(timeout) or self.proc.poll() is not None:
            self.stop()
            raise RuntimeError(
                f"rhbl server did not start (exit {self.proc.poll()}):\n" + self.output()
            )

    def output(self) -> str:
        return "\n".join(self.lines)

    def wait_for_line(self, text: str, timeout: float = 10.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any(text in ln for ln in self.lines):
                return True
            time.sleep(0.05)
        return False

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 10.0) -> int | None:
        """Send ``sig`` to the server's PID and wait; SIGKILL if it does not end in time."""
        if self.proc.poll() is None:
            try:
                os.kill(self.proc.pid, sig)
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.kill(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
            except ProcessLookupError:
                pass
        self._reader.join(2.0)
        return self.proc.returncode


def _server_factory(started: list[ServerProcess]):
    def start(
        world: str = "corridor",
        *extra: str,
        speedup: float | None = None,
        lockstep: bool = False,
        robots: int | None = None,
        port: int | None = None,
        ready_timeout: float = 30.0,
    ) -> ServerProcess:
        endpoint = f"tcp/127.0.0.1:{port or find_free_port()}"
        args = [sys.executable, "-m", "lab.cli", "server", "--world", world, "--listen", endpoint]
        if speedup is not None:
            args += ["--speedup", str(speedup)]
        if lockstep:
            args.append("--lockstep")
        if robots is not None:
            args += ["--robots", str(robots)]
        args += list(extra)
        srv = ServerProcess(args, endpoint)
        started.append(srv)
        srv.wait_ready(ready_timeout)
        return srv

    return start


@pytest.fixture
def start_server():
    """Factory: ``start_server(world="corridor", *extra_args, speedup=None, lockstep=False,
    robots=None, port=None) -> ServerProcess`` listening on ``tcp/127.0.0.1:<free port>``.
    Every server started is stopped by PID (SIGTERM, then SIGKILL) at teardown."""
    started: list[ServerProcess] = []
    yield _server_factory(started)
    for srv in started:
        srv.stop()


@pytest.fixture(scope="module")
def start_module_server():
    """Like ``start_server`` but the servers live until the end of the test module (share one
    server between the tests of a module)."""
    started: list[ServerProcess] = []
    yield _server_factory(started)
    for srv in started:
        srv.stop()


@pytest.fixture
def client_config():
    """Function ``client_config(endpoint) -> zenoh.Config``: a client-mode session connected to
    ``endpoint``, multicast scouting off."""
    from protocol.session import make_config

    def make(endpoint: str, mode: str = "client"):
        return make_config(mode=mode, connect=[endpoint])

    return make
