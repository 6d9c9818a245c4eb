"""What every rhbl process shares: exit codes, logging, signals, opening the session, a scope.

``rhbl server`` and the client processes (teacher, learner, controller) run through ``run_process``:

- ``run_process(role, args, body, check=..., robot=..., ident=..., early_token=...)``: configures
  logging (``--log-level``), turns SIGINT/SIGTERM into ``SystemExit(0)``, calls ``check()``
  (flags and files checked before any network: bad input exits 2 before an unreachable router
  exits 3), opens the zenoh session with an error naming the endpoint and the likely reason,
  optionally declares the liveliness token ``rhbl/alive/<role>/<ident>``, calls ``body(ctx)``
  and maps failures to exit codes (``EXIT_*`` below), each reported as one log line.
- ``Context.scope``: a ``contextlib.ExitStack`` holding everything the process declares
  (``ctx.subscriber``, ``ctx.queryable``, ``ctx.publisher``, ``ctx.keep``) and its closing
  (``ctx.scope.callback``: a process's last lines are said there, after "stopping (signal)"):
  released in reverse order on every path, then the session is closed (an unclosed session
  with callback subscribers hangs the interpreter at exit).
- ``Context.report(counters)``: the process's counters as data: ``counters()`` returns a JSON
  map, written to ``--stats FILE`` when the process exits (with its ``role`` and ``exit``
  code), whatever the path; tests and campaigns read it rather than log lines.
- ``on_stop_signal(callback)``: a process that stops gracefully (the learner drains, the server
  finishes its tick) replaces ``SystemExit`` by its own stop request.

Exit codes: 0 ok (also after SIGINT/SIGTERM), 1 failure, 2 usage/bad input (a snapshot that does
not fit, a bad world, ...), 3 the router/server endpoint is unreachable, refused the session or a
listen endpoint cannot be bound, 4 the server is not up (no scans of the robot), 5 no learner is
up (the teacher, unless ``--no-wait-learner``).
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

from process import arguments, files
from process.session import config_from_args
from protocol import keys

__all__ = [
    "EXIT_FAILURE",
    "EXIT_NO_LEARNER",
    "EXIT_NO_SERVER",
    "EXIT_OK",
    "EXIT_UNREACHABLE",
    "EXIT_USAGE",
    "Context",
    "ProcessError",
    "add_report_arguments",
    "check_stats_path",
    "install_signal_handlers",
    "on_stop_signal",
    "open_session",
    "run_process",
    "setup_logging",
    "uninterrupted",
    "write_stats",
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


def _undeclare(thing: Any) -> None:
    with contextlib.suppress(Exception):  # already gone with the session
        thing.undeclare()


@dataclass
class Context:
    """What ``run_process`` hands to a process body: the session and the scope its declarations live in."""

    role: str
    ident: str
    args: argparse.Namespace
    session: zenoh.Session
    scope: contextlib.ExitStack
    robot: str = ""
    endpoints: list[str] = field(default_factory=list)  # the connect endpoints
    config: zenoh.Config | None = None
    token: Any = None  # the liveliness token (kept referenced while declared)
    counters: Callable[[], dict] | None = None  # set by ``report``

    def report(self, counters: Callable[[], dict]) -> None:
        """Give the process's counters (``counters()``: a JSON map), written to ``--stats``
        at exit."""
        self.counters = counters

    def declare_token(self) -> None:
        """Declare the liveliness token ``rhbl/alive/<role>/<ident>`` (once). ``run_process(...,
        early_token=False)`` leaves it to the body, to declare when the process is ready (the
        learner: after its label subscription, so the token means "ready to receive")."""
        if self.token is None:
            self.token = self.session.liveliness().declare_token(
                keys.alive_key(self.role, self.ident))
            self.scope.callback(self.withdraw_token)

    def withdraw_token(self) -> None:
        """Undeclare the liveliness token now (the process stops being what it announced)."""
        token, self.token = self.token, None
        if token is not None:
            _undeclare(token)

    def keep(self, thing: Any) -> Any:
        """Undeclare ``thing`` (a subscriber, queryable, publisher, token) when the scope ends."""
        self.scope.callback(_undeclare, thing)
        return thing

    def subscriber(self, key: str, handler: Any, **kw: Any) -> Any:
        return self.keep(self.session.declare_subscriber(key, handler, **kw))

    def queryable(self, key: str, handler: Any, **kw: Any) -> Any:
        return self.keep(self.session.declare_queryable(key, handler, **kw))

    def publisher(self, key: str, **kw: Any) -> Any:
        return self.keep(self.session.declare_publisher(key, **kw))


def add_report_arguments(parser: argparse.ArgumentParser) -> None:
    """What a process says and reports: ``--log-level`` and ``--stats FILE``."""
    parser.add_argument("--log-level", default=os.environ.get("RHBL_LOG_LEVEL", "INFO"),
                        choices=["DEBUG", "INFO", "WARNING", "ERROR"], type=str.upper,
                        help="logging level (default: INFO or $RHBL_LOG_LEVEL)")
    parser.add_argument("--stats", metavar="FILE", default=None, type=arguments.output_file,
                        help="at exit, write the process's counters to FILE as JSON (with its "
                             "role and exit code); the file is replaced (a regular file or a "
                             "new one only)")


def check_stats_path(path: str | None) -> None:
    """``--stats FILE`` must be writable under ``process.files``' rule (FileRuleError, a
    ValueError)."""
    if path is not None:
        files.check_output(path, "--stats")


def write_stats(path: str, role: str, code: int, counters: dict) -> None:
    """``--stats FILE``: the counters as JSON, written atomically (a reader never sees half),
    to a regular file only (``process.files``)."""
    files.write_text(path, json.dumps({"role": role, "exit": code, **counters}, indent=1,
                                      default=str) + "\n", "--stats")


def setup_logging(role: str, level: str = "INFO") -> None:
    logging.basicConfig(
        level=getattr(logging, str(level).upper(), logging.INFO),
        format=f"%(asctime)s {role}[%(process)d] %(levelname)s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
        force=True,
    )


# how often a stop signal is delivered again while the main thread has not unwound
REDELIVER_S = 1.0
_stopping = threading.Event()
_redelivering = threading.Event()  # the stop signal's redelivery loop runs (``_raise_exit``)


# a stop signal that lands in one of these is delivered again shortly instead of raised there:
# Python swallows (and prints as "Exception ignored in ...") an exception raised in the import
# machinery's lock callbacks (frozen code) and in ``__del__``
DEFER_S = 0.05
_SWALLOWING = ("<frozen importlib",)


_held = threading.local()  # .depth > 0: the main thread is in ``uninterrupted()``


@contextlib.contextmanager
def uninterrupted():
    """A stop signal arriving inside this block is delivered again shortly after it instead of
    raised in it: for a few statements that must all happen or none (a label put on the bus
    and counted)."""
    _held.depth = getattr(_held, "depth", 0) + 1
    try:
        yield
    finally:
        _held.depth -= 1


def _deferred_here(frame) -> bool:
    """Whether a stop signal must not be raised in ``frame``: the interpreter would swallow the
    exception there, or the main thread is in ``uninterrupted()``."""
    if getattr(_held, "depth", 0):
        return True
    code = frame.f_code if frame is not None else None
    return code is not None and (code.co_name == "__del__"
                                 or code.co_filename.startswith(_SWALLOWING))


def _raise_exit(signum, frame) -> None:
    _stopping.set()
    if _deferred_here(frame):  # raised here it would be lost, or cut an uninterrupted block
        threading.Thread(target=_redeliver, args=(signum, DEFER_S, False), name="stop-signal",
                         daemon=True).start()
        return
    # the first time it is raised (not the first signal: a deferred one was not raised), the
    # signal is delivered again until acted on: before, a signal deferred once and then
    # swallowed where it was raised left the process running (a server stopped during its
    # start kept on until SIGKILL)
    if not _redelivering.is_set():
        _redelivering.set()
        threading.Thread(target=_redeliver, args=(signum,), name="stop-signal",
                         daemon=True).start()
    raise SystemExit(EXIT_OK)


def _redeliver(signum: int, every: float = REDELIVER_S, loop: bool = True) -> None:
    """Deliver the stop signal again every ``every`` s until its handler is gone
    (``run_process`` ignores stop signals once the body has unwound), or once (``loop`` false:
    a signal deferred by ``_raise_exit``). The ``SystemExit`` a signal raises lands wherever the
    main thread happens to be, and code there can swallow it: a signal that came during numpy's
    first lazy ``import numpy.random`` was lost that way, and the teacher went on waiting for a
    learner until it was killed."""
    while True:
        time.sleep(every)
        if signal.getsignal(signum) is not _raise_exit:
            return
        if loop:
            log.info("stop signal %d not acted on after %g s: delivered again", signum, every)
        signal.pthread_kill(threading.main_thread().ident, signum)
        if not loop:
            return


def install_signal_handlers() -> None:
    """SIGINT/SIGTERM -> SystemExit(0) in the main thread (a blocking ``recv`` is interrupted),
    delivered again until the main thread has unwound (see ``_redeliver``)."""
    signal.signal(signal.SIGINT, _raise_exit)
    signal.signal(signal.SIGTERM, _raise_exit)


def on_stop_signal(callback: Callable[[], None]) -> None:
    """SIGINT/SIGTERM call ``callback()`` instead (a process that stops on its own terms)."""
    def handler(signum, _frame) -> None:
        callback()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def _ignore_signals() -> None:
    """A second signal while closing must not leave the session open."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


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


def _diagnose(connect: list[str], listen: list[str], default: bool = False) -> list[str]:
    """Why ``zenoh.open`` failed, endpoint by endpoint (zenoh reports every case alike);
    ``default``: the endpoints are the default ones, no ``--connect`` was given."""
    reasons = []
    for ep in connect:
        state = _probe(ep)
        what = f"{ep} (the default endpoint: no --connect given)" if default else ep
        if state == "open":
            reasons.append(f"{what}: something listens there but refused the zenoh session "
                           f"(another program holding that port, or wrong credentials, TLS "
                           f"certificates or protocol version?)")
        elif state == "refused":
            reasons.append(f"{what}: connection refused (no router/server listening there; "
                           f"is `rhbl server` or the router running?)")
        else:
            reasons.append(f"{what}: {state}")
    for ep in listen:
        if _probe(ep, timeout=0.5) == "open":
            reasons.append(f"listen {ep}: already in use (another server or router listens "
                           f"there?)")
    return reasons


def _mode(config: zenoh.Config) -> str:
    try:
        return str(json.loads(config.get_json("mode")))
    except Exception:  # noqa: BLE001
        return "peer"


ROUTER_RETRY = 0.1  # s between attempts while waiting for a router (``wait_router``)


def open_session(config: zenoh.Config, role: str = "process", wait_router: float | None = None,
                 default: bool = False) -> tuple[zenoh.Session, list[str]]:
    """``zenoh.open`` with an error that says which endpoint failed and the likely reason
    (ProcessError, EXIT_UNREACHABLE); ``default``: the endpoints are the default ones (no
    ``--connect`` given), said in the error. With ``wait_router`` (seconds, 0 = forever), a
    client whose endpoints all refuse the connection (nothing listens yet) tries again every
    ``ROUTER_RETRY`` s, logging what it waits for. Returns the session and its connect
    endpoints."""
    connect = _config_endpoints(config, "connect/endpoints")
    mode = _mode(config)
    t0 = time.monotonic()
    next_note = t0
    was_refused = False  # the attempt before was refused: a router coming up now is tried again
    while True:
        try:
            session = zenoh.open(config)
            break
        except Exception as exc:  # zenoh.ZError; also config errors
            reasons = _diagnose(connect, _config_endpoints(config, "listen/endpoints"), default)
            refused = bool(connect) and all("connection refused" in r for r in reasons)
            waited = time.monotonic() - t0
            # refused while opening, listening by the diagnosis: the router came up between
            # the two, so one more attempt (a second refusal by a listener is an error)
            retry = refused or was_refused
            was_refused = refused
            if wait_router is None or not retry or (wait_router and waited >= wait_router):
                raise ProcessError(
                    f"{role}: cannot open a zenoh session ({mode} mode, connect "
                    f"{connect or 'none'}): {'; '.join(reasons) or exc}. zenoh said: {exc}",
                    EXIT_UNREACHABLE) from exc
            if time.monotonic() >= next_note:
                log.info("%s: waiting for a router: nothing listens on %s yet (%.0f s%s)", role,
                         ", ".join(connect), waited,
                         f" of {wait_router:g}" if wait_router else "")
                next_note = time.monotonic() + 3.0
            time.sleep(ROUTER_RETRY)
    if connect and mode != "client":
        _say_if_alone(session, role, connect)
    return session, connect


def _say_if_alone(session: zenoh.Session, role: str, connect: list[str]) -> None:
    """A peer (or router) that cannot connect opens anyway, silently alone: say so."""
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        info = session.info
        if info.routers_zid() or info.peers_zid():
            return
        time.sleep(0.05)
    log.warning("%s: connected to no router or peer yet (connect %s); still trying",
                role, ", ".join(connect))


def _close_session(session: zenoh.Session) -> None:
    _ignore_signals()
    with contextlib.suppress(Exception):
        session.close()


# ---- the main wrapper ---------------------------------------------------------------------
def run_process(role: str, args: argparse.Namespace, body: Callable[[Context], int | None], *,
                check: Callable[[], None] | None = None, robot: str = "",
                ident: str | None = None, early_token: bool = True,
                wait_router: float | None = None) -> int:
    """Run a process body with logging, signals, a session and a scope; the exit code.

    ``check()`` runs before the session opens (raise ProcessError(EXIT_USAGE) or ValueError for
    bad input; ``--stats`` is checked there too). The liveliness token
    ``rhbl/alive/<role>/<ident>`` (``ident`` default: the pid) is declared before ``body`` runs
    if ``early_token``, else by the body with ``ctx.declare_token()`` if ever (the server's
    node declares its own). ``wait_router`` (seconds, 0 = forever; None: not at all): while
    nothing listens on the connect endpoints, try again instead of exiting 3. The counters the
    body gave (``ctx.report``) go to ``--stats`` at exit."""
    setup_logging(role, getattr(args, "log_level", "INFO"))
    install_signal_handlers()
    holder: list[Context] = []
    code = EXIT_FAILURE
    try:
        code = _run(role, args, body, check, robot, ident, early_token, wait_router, holder)
    except ProcessError as exc:
        log.error("%s", exc)
        code = exc.code
    except SystemExit as exc:  # a stop signal before the body ran (opening the session)
        code = exc.code if isinstance(exc.code, int) else EXIT_OK
        if code == EXIT_OK:
            log.info("%s stopping (signal)", role)
    except KeyboardInterrupt:
        code = EXIT_OK
    except Exception:
        log.exception("%s failed", role)
        code = EXIT_FAILURE
    stats = getattr(args, "stats", None)
    if stats and holder and holder[0].counters is not None:
        try:
            write_stats(stats, role, code, holder[0].counters())
        except Exception as exc:  # noqa: BLE001 - the exit code stands; say why
            log.error("%s: could not write --stats %s: %s", role, stats, exc)
    return code


def _run(role: str, args: argparse.Namespace, body, check, robot: str, ident: str | None,
         early_token: bool, wait_router: float | None, holder: list) -> int:
    """``run_process`` inside the scope: a stop signal during the body is said at once, then
    the scope (the process's closing and last lines) is released with signals ignored."""
    with contextlib.ExitStack() as scope:
        _checked(role, lambda: (check_stats_path(getattr(args, "stats", None)),
                                check() if check is not None else None))
        ctx = _open(role, args, scope, robot, ident or str(os.getpid()), wait_router)
        holder.append(ctx)
        if early_token:
            ctx.declare_token()
        where = f"robot {robot}, " if robot else ""
        log.info("%s up (%spid %d, zid %s)", role, where, os.getpid(), ctx.session.zid())
        try:
            return int(body(ctx) or EXIT_OK)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else EXIT_OK
            if code == EXIT_OK:
                log.info("%s stopping (signal)", role)
            return code
        finally:
            _ignore_signals()  # the scope is released whatever arrives now


def _checked(role: str, check: Callable[[], None]) -> None:
    try:
        check()
    except ValueError as exc:
        raise ProcessError(f"{role}: {exc}", EXIT_USAGE) from exc


def _open(role: str, args: argparse.Namespace, scope: contextlib.ExitStack, robot: str,
          ident: str, wait_router: float | None = None) -> Context:
    try:
        config = config_from_args(args)
    except Exception as exc:  # noqa: BLE001 - bad flags or config file
        raise ProcessError(f"{role}: bad zenoh configuration: {exc}", EXIT_USAGE) from exc
    default = getattr(args, "connect", None) is None and getattr(args, "zenoh_config", None) is None
    session, endpoints = open_session(config, role, wait_router, default=default)
    scope.callback(_close_session, session)  # the last to go: everything else was declared in it
    return Context(role, ident, args, session, scope, robot, endpoints, config)
