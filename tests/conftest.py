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
import re
import socket
import sys
from collections.abc import Callable

import pytest
from waiting import PATIENCE, Timeout, eventually

from lab.children import Child
from lab.children import free_port as find_free_port

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTS = os.path.join(ROOT, "tests")

# The fast tier, ``make check`` (``pytest -m "not slow"``), leaves out every test marked slow:
# those so marked in their module, and every test of these folders and modules (a whole
# system of processes, a browser, containers, a campaign: seconds to minutes each), so that the
# edit-test loop keeps the unit tests and the quick integration tests (one real server or
# process, a few seconds) and ends within 3 minutes on a busy 2-core machine
SLOW_FOLDERS = ("integration", "fuzz")
SLOW_MODULES = ("benchmarks/test_bench_latency.py",)


def pytest_collection_modifyitems(config, items) -> None:
    """Marks slow every test of ``SLOW_FOLDERS`` and ``SLOW_MODULES`` and runs them first; with
    ``$RHBL_TEST_PATIENCE`` above 1, stretches each test's timeout (pytest-timeout's marker or
    the ini's) as every wait's deadline is."""
    default = float(config.getini("timeout") or 0)
    for item in items:
        rel = os.path.relpath(str(item.path), TESTS).replace(os.sep, "/")
        if rel.split("/", 1)[0] in SLOW_FOLDERS or rel in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
        if PATIENCE > 1:
            marker = item.get_closest_marker("timeout")
            seconds = float(marker.args[0]) if marker is not None and marker.args else default
            if seconds > 0:
                item.add_marker(pytest.mark.timeout(seconds * PATIENCE), append=False)
    # the slow files first (a stable sort: each file's tests stay together and in order), so
    # that the workers of ``-n N --dist loadfile`` do not end on one long file while the others
    # wait: the whole suite ends sooner
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture
def free_port() -> Callable[[], int]:
    """A function returning a free loopback TCP port."""
    return find_free_port


class ServerProcess(Child):
    """A running ``rhbl server`` (a ``lab.children.Child``: stdout and stderr in ``lines``)."""

    def __init__(self, args: list[str], endpoint: str) -> None:
        super().__init__("rhbl server", args, cwd=ROOT)
        self.args = args
        self.endpoint = endpoint
        self.start()

    def ident(self) -> str:
        """Its id in its liveliness tokens: ``--ident``, else ``<host>-<pid>`` (the server's
        default, ``server.node.default_ident``)."""
        if "--ident" in self.args:
            return self.args[self.args.index("--ident") + 1]
        host = re.sub(r"[^A-Za-z0-9_.\-]", "-", socket.gethostname()) or "host"
        return f"{host}-{self.pid}"

    def wait_ready(self, timeout: float = 30.0) -> None:
        """Until its liveliness token ``rhbl/alive/server/<ident>/<robot>`` is seen on its
        endpoint (declared once its subscribers and queryables are: it serves); stops it and
        raises if it ends or takes too long."""
        import zenoh

        from process.session import make_config
        from protocol import keys

        prefix = keys.alive_key("server", self.ident()) + "/"
        config = make_config(mode="client", connect=[self.endpoint])
        try:
            # refused until it listens
            with eventually(lambda: zenoh.open(config), timeout, f"{self.endpoint} listening",
                            ignore=(zenoh.ZError,), alive=[self], every=0.02) as session:
                eventually(lambda: [str(r.ok.key_expr) for r in session.liveliness().get(
                    prefix + "*", timeout=1.0) if r.ok is not None], timeout,
                    f"the server's token {prefix}<robot>", alive=[self], every=0.02)
        except Timeout as exc:
            self.stop()
            raise RuntimeError(f"rhbl server did not start (exit {self.poll()}): {exc}") from None


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
    from process.session import make_config

    def make(endpoint: str, mode: str = "client"):
        return make_config(mode=mode, connect=[endpoint])

    return make
