"""Plumbing shared by the teacher, learner and controller processes.

- ``add_process_arguments(parser)``: the common flags (zenoh flags from ``protocol.session``,
  ``--robot``, ``--wait-server``, ``--log-level``).
- ``run(role, args, body)``: configures logging, turns SIGINT/SIGTERM into ``SystemExit(0)``, opens
  the zenoh session with clear errors, declares the liveliness token ``rhbl/alive/<role>/<id>``,
  calls ``body(ctx)`` and maps failures to exit codes (``EXIT_*`` below). The session is closed
  on every path (an unclosed session with callback subscribers hangs the interpreter at exit).
- ``wait_for_server(ctx)``: waits for the first scan of the robot, logging what it waits for,
  and fails with a message naming the endpoint and the key when the server is not up.
- ``wait_for_learner(ctx, timeout)``: waits for a learner's liveliness token of the robot
  (``rhbl/alive/learner/<robot>-*``; a learner declares it once its label subscription is in
  place), logging what it waits for, and fails with EXIT_NO_LEARNER when none appears.
- ``ScanWatch``: a background thread that logs when scans stop arriving and when they resume.

Exit codes: 0 ok (also after SIGINT/SIGTERM), 1 failure, 2 usage/bad input (a snapshot that does
not fit, ...), 3 the router/server endpoint is unreachable or refused the session, 4 the server is
not up (no scans of the robot), 5 no learner is up (the teacher, unless ``--no-wait-learner``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from protocol import keys
from protocol.messages import Scan
from protocol.session import add_zenoh_arguments, config_from_args

__all__ = [
    "EXIT_FAILURE",
    "EXIT_NO_LEARNER",
    "EXIT_NO_SERVER",
    "EXIT_OK",
    "EXIT_UNREACHABLE",
    "EXIT_USAGE",
    "Context",
    "ProcessError",
    "ScanWatch",
    "add_process_arguments",
    "open_session",
    "run",
    "wait_for_learner",
    "wait_for_server",
]

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_UNREACHABLE = 3
EXIT_NO_SERVER = 4
EXIT_NO_LEARNER = 5


class ProcessError(Exception):
    """A failure a process reports with one clear message and an exit code (no traceback)."""

    def __init__(self, message: str, code: int = EXIT_FAILURE):
        super().__init__(message)
        self.code = code


@dataclass
class Context:
    """What ``run`` hands to a process body."""

    role: str
    ident: str
    args: argparse.Namespace
    session: zenoh.Session
    robot: str
    endpoints: list[str] = field(default_factory=list)
    token: Any = None  # the liveliness token (kept referenced for the session's lifetime)

    def declare_token(self) -> None:
        """Declare the liveliness token ``rhbl/alive/<role>/<ident>`` (once). ``run(...,
        early_token=False)`` leaves it to the body, to declare when the process is ready (the
        learner: after its label subscription, so the token means "ready to receive")."""
        if self.token is None:
            self.token = self.session.liveliness().declare_token(
                keys.alive_key(self.role, self.ident))


def add_process_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--robot", default="r0", help="robot name (default: r0)")
    parser.add_argument("--wait-server", type=float, default=10.0, metavar="SECONDS",
                        help="how long to wait for the server's first scan before giving up "
                             "(0 = wait forever, logging every few seconds; default: 10)")
    parser.add_argument("--log-level", default=os.environ.get("RHBL_LOG_LEVEL", "INFO"),
                        choices=["DEBUG", "INFO", "WARNING", "ERROR"], type=str.upper,
                        help="logging level (default: INFO or $RHBL_LOG_LEVEL)")


def setup_logging(role: str, level: str = "INFO") -> None:
    logging.basicConfig(
        level=getattr(logging, level, logging.INFO),
        format=f"%(asctime)s {role}[%(process)d] %(levelname)s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
        force=True,
    )


def _raise_exit(signum, _frame) -> None:
    raise SystemExit(EXIT_OK)


def install_signal_handlers() -> None:
    """SIGINT/SIGTERM -> SystemExit(0) in the main thread (a blocking ``recv`` is interrupted)."""
    signal.signal(signal.SIGINT, _raise_exit)
    signal.signal(signal.SIGTERM, _raise_exit)


# ---- session ------------------------------------------------------------------------------
def _config_endpoints(config: zenoh.Config, key: str) -> list[str]:
    try:
        value = config.get_json(key)
    except Exception:  # noqa: BLE001 - a config without the key
        return []
    if isinstance(value, str):
        try:
            value = json.loads(value)
        except ValueError:
            return [value]
    if isinstance(value, dict):  # per-mode endpoints {"router": [...], "peer": [...]}
        out: list[str] = []
        for v in value.values():
            out.extend(v if isinstance(v, list) else [v])
        return [str(e) for e in out]
    return [str(e) for e in value or []]


def _probe(endpoint: str, timeout: float = 1.0) -> str:
    """What a plain TCP connect to an endpoint says: 'open', 'refused', 'timeout: ...'."""
    proto, _, rest = endpoint.partition("/")
    if proto not in ("tcp", "tls", "quic", "ws"):
        return "unknown"
    addr = rest.split("#", 1)[0]
    host, _, port = addr.rpartition(":")
    host = host.strip("[]")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            return "open"
    except ConnectionRefusedError:
        return "refused"
    except (OSError, ValueError) as exc:
        return f"unreachable ({exc})"


def open_session(config: zenoh.Config, role: str = "process") -> tuple[zenoh.Session, list[str]]:
    """``zenoh.open`` with an error that says which endpoint failed and the likely reason."""
    connect = _config_endpoints(config, "connect/endpoints")
    try:
        mode = json.loads(config.get_json("mode"))
    except Exception:  # noqa: BLE001
        mode = "peer"
    try:
        session = zenoh.open(config)
    except Exception as exc:  # zenoh.ZError; also config errors
        reasons = []
        for ep in connect:
            state = _probe(ep)
            if state == "open":
                reasons.append(f"{ep}: something listens there but refused the zenoh session "
                               f"(wrong credentials, TLS certificates or protocol version?)")
            elif state == "refused":
                reasons.append(f"{ep}: connection refused (no router/server listening there; "
                               f"is `rhbl server` or the router running?)")
            else:
                reasons.append(f"{ep}: {state}")
        detail = "; ".join(reasons) or str(exc)
        raise ProcessError(f"{role}: cannot open a zenoh session ({mode} mode, connect "
                           f"{connect or 'none'}): {detail}. zenoh said: {exc}",
                           EXIT_UNREACHABLE) from exc
    if connect and mode != "client":
        # a peer that cannot connect opens anyway, silently alone: say so
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            info = session.info
            if info.routers_zid() or info.peers_zid():
                break
            time.sleep(0.05)
        else:
            log.warning("%s: connected to no router or peer yet (connect %s); still trying",
                        role, ", ".join(connect))
    return session, connect


# ---- the server ---------------------------------------------------------------------------
def server_alive(session: zenoh.Session, timeout: float = 1.0) -> list[str]:
    """Key expressions of the server liveliness tokens currently visible."""
    found = []
    try:
        for reply in session.liveliness().get(keys.alive_key("server", "**"), timeout=timeout):
            if reply.ok is not None:
                found.append(str(reply.ok.key_expr))
    except Exception as exc:  # noqa: BLE001 - diagnostics only
        log.debug("liveliness query failed: %s", exc)
    return found


def wait_for_server(ctx: Context, timeout: float | None = None,
                    got: threading.Event | None = None) -> None:
    """Block until the robot's first scan arrives; ProcessError(EXIT_NO_SERVER) after timeout.

    ``got``: an event the caller's own scan subscription sets (``ScanWatch.first``). Pass it
    when that subscription was declared before the process announced itself: a subscription
    declared here, later, could miss a scan sent as soon as the token was seen.
    Logs what it is waiting for every few seconds, so a process never waits silently.
    """
    timeout = ctx.args.wait_server if timeout is None else timeout
    key = keys.scan_key(ctx.robot)
    sub = None
    if got is None:
        got = threading.Event()
        sub = ctx.session.declare_subscriber(key, lambda _s: got.set())
    try:
        t0 = time.monotonic()
        next_note = t0 + 2.0
        while not got.wait(0.05):
            now = time.monotonic()
            if timeout and now - t0 >= timeout:
                alive = server_alive(ctx.session)
                where = ", ".join(ctx.endpoints) or "the local zenoh network"
                if alive:
                    raise ProcessError(
                        f"{ctx.role}: a server is up ({', '.join(alive)}) but no scans of robot "
                        f"{ctx.robot!r} arrived on {key} within {timeout:g} s (wrong --robot, or "
                        f"the server is paused?)", EXIT_NO_SERVER)
                raise ProcessError(
                    f"{ctx.role}: the server is not up: no scans on {key} and no liveliness "
                    f"token {keys.alive_key('server', '*')} within {timeout:g} s via {where}. "
                    f"Start `rhbl server` (or check --connect/--robot).", EXIT_NO_SERVER)
            if now >= next_note:
                alive = server_alive(ctx.session, timeout=0.5)
                log.info("waiting for the server: no scans on %s yet (%s; %.0f s)", key,
                         f"server tokens: {', '.join(alive)}" if alive else "no server token",
                         now - t0)
                next_note = now + 3.0
    finally:
        if sub is not None:
            sub.undeclare()
    log.info("server is up: scans arrive on %s", key)


def learners_alive(session: zenoh.Session, robot: str, timeout: float = 1.0) -> list[str]:
    """Key expressions of the liveliness tokens of the learners of ``robot`` now visible."""
    found = []
    try:
        for reply in session.liveliness().get(keys.alive_key("learner", "*"), timeout=timeout):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                if key.rsplit("/", 1)[-1].startswith(f"{robot}-"):
                    found.append(key)
    except Exception as exc:  # noqa: BLE001 - treated as "none yet"
        log.debug("liveliness query failed: %s", exc)
    return found


def wait_for_learner(ctx: Context, timeout: float | None = None) -> list[str]:
    """Block until a learner of the robot holds its liveliness token (it then receives labels);
    ProcessError(EXIT_NO_LEARNER) after ``timeout`` s (0 = wait forever). Logs every few
    seconds while waiting. Returns the learners' token keys."""
    timeout = ctx.args.wait_learner_timeout if timeout is None else timeout
    want = f"{keys.alive_key('learner', '*')[:-1]}{ctx.robot}-<pid>"
    t0 = time.monotonic()
    found = learners_alive(ctx.session, ctx.robot, timeout=0.5)
    if not found:
        log.info("%s: waiting for a learner (liveliness token %s) before demonstrating, so no "
                 "label is lost; --no-wait-learner to demonstrate without one", ctx.role, want)
    next_note = t0 + 3.0
    while not found:
        now = time.monotonic()
        if timeout and now - t0 >= timeout:
            where = ", ".join(ctx.endpoints) or "the local zenoh network"
            raise ProcessError(
                f"{ctx.role}: no learner is up: no liveliness token {want} within {timeout:g} s "
                f"via {where}. Start `rhbl learner --robot {ctx.robot}` (it may start later: "
                f"raise --wait-learner-timeout, 0 = wait forever), or pass --no-wait-learner to "
                f"demonstrate without recording.", EXIT_NO_LEARNER)
        if now >= next_note:
            log.info("%s: still waiting for a learner (%s; %.0f s%s)", ctx.role, want, now - t0,
                     f" of {timeout:g}" if timeout else "")
            next_note = now + 3.0
        time.sleep(0.2)
        found = learners_alive(ctx.session, ctx.robot, timeout=0.5)
    log.info("learner is up: %s", ", ".join(found))
    return found


class ScanWatch:
    """Logs (once) when no scan has arrived for ``stale`` seconds, and when scans resume.

    The processes only act on scans, so when scans stop they stop commanding by construction;
    this thread just makes it visible. Call ``seen()`` for every scan.
    """

    def __init__(self, role: str, key: str, stale: float = 1.0):
        self.role, self.key, self.stale = role, key, stale
        self._last = time.monotonic()
        self._stalled = False
        self.first = threading.Event()  # set by the first scan seen
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"{role}-scanwatch", daemon=True)

    def start(self) -> ScanWatch:
        self._thread.start()
        return self

    def seen(self) -> None:
        self._last = time.monotonic()
        self.first.set()
        if self._stalled:
            self._stalled = False
            log.info("%s: scans resumed on %s", self.role, self.key)

    @property
    def stalled(self) -> bool:
        return self._stalled

    def _loop(self) -> None:
        while not self._stop.wait(min(0.25, self.stale / 2)):
            idle = time.monotonic() - self._last
            if not self._stalled and idle >= self.stale:
                self._stalled = True
                log.warning("%s: no scan on %s for %.1f s: not commanding (the server's "
                            "watchdog stops the robot); waiting", self.role, self.key, idle)

    def stop(self) -> None:
        self._stop.set()


# ---- the main wrapper ---------------------------------------------------------------------
def run(role: str, args: argparse.Namespace, body: Callable[[Context], int | None],
        early_token: bool = True) -> int:
    """Run a process body with logging, signals, a session and a liveliness token (declared
    before ``body`` runs, or by the body with ``ctx.declare_token()`` if not ``early_token``)."""
    setup_logging(role, getattr(args, "log_level", "INFO"))
    install_signal_handlers()
    session = None
    try:
        robot = getattr(args, "robot", "r0")
        try:
            keys.check_chunk(robot, "--robot")
        except ValueError as exc:
            raise ProcessError(f"{role}: {exc}", EXIT_USAGE) from exc
        try:
            config = config_from_args(args)
        except Exception as exc:  # noqa: BLE001 - bad flags or config file
            raise ProcessError(f"{role}: bad zenoh configuration: {exc}", EXIT_USAGE) from exc
        session, endpoints = open_session(config, role)
        ident = f"{robot}-{os.getpid()}"
        ctx = Context(role, ident, args, session, robot, endpoints)
        if early_token:
            ctx.declare_token()
        log.info("%s up (robot %s, pid %d, zid %s)", role, robot, os.getpid(), session.zid())
        return int(body(ctx) or EXIT_OK)
    except ProcessError as exc:
        log.error("%s", exc)
        return exc.code
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else EXIT_OK
        log.info("%s stopping (signal)", role) if code == EXIT_OK else None
        return code
    except KeyboardInterrupt:
        return EXIT_OK
    except Exception:
        log.exception("%s failed", role)
        return EXIT_FAILURE
    finally:
        if session is not None:
            # a second signal while closing must not leave the session open
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            with contextlib.suppress(Exception):
                session.close()


def decode_scan(payload: bytes) -> Scan | None:
    """Decode a scan, logging (not raising) a malformed one."""
    try:
        return Scan.decode(payload)
    except Exception as exc:  # noqa: BLE001 - protocol.DecodeError and friends
        log.warning("dropped a malformed scan: %s", exc)
        return None
