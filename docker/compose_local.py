"""Run docker/compose.yaml's scenario as local processes, without a Docker engine.

Reads the compose file itself and runs every service's command as it stands: ``rhbl ...`` for
the rhbl services, the secrets generator for ``secrets``, and for the router image a Python
zenoh session in router mode (docker/router_standin.py) on the same config file. Container
paths and hostnames are mapped to the local machine: ``/run/secrets/`` -> a secrets directory,
``/data/`` -> a data directory, ``tls/router:7447`` -> ``tls/127.0.0.1:PORT``. Services start
in ``depends_on`` order and are restarted as their ``restart`` policy says.

    python docker/compose_local.py --workdir /tmp/rhbl-compose       # Ctrl-C stops it all

``tests/integration/test_compose_local.py`` drives it.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from lab import children

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
COMPOSE_FILE = HERE / "compose.yaml"
ROUTER_HOST = "router"
ROUTER_PORT = 7447

__all__ = [
    "Scenario", "client_config", "interpolate", "load_compose", "rhbl_argv", "start_order"
]

_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?:(:?-)([^}]*))?\}")


def interpolate(value, env: dict[str, str]):
    """Compose-style ``${VAR}``, ``${VAR:-default}``, ``${VAR-default}`` in every string."""
    if isinstance(value, str):

        def sub(m):
            name, op, default = m.group(1), m.group(2), m.group(3) or ""
            if op == ":-":
                return env.get(name) or default
            if op == "-":
                return env.get(name, default)
            return env.get(name, "")

        return _VAR.sub(sub, value)
    if isinstance(value, list):
        return [interpolate(v, env) for v in value]
    if isinstance(value, dict):
        return {k: interpolate(v, env) for k, v in value.items()}
    return value


def load_compose(path: Path = COMPOSE_FILE, env: dict[str, str] | None = None) -> dict:
    """The compose file, YAML anchors merged and variables interpolated from ``env``."""
    with open(path) as f:
        data = yaml.safe_load(f)
    return interpolate(data, dict(os.environ) if env is None else env)


def rhbl_argv(service: dict) -> list[str] | None:
    """The ``rhbl`` arguments of a service built from our image (None for other services)."""
    build = service.get("build") or {}
    if build.get("dockerfile") != "docker/Dockerfile" or "entrypoint" in service:
        return None
    command = service.get("command", [])
    return list(command) if isinstance(command, list) else command.split()


def start_order(services: dict) -> list[str]:
    """Service names, each after everything it depends on."""
    order: list[str] = []

    def visit(name, stack=()):
        if name in order:
            return
        if name in stack:
            raise ValueError(f"depends_on cycle: {' -> '.join((*stack, name))}")
        deps = services[name].get("depends_on", {})
        for dep in deps if isinstance(deps, list) else deps.keys():
            visit(dep, (*stack, name))
        order.append(name)

    for name in services:
        visit(name)
    return order


def client_config(config, endpoint: str, retry_ms: int | None = None):
    """``config`` (a ``zenoh.Config``, e.g. a role's credentials) made a client of the router at
    ``endpoint`` only, multicast scouting off; ``retry_ms``: try to reconnect that often after
    losing the router (default: zenoh's backoff)."""
    import json

    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    if retry_ms is not None:
        config.insert_json5("connect/retry", json.dumps(
            {"period_init_ms": retry_ms, "period_max_ms": retry_ms,
             "period_increase_factor": 1}))
    return config


@dataclass
class Proc:
    """A service: its process (started again as its ``restart`` policy says) and exit codes."""

    name: str
    restart: str
    child: children.Child
    exits: list[int] = field(default_factory=list)

    @property
    def log(self) -> Path:
        return self.child.logfile


class Scenario:
    """The compose scenario as local processes (a context manager: stops everything on exit)."""

    def __init__(
        self,
        workdir: Path,
        port: int,
        env: dict[str, str] | None = None,
        compose_file: Path = COMPOSE_FILE,
    ):
        self.workdir = Path(workdir)
        self.port = port
        self.env = dict(os.environ if env is None else env)
        self.compose = load_compose(compose_file, self.env)
        self.services: dict = self.compose["services"]
        self.secrets = self.workdir / "secrets"
        self.data = self.workdir / "data"
        self.logs = self.workdir / "logs"
        self.procs: dict[str, Proc] = {}

    # ---- mapping container paths and names to this machine ---------------------------------
    def localize(self, arg: str) -> str:
        arg = arg.replace(f"tls/{ROUTER_HOST}:{ROUTER_PORT}", f"tls/127.0.0.1:{self.port}")
        if arg.startswith("0.0.0.0:"):  # a container's published port: here loopback, any port
            arg = "127.0.0.1:0"
        for inside, here in (("/run/secrets", self.secrets), ("/data", self.data)):
            if arg == inside or arg.startswith(inside + "/"):
                arg = str(here) + arg[len(inside) :]
        return arg

    def _router_argv(self, service: dict) -> list[str]:
        cmd = list(service.get("command", []))
        mounts = {}
        for vol in service.get("volumes", []):
            src, dst = vol.split(":")[:2]
            mounts[dst] = src
        argv = [
            sys.executable,
            str(HERE / "router_standin.py"),
            "--secrets",
            str(self.secrets),
            "--listen",
            f"tls/127.0.0.1:{self.port}",
        ]
        i = 0
        while i < len(cmd):
            if cmd[i] in ("-c", "--config"):
                argv += ["--config", str((HERE / mounts.get(cmd[i + 1], cmd[i + 1])).resolve())]
                i += 2
            elif cmd[i] == "--cfg":
                argv += ["--cfg", cmd[i + 1]]
                i += 2
            else:
                raise ValueError(f"router: cannot map argument {cmd[i]!r}")
        return argv

    def argv_of(self, name: str) -> list[str]:
        service = self.services[name]
        if name == ROUTER_HOST:  # the router service, reached by its name
            return self._router_argv(service)
        if service.get("entrypoint") == ["rhbl-gen-dev-secrets"]:
            return [
                "bash",
                str(ROOT / "scripts" / "gen-dev-secrets.sh"),
                *[self.localize(a) for a in service.get("command", [])],
            ]
        argv = rhbl_argv(service)
        if argv is None:
            raise ValueError(f"service {name}: do not know how to run it locally")
        return children.rhbl_argv(*[self.localize(a) for a in argv])

    # ---- running ----------------------------------------------------------------------------
    def _child(self, name: str) -> children.Child:
        service = self.services[name]
        env = dict(self.env)
        env.update({k: str(v) for k, v in (service.get("environment") or {}).items()})
        env["SECRETS_PREFIX"] = str(self.secrets)  # the generated configs point here
        env["RUST_LOG"] = env.get("RUST_LOG", "warn")
        return children.Child(name, self.argv_of(name), self.logs, env=env, cwd=self.data)

    def start(self, wait_completed: float = 60.0) -> Scenario:
        for d in (self.secrets, self.data, self.logs):
            d.mkdir(parents=True, exist_ok=True)
        for name in start_order(self.services):
            deps = self.services[name].get("depends_on", {})
            for dep, cond in deps.items() if isinstance(deps, dict) else []:
                if cond.get("condition") == "service_completed_successfully":
                    self._wait_completed(dep, wait_completed)
            proc = Proc(name, str(self.services[name].get("restart", "no")), self._child(name))
            self.procs[name] = proc
            proc.child.start()
            if name == "router":
                self._wait_router(10.0)
        return self

    def _wait_completed(self, name: str, timeout: float) -> None:
        child = self.procs[name].child
        code = child.wait(timeout)
        if code != 0:
            why = "did not finish in time" if code is None else f"exited {code}"
            raise RuntimeError(f"{name} {why}:\n{child.tail(30)}")

    def _wait_router(self, timeout: float) -> None:
        """Until the router stand-in says it listens (it prints that once its session is open)."""
        child = self.procs["router"].child
        if not child.wait_for_line("listening on", timeout):
            raise RuntimeError(f"router did not listen:\n{child.tail(30)}")

    def poll(self, restart_delay: float = 1.0) -> None:
        """Restart exited services as their ``restart`` policy says (call it periodically)."""
        for proc in self.procs.values():
            code = proc.child.poll()
            if code is None or len(proc.exits) >= proc.child.starts:
                continue
            proc.exits.append(code)
            again = proc.restart in ("always", "unless-stopped") or (
                proc.restart == "on-failure" and code != 0
            )
            if again and proc.name != "secrets":
                time.sleep(restart_delay)
                proc.child.start()

    def client_config(self, role: str = "learner", retry_ms: int | None = None):
        """A zenoh client config for this scenario's router with one of its own credentials
        (``role``: the router refuses anyone else), e.g. for an observer; ``retry_ms``: try to
        reconnect that often after losing the router (default: zenoh's backoff)."""
        import zenoh

        config = zenoh.Config.from_file(str(self.secrets / f"{role}.json5"))
        return client_config(config, f"tls/127.0.0.1:{self.port}", retry_ms)

    def running(self, name: str) -> bool:
        return self.procs[name].child.poll() is None

    def stop(self, timeout: float = 10.0) -> None:
        """SIGTERM to every service by PID (last started first), then wait for each; SIGKILL
        for any still running after ``timeout``."""
        children = [self.procs[name].child for name in reversed(list(self.procs))]
        for child in children:
            child.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for child in children:
            child.stop(signal.SIGTERM, timeout=max(0.1, deadline - time.monotonic()))

    def __enter__(self) -> Scenario:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--workdir", required=True, type=Path, help="secrets/, data/, logs/ go here"
    )
    parser.add_argument("--port", type=int, default=ROUTER_PORT, help="router port (7447)")
    args = parser.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with Scenario(args.workdir, args.port) as scenario:
        print(f"compose_local: running {', '.join(scenario.procs)}; logs in {scenario.logs}")
        while not stop.wait(0.5):  # restarts exited services twice a second, as docker would
            scenario.poll()
    return 0


if __name__ == "__main__":
    sys.exit(main())
