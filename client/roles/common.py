"""What the client's processes (teacher, learner, controller, console, record, replay, foxglove)
share beyond ``process.runtime`` (exit codes ``EXIT_*``, ``ProcessError``, logging, signals,
``open_session``, ``Context`` and its scope, shared with ``rhbl server``: import those from
there):

- ``add_process_arguments(parser)``: the common flags (zenoh flags from ``process.session``,
  ``--robot``, ``--wait-server``, ``--log-level``).
- ``run_role(role, args, body)``: ``process.runtime.run_process`` with the robot checked
  (``--robot`` must be a key chunk: exit 2) and the liveliness token ``rhbl/alive/<role>/<robot>-<pid>``.
- ``wait_for_server(ctx)``: waits for the first scan of the robot, logging what it waits for,
  and fails with a message naming the endpoint and the key when the server is not up.
- ``wait_for_learner(ctx, timeout)``: waits for a learner's liveliness token of the robot
  (``rhbl/alive/learner/<robot>-*``; a learner declares it once its label subscription is in
  place), logging what it waits for, and fails with EXIT_NO_LEARNER when none appears.
- ``ScanWatch``: a background thread that logs when scans stop arriving and when they resume.
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from process import arguments
from process.runtime import (
    EXIT_NO_LEARNER,
    EXIT_NO_SERVER,
    Context,
    ProcessError,
    add_report_arguments,
    run_process,
)
from process.session import add_zenoh_arguments
from protocol import keys

__all__ = [
    "ScanWatch",
    "add_process_arguments",
    "run_role",
    "wait_for_learner",
    "wait_for_server",
]

log = logging.getLogger(__name__)


def add_process_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--robot", default="r0", type=arguments.key_chunk,
                        help="robot name (default: r0)")
    parser.add_argument("--wait-server", type=arguments.seconds_or_zero, default=10.0,
                        metavar="SECONDS",
                        help="how long to wait for the server's first scan before giving up "
                             "(0 = wait forever, logging every few seconds; default: 10)")
    add_report_arguments(parser)


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
                    got: threading.Event | None = None,
                    stop: Callable[[], bool] | None = None, ring: Any = None) -> Any:
    """Block until the robot's first scan arrives; ProcessError(EXIT_NO_SERVER) after timeout.
    Returns early, quietly, when ``stop()`` says so (a process whose signals set a flag).

    ``got``: an event the caller's own scan subscription sets (``ScanWatch.first``). Pass it
    when that subscription was declared before the process announced itself: a subscription
    declared here, later, could miss a scan sent as soon as the token was seen.
    ``ring``: the caller's own ``client.player.ScanChannel``: the wait takes the first scan
    from it and returns it, for the caller to answer (a lock-step sender waits for that answer
    before it sends another scan). A channel of another robot than an rhbl server's (a
    ``client.ros2.nodes.Ros2ScanChannel``) names its ``key`` and what it ``needs``, said instead.
    Logs what it is waiting for every few seconds, so a process never waits silently.
    """
    timeout = ctx.args.wait_server if timeout is None else timeout
    key = getattr(ring, "key", None) or keys.scan_key(ctx.robot)
    needs = getattr(ring, "needs", None)
    sub = first = None
    if ring is not None:
        got = threading.Event()
    elif got is None:
        got = threading.Event()
        sub = ctx.session.declare_subscriber(key, lambda _s: got.set())
    try:
        t0 = time.monotonic()
        next_note = t0 + 2.0
        while not got.wait(0 if ring is not None else 0.05):
            if ring is not None:
                first = ring.try_recv()
                if first is not None:
                    break
                time.sleep(0.01)
            if stop is not None and stop():
                return
            now = time.monotonic()
            if timeout and now - t0 >= timeout:
                where = ", ".join(ctx.endpoints) or "the local zenoh network"
                if needs:
                    raise ProcessError(f"{ctx.role}: no scans on {key} within {timeout:g} s via "
                                       f"{where}: is {needs} up?", EXIT_NO_SERVER)
                alive = server_alive(ctx.session)
                if alive:
                    raise ProcessError(
                        f"{ctx.role}: a server is up ({', '.join(alive)}) but no scans of robot "
                        f"{ctx.robot!r} arrived on {key} within {timeout:g} s (wrong --robot, or "
                        f"the server is paused?)", EXIT_NO_SERVER)
                raise ProcessError(
                    f"{ctx.role}: the server is not up: no scans on {key} and no liveliness "
                    f"token {keys.alive_key('server', '**')} within {timeout:g} s via {where}. "
                    f"Start `rhbl server` (or check --connect/--robot).", EXIT_NO_SERVER)
            if now >= next_note and needs:
                log.info("waiting for %s: no scans on %s yet (%.0f s)", needs, key, now - t0)
                next_note = now + 3.0
            elif now >= next_note:
                alive = server_alive(ctx.session, timeout=0.5)
                log.info("waiting for the server: no scans on %s yet (%s; %.0f s)", key,
                         f"server tokens: {', '.join(alive)}" if alive else "no server token",
                         now - t0)
                next_note = now + 3.0
    finally:
        if sub is not None:
            sub.undeclare()
    log.info("%s: scans arrive on %s", "robot is up" if needs else "server is up", key)
    return first


def learners_alive(session: zenoh.Session, robot: str, timeout: float = 1.0) -> list[str]:
    """Key expressions of the liveliness tokens of the learners of ``robot`` now visible."""
    found = []
    try:
        for reply in session.liveliness().get(keys.alive_key("learner", "*"), timeout=timeout):
            if reply.ok is not None and keys.parse(reply.ok.key_expr).names_robot(robot):
                found.append(str(reply.ok.key_expr))
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
        """Watch from now on (a process that waited for a server or a learner first did not
        go without scans meanwhile)."""
        self._last = time.monotonic()
        self._thread.start()
        return self

    def seen(self) -> None:
        self._last = time.monotonic()
        if not self.first.is_set():  # set() takes a lock and notifies: once is enough
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
def run_role(role: str, args: argparse.Namespace, body: Callable[[Context], int | None],
             early_token: bool = True, check: Callable[[], None] | None = None,
             wait_router: float | None = None) -> int:
    """``process.runtime.run_process`` for a process of one robot (``--robot``): the token is
    ``rhbl/alive/<role>/<robot>-<pid>``, declared before ``body`` runs (or by the body with
    ``ctx.declare_token()`` if not ``early_token``); ``check`` (the process's own) runs after
    the robot's, before any connection."""
    robot = getattr(args, "robot", "r0")

    def checks() -> None:
        keys.check_chunk(robot, "--robot")
        if check is not None:
            check()

    return run_process(role, args, body, check=checks, robot=robot,
                       ident=f"{robot}-{os.getpid()}", early_token=early_token,
                       wait_router=wait_router)
