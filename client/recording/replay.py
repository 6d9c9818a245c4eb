"""``rhbl replay``: republish a recording's sensor stream on zenoh with its timing (Player's
``readlog``): the server's keys (state, scan, driver) of every recorded robot, payloads bit for
bit, spaced as they were received (``--speed`` scales it). A controller or learner then runs
against it without a simulator; commands are not replayed (the new controller makes its own).

    rhbl replay run.mcap --listen tcp/127.0.0.1:7447 --mode router   # be the rendezvous
    rhbl controller --tree tree.rhbl --connect tcp/127.0.0.1:7447      # drives the replay

The recording is read before any connection (a file that is not a recording: one line, exit
2). It answers ``sim/req/get_world`` with the recorded world (viewers draw the walls) and holds
the liveliness token ``rhbl/alive/server/replay-<pid>`` while it plays.
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time

import zenoh

from client.recording.mcap_file import RecordedMessage, RecordingError, read_recording
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import Scan, VelCmd
from protocol.runtime import Context, add_report_arguments, run_process
from protocol.session import add_zenoh_arguments

__all__ = ["SENSOR_KINDS", "ReplayProcess", "add_arguments", "load_stream", "main"]

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
    add_report_arguments(parser)


def load_stream(path: str, robots: list[str] | None = None
                ) -> tuple[list[RecordedMessage], dict[str, bytes]]:
    """The sensor messages of a recording (``SENSOR_KINDS``, of ``robots`` or every robot) in
    the order received, and each robot's recorded world (``WorldInfo`` payload). ValueError
    naming the file when it is no recording or holds no sensor message."""
    try:
        msgs = [m for m in read_recording(path)
                if m.kind in (*SENSOR_KINDS, "world") and (not robots or m.robot in robots)]
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    stream = [m for m in msgs if m.kind in SENSOR_KINDS]
    if not stream:
        raise ValueError(f"{path} holds no sensor messages"
                         f"{' of robot ' + ', '.join(robots) if robots else ''}")
    return stream, {m.robot: m.data for m in msgs if m.kind == "world"}


def main(args: argparse.Namespace) -> int:
    if not args.speed >= 0:
        raise ValueError(f"--speed must be >= 0, got {args.speed}")
    for r in args.robots or []:
        keys.check_chunk(r, "--robot")
    if not os.path.exists(args.recording):
        raise ValueError(f"recording {args.recording} does not exist")
    stream, worlds = load_stream(args.recording, args.robots)  # before any connection
    # it holds a server's token (rhbl/alive/server/replay-<pid>), not one of its own
    return run_process("replay", args, lambda ctx: ReplayProcess(ctx, stream, worlds).run(),
                       early_token=False)


class ReplayProcess:
    """Publishers for the recorded keys, the recorded worlds served, the stream played."""

    def __init__(self, ctx: Context, stream: list[RecordedMessage], worlds: dict[str, bytes]):
        self.args, self.session, self.stream = ctx.args, ctx.session, stream
        for robot, data in worlds.items():
            key = keys.sim_request_key(robot, "get_world")
            ctx.queryable(key, lambda q, key=key, data=data: self._answer(q, key, data))
        self.pubs: dict[str, zenoh.Publisher] = {}
        for m in stream:
            if m.key not in self.pubs:
                self.pubs[m.key] = ctx.publisher(
                    m.key, congestion_control=zenoh.CongestionControl.BLOCK)
        ctx.keep(self.session.liveliness().declare_token(
            keys.alive_key("server", f"replay-{os.getpid()}")))
        self.robots = sorted({m.robot for m in stream})
        self.answers = _Answers(self.session, self.robots) if self.args.lockstep else None
        self.sent = self.unanswered = 0
        self.t0 = time.monotonic()
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)

    @staticmethod
    def _answer(query, key: str, data: bytes) -> None:
        try:
            query.reply(key, data)
        except Exception as exc:  # noqa: BLE001 - the querier went away
            log.debug("get_world reply failed: %s", exc)

    def run(self) -> int:
        self.wait_for_subscriber()
        log.info("replaying %d messages of %s (robots %s) at %s", len(self.stream),
                 self.args.recording, ", ".join(self.robots),
                 f"{self.args.speed:g}x" if self.args.speed else "full speed")
        self.t0 = time.monotonic()
        for m in self.stream:
            self.play(m)
        return 0

    def wait_for_subscriber(self) -> None:
        """Until something subscribes to a recorded scan key (at most ``--wait-subscriber``)."""
        wait = self.args.wait_subscriber
        scans = [p for k, p in self.pubs.items() if keys.parse(k).kind == "scan"]
        if wait <= 0 or not scans:
            return
        deadline = time.monotonic() + wait
        while not any(p.matching_status.matching for p in scans):
            if time.monotonic() >= deadline:
                log.info("nobody subscribes to the scans after %.0f s: replaying anyway", wait)
                return
            time.sleep(0.02)

    def play(self, m: RecordedMessage) -> None:
        """Publish ``m`` at its recorded time (scaled by ``--speed``); with ``--lockstep`` a
        scan then waits for its answer, and the recorded spacing goes on after it."""
        speed = self.args.speed
        if speed > 0:
            due = self.t0 + (m.log_time - self.stream[0].log_time) / 1e9 / speed
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        self.pubs[m.key].put(m.data)
        self.sent += 1
        if self.answers is not None and m.kind == "scan":
            waited = time.monotonic()
            if not self.answers.wait(m.robot, m.data, self.args.lockstep_timeout):
                self.unanswered += 1
            self.t0 += time.monotonic() - waited

    def close(self) -> None:
        if self.answers is not None:
            self.answers.close()
            log.info("lock-step: %d scans without an answer within %.1f s", self.unanswered,
                     self.args.lockstep_timeout)
            self.answers = None
        span = (self.stream[-1].log_time - self.stream[0].log_time) / 1e9
        log.info("replay stopped: %d of %d messages sent (%.1f s recorded, %.1f s played)",
                 self.sent, len(self.stream), span, time.monotonic() - self.t0)

    def counters(self) -> dict:
        return {"sent": self.sent, "messages": len(self.stream), "unanswered": self.unanswered,
                "robots": self.robots}


class _Answers:
    """The scan ids the robots' commands answered (``--lockstep``)."""

    def __init__(self, session, robots):
        self._cond = threading.Condition()
        self._seen: dict[str, int] = {}
        self.decoder = Decoder(log, level=logging.DEBUG)  # a malformed command answers nothing
        self._subs = [session.declare_subscriber(keys.cmd_vel_subscription(r),
                                                 lambda s, r=r: self._on(r, s))
                      for r in robots]

    def _on(self, robot: str, sample) -> None:
        cmd = self.decoder.decode(VelCmd, sample.payload.to_bytes())
        if cmd is None or cmd.scan_id is None:
            return
        with self._cond:
            self._seen[robot] = max(self._seen.get(robot, -1), cmd.scan_id)
            self._cond.notify_all()

    def wait(self, robot: str, scan_payload: bytes, timeout: float) -> bool:
        scan = self.decoder.decode(Scan, scan_payload)
        if scan is None:
            return True
        with self._cond:
            return self._cond.wait_for(lambda: self._seen.get(robot, -1) >= scan.id, timeout)

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
