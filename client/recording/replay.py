"""``rhbl replay``: republish a recording's sensor stream on zenoh with its timing (Player's
``readlog``): the server's keys (state, scan, driver) of every recorded robot, payloads bit for
bit, spaced as they were received (``--speed`` scales it). A controller or learner then runs
against it without a simulator; commands are not replayed (the new controller makes its own).

    rhbl replay run.mcap --listen tcp/127.0.0.1:7447 --mode router   # be the rendezvous
    rhbl controller --tree tree.rhbl --connect tcp/127.0.0.1:7447      # drives the replay

It answers ``sim/req/get_world`` with the recorded world (viewers draw the walls) and holds the
liveliness token ``rhbl/alive/server/replay-<pid>`` while it plays.
"""

from __future__ import annotations

import argparse
import logging
import os
import time

import zenoh

from client.recording.mcap_file import RecordingError, classify, read_recording
from client.roles.common import run_role
from protocol import keys
from protocol.messages import Scan, VelCmd
from protocol.runtime import EXIT_USAGE, Context, ProcessError, add_logging_arguments
from protocol.session import add_zenoh_arguments

__all__ = ["SENSOR_KINDS", "add_arguments", "main"]

log = logging.getLogger(__name__)

SENSOR_KINDS = ("state", "scan", "driver")  # what the server publishes


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("recording", help="an MCAP file written by rhbl record (or --record)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="X",
                        help="play X times as fast as recorded (0 = as fast as possible; "
                             "default 1)")
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        help="replay only this robot (repeatable; default: every robot)")
    parser.add_argument("--wait-subscriber", type=float, default=10.0, metavar="SECONDS",
                        help="start once something subscribes to the scans, waiting at most "
                             "this long (0 = start at once; default 10)")
    parser.add_argument("--lockstep", action="store_true",
                        help="after each scan wait until a command answers it (its scan_id), "
                             "as a lock-step server does, at most --lockstep-timeout: every "
                             "scan gets its command however slow the machine")
    parser.add_argument("--lockstep-timeout", type=float, default=1.0, metavar="SECONDS",
                        help="with --lockstep: go on after this long without an answer "
                             "(default 1)")
    add_logging_arguments(parser)


def main(args: argparse.Namespace) -> int:
    if not args.speed >= 0:
        raise ValueError(f"--speed must be >= 0, got {args.speed}")
    if not os.path.exists(args.recording):
        raise ValueError(f"recording {args.recording} does not exist")
    args.robot = "replay"  # the liveliness token's name
    return run_role("replay", args, _body, early_token=False)


def _body(ctx: Context) -> int:
    args, session = ctx.args, ctx.session
    try:
        msgs = [m for m in read_recording(args.recording)
                if m.kind in (*SENSOR_KINDS, "world")
                and (not args.robots or m.robot in args.robots)]
    except RecordingError as exc:
        raise ProcessError(f"replay: {exc}", EXIT_USAGE) from exc
    stream = [m for m in msgs if m.kind in SENSOR_KINDS]
    if not stream:
        raise ProcessError(f"replay: {args.recording} holds no sensor messages"
                           f"{' of robot ' + ', '.join(args.robots) if args.robots else ''}",
                           EXIT_USAGE)
    worlds = {m.robot: m.data for m in msgs if m.kind == "world"}
    queryables = []
    for robot, data in worlds.items():
        key = keys.sim_request_key(robot, "get_world")

        def answer(query, key=key, data=data):
            try:
                query.reply(key, data)
            except Exception as exc:  # noqa: BLE001 - the querier went away
                log.debug("get_world reply failed: %s", exc)

        queryables.append(session.declare_queryable(key, answer))
    pubs: dict[str, zenoh.Publisher] = {}
    for m in stream:
        if m.key not in pubs:
            pubs[m.key] = session.declare_publisher(
                m.key, congestion_control=zenoh.CongestionControl.BLOCK)
    token = session.liveliness().declare_token(keys.alive_key("server", f"replay-{os.getpid()}"))
    robots = sorted({m.robot for m in stream})
    scan_pubs = [p for k, p in pubs.items() if classify(k)[0] == "scan"]
    if args.wait_subscriber > 0 and scan_pubs:
        deadline = time.monotonic() + args.wait_subscriber
        while not any(p.matching_status.matching for p in scan_pubs):
            if time.monotonic() >= deadline:
                log.info("nobody subscribes to the scans after %.0f s: replaying anyway",
                         args.wait_subscriber)
                break
            time.sleep(0.02)
    log.info("replaying %d messages of %s (robots %s) at %s", len(stream), args.recording,
             ", ".join(robots), f"{args.speed:g}x" if args.speed else "full speed")
    answers = _Answers(session, robots) if args.lockstep else None
    t_rec0 = stream[0].log_time
    t0 = time.monotonic()
    sent = unanswered = 0
    try:
        for m in stream:
            if args.speed > 0:
                due = t0 + (m.log_time - t_rec0) / 1e9 / args.speed
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            pubs[m.key].put(m.data)
            sent += 1
            if answers is not None and m.kind == "scan":
                waited = time.monotonic()
                if not answers.wait(m.robot, m.data, args.lockstep_timeout):
                    unanswered += 1
                t0 += time.monotonic() - waited  # the recorded spacing after the answer
    finally:
        if answers is not None:
            answers.close()
            log.info("lock-step: %d scans without an answer within %.1f s", unanswered,
                     args.lockstep_timeout)
        span = (stream[-1].log_time - t_rec0) / 1e9
        log.info("replay stopped: %d of %d messages sent (%.1f s recorded, %.1f s played)", sent,
                 len(stream), span, time.monotonic() - t0)
        token.undeclare()
        for q in queryables:
            q.undeclare()
    return 0



class _Answers:
    """The scan ids the robots' commands answered (``--lockstep``)."""

    def __init__(self, session, robots):
        import threading

        self._cond = threading.Condition()
        self._seen: dict[str, int] = {}
        self._subs = [session.declare_subscriber(keys.cmd_vel_subscription(r),
                                                 lambda s, r=r: self._on(r, s))
                      for r in robots]

    def _on(self, robot: str, sample) -> None:
        try:
            cmd = VelCmd.decode(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - a malformed command answers nothing
            return
        if cmd.scan_id is None:
            return
        with self._cond:
            self._seen[robot] = max(self._seen.get(robot, -1), cmd.scan_id)
            self._cond.notify_all()

    def wait(self, robot: str, scan_payload: bytes, timeout: float) -> bool:
        try:
            sid = Scan.decode(scan_payload).id
        except Exception:  # noqa: BLE001
            return True
        with self._cond:
            return self._cond.wait_for(lambda: self._seen.get(robot, -1) >= sid, timeout)

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
