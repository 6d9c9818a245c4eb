"""``rhbl replay``: republish a recording's sensor stream on zenoh with its timing (Player's
``readlog``): the server's keys (state, scan, driver) of every recorded robot, payloads bit for
bit, spaced as they were received (``--speed`` scales it). A controller or learner then runs
against it without a simulator; commands are not replayed (the new controller makes its own).

    rhbl replay run.mcap --listen tcp/127.0.0.1:7447 --mode router   # be the rendezvous
    rhbl controller --tree tree.rhbl --connect tcp/127.0.0.1:7447      # drives the replay

The recording is read once before any connection (a file that is not a recording, or holds a
topic that is not a robot's plain key: one line, exit 2), then again as it plays (streamed:
memory does not grow with the file). A pause longer than ``--max-gap`` is played as that long. It answers ``sim/req/get_world`` with the recorded world (viewers draw the walls) and holds
the liveliness token ``rhbl/alive/server/replay-<pid>`` while it plays.
"""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import zenoh

from client.recording.mcap_file import RecordedMessage, RecordingError, read_recording
from process import arguments
from process.runtime import Context, add_report_arguments, run_process
from process.session import add_zenoh_arguments
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import Scan, VelCmd

__all__ = ["MAX_GAP", "SENSOR_KINDS", "ReplayPlan", "ReplayProcess", "add_arguments", "main",
           "plan_replay", "sensor_messages"]

log = logging.getLogger(__name__)

SENSOR_KINDS = ("state", "fiducial", "scan", "driver")  # what the server publishes
_PLAIN_KEY = {"state": keys.state_key, "fiducial": keys.fiducial_key, "scan": keys.scan_key,
              "driver": keys.driver_key}
MAX_GAP = 5.0  # default --max-gap: a longer pause in a recording is played as this long


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("recording", type=arguments.input_file,
                        help="an MCAP file written by rhbl record (or --record)")
    parser.add_argument("--speed", type=arguments.non_negative_float, default=1.0, metavar="X",
                        help="play X times as fast as recorded (0 = as fast as possible; "
                             "default 1)")
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        type=arguments.key_chunk,
                        help="replay only this robot (repeatable; default: every robot)")
    parser.add_argument("--max-gap", type=arguments.seconds, default=MAX_GAP,
                        metavar="SECONDS",
                        help=f"a pause longer than this between two recorded messages is played "
                             f"as this long (recorded time; default {MAX_GAP:g}); a message "
                             f"recorded before the one ahead of it is played at once")
    parser.add_argument("--wait-subscriber", type=arguments.seconds_or_zero, default=10.0,
                        metavar="SECONDS",
                        help="start once something subscribes to the scans, waiting at most "
                             "this long (0 = start at once; default 10)")
    parser.add_argument("--lockstep", action="store_true",
                        help="after each scan wait until a command answers it (its scan_id), "
                             "as a lock-step server does, at most --lockstep-timeout: every "
                             "scan gets its command however slow the machine")
    parser.add_argument("--lockstep-timeout", type=arguments.seconds, default=1.0,
                        metavar="SECONDS",
                        help="with --lockstep: go on after this long without an answer "
                             "(default 1)")
    add_report_arguments(parser)


def _checked_robot(m: RecordedMessage, n: int, path) -> str:
    """The robot of a recorded sensor or world message whose topic is the plain key of a
    robot (``protocol.keys``: no wildcard, no empty chunk, nothing but the key the server
    publishes); ValueError naming the topic otherwise (a replay publishes on it)."""
    info = keys.parse(m.key)
    try:
        keys.check_chunk(info.robot, "its robot")
        plain = (keys.sim_request_key(info.robot, "get_world") if m.kind == "world"
                 else _PLAIN_KEY[m.kind](info.robot, info.index or 0))
    except ValueError as exc:
        raise ValueError(f"{path}: message {n} is on the topic {m.key!r}, not a robot's plain "
                         f"key: {exc}; refused (a replay publishes on the keys it reads)"
                         ) from None
    if plain != m.key:
        raise ValueError(f"{path}: message {n} is on the topic {m.key!r}, not a robot's plain "
                         f"key ({plain}); refused (a replay publishes on the keys it reads)")
    return info.robot


def sensor_messages(path, robots: list[str] | None = None, worlds: bool = False
                    ) -> Iterator[RecordedMessage]:
    """The sensor messages (``SENSOR_KINDS``, and the recorded worlds with ``worlds``) of
    ``robots`` (default every robot) in the order received, streamed from the file (one chunk
    in memory), each topic checked (``_checked_robot``). ValueError naming the file for a
    recording that is damaged or holds a topic that is not a plain key."""
    want = (*SENSOR_KINDS, "world") if worlds else SENSOR_KINDS
    checked: dict[str, str] = {}  # topic -> its robot, once checked
    try:
        for n, m in enumerate(read_recording(path)):
            if m.kind not in want:
                continue
            robot = checked.get(m.key)
            if robot is None:
                robot = checked[m.key] = _checked_robot(m, n, path)
            if not robots or robot in robots:
                yield m
    except RecordingError as exc:
        raise ValueError(str(exc)) from None


@dataclass
class ReplayPlan:
    """What a replay will play, found by reading the file once before any connection."""

    path: str
    robots: list[str]
    keys: set[str]
    messages: int
    worlds: dict[str, bytes] = field(default_factory=dict)  # robot -> WorldInfo payload
    span: float = 0.0  # recorded seconds played (gaps capped)
    capped: int = 0  # gaps longer than max_gap


def _gap(prev_ns: int | None, ns: int, max_gap: float) -> float:
    """Recorded seconds between two messages as played: >= 0 (a clock that stepped back
    plays at once), at most ``max_gap``."""
    if prev_ns is None:
        return 0.0
    return min(max(0.0, (ns - prev_ns) / 1e9), max_gap)


def plan_replay(path, robots: list[str] | None, max_gap: float) -> ReplayPlan:
    """Read the recording once (streamed): every topic checked, the robots, keys and worlds
    it holds. ValueError naming the file when it is no recording, is damaged, holds a topic
    that is not a plain key, or holds no sensor message."""
    plan = ReplayPlan(str(path), [], set(), 0)
    prev = None
    for m in sensor_messages(path, robots, worlds=True):
        robot = keys.parse(m.key).robot
        if m.kind == "world":
            plan.worlds[robot] = m.data
            continue
        plan.keys.add(m.key)
        plan.messages += 1
        if prev is not None and (m.log_time - prev) / 1e9 > max_gap:
            plan.capped += 1
        plan.span += _gap(prev, m.log_time, max_gap)
        prev = m.log_time
        if robot not in plan.robots:
            plan.robots.append(robot)
    if not plan.messages:
        raise ValueError(f"{path} holds no sensor messages"
                         f"{' of robot ' + ', '.join(robots) if robots else ''}")
    plan.robots.sort()
    return plan


def main(args: argparse.Namespace) -> int:
    plan = plan_replay(args.recording, args.robots, args.max_gap)  # before any connection
    # it holds a server's token (rhbl/alive/server/replay-<pid>), not one of its own
    return run_process("replay", args, lambda ctx: ReplayProcess(ctx, plan).run(),
                       early_token=False)


class ReplayProcess:
    """Publishers for the recorded keys, the recorded worlds served, the stream played (read
    from the file again as it plays: memory does not grow with the recording)."""

    def __init__(self, ctx: Context, plan: ReplayPlan):
        self.args, self.session, self.plan = ctx.args, ctx.session, plan
        for robot, data in plan.worlds.items():
            key = keys.sim_request_key(robot, "get_world")
            ctx.queryable(key, lambda q, key=key, data=data: self._answer(q, key, data))
        self.pubs: dict[str, zenoh.Publisher] = {
            key: ctx.publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            for key in sorted(plan.keys)}
        # a server's token per robot it serves (rhbl/alive/server/replay-<pid>/<robot>), as
        # rhbl server declares them: a console lists the robots a live server serves
        ident = keys.alive_key("server", f"replay-{os.getpid()}")
        for robot in plan.robots or [None]:
            ctx.keep(self.session.liveliness().declare_token(
                ident if robot is None else f"{ident}/{robot}"))
        self.robots = plan.robots
        self.answers = _Answers(self.session, self.robots) if self.args.lockstep else None
        self.sent = self.unanswered = 0
        self.played = 0.0  # recorded seconds played so far (gaps capped)
        self._prev_ns: int | None = None
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
        log.info("replaying %d messages of %s (robots %s) at %s%s", self.plan.messages,
                 self.args.recording, ", ".join(self.robots),
                 f"{self.args.speed:g}x" if self.args.speed else "full speed",
                 f"; {self.plan.capped} pauses longer than {self.args.max_gap:g} s played as "
                 f"{self.args.max_gap:g} s" if self.plan.capped else "")
        self.t0 = time.monotonic()
        for m in sensor_messages(self.args.recording, self.args.robots):
            if m.key in self.pubs:  # the file changed since it was checked: nothing new
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
        """Publish ``m`` at its recorded time (pauses capped at ``--max-gap``, scaled by
        ``--speed``); with ``--lockstep`` a scan then waits for its answer, and the recorded
        spacing goes on after it."""
        speed = self.args.speed
        self.played += _gap(self._prev_ns, m.log_time, self.args.max_gap)
        self._prev_ns = m.log_time
        if speed > 0:
            delay = self.t0 + self.played / speed - time.monotonic()
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
        log.info("replay stopped: %d of %d messages sent (%.1f s recorded, %.1f s played)",
                 self.sent, self.plan.messages, self.plan.span, time.monotonic() - self.t0)

    def counters(self) -> dict:
        return {"sent": self.sent, "messages": self.plan.messages,
                "unanswered": self.unanswered, "robots": self.robots}


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
