"""``rhbl record``: keep every message of the robots' keys in an MCAP file (Player's
``writelog``, a ROS bag). docs/recording.md describes the file.

    rhbl record --out run.mcap                      # every robot it sees, until Ctrl-C
    rhbl record --out run.mcap --robot r0 --duration 120
    rhbl record --ros2 --out bag.mcap               # ROS 2 messages (client.ros2.bag)

It needs no server: started before one, it waits for a router to connect to (``--wait-router``,
forever by default, logging what it waits for) and records from then on. ``--out`` and the
other options are checked before any connection. SIGINT/SIGTERM finish the file (summary and
indexes); a SIGKILL leaves every message up to the last chunk (closed every second) readable.
A full disk stops it with one clear error (exit 1); what was written stays readable.
"""

from __future__ import annotations

import argparse
import logging
import os
import time

from client.recording.mcap_file import CHUNK_SECONDS, RecordingError, RecordingWriter
from client.recording.tap import BusTap
from client.ros2.bag import Ros2Recording
from client.ros2.nodes import Ros2Options, add_ros2_arguments
from process import arguments, files
from process.runtime import (
    EXIT_FAILURE,
    EXIT_USAGE,
    Context,
    ProcessError,
    add_report_arguments,
    run_process,
)
from process.session import add_zenoh_arguments
from protocol import keys
from protocol.messages import LaserConfig

__all__ = ["RecordProcess", "add_arguments", "check_out", "demo_recording", "main",
           "say_demo_recording"]

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--out", required=True, metavar="FILE", type=arguments.output_file,
                        help="the MCAP file to write (refused if it exists, unless --overwrite; "
                             "a regular file or a new one only)")
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        type=arguments.key_chunk,
                        help="record this robot's keys (repeatable; default: every robot seen)")
    parser.add_argument("--duration", type=arguments.seconds, default=None, metavar="SECONDS",
                        help="stop after this many seconds of recording (wall time; default: "
                             "until stopped)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.add_argument("--no-viewer", action="store_true",
                        help="only the bus messages, no Foxglove viewer channels")
    parser.add_argument("--chunk-seconds", type=arguments.seconds, default=CHUNK_SECONDS,
                        metavar="S",
                        help=f"close a chunk at least this often (default {CHUNK_SECONDS:g}): "
                             f"what a killed recorder can lose at most")
    parser.add_argument("--ros2", action="store_true",
                        help="write the robots' scans and states as ROS 2 messages (MCAP, ROS 2 "
                             "profile: ros2 bag, Foxglove's ROS 2 view): the topics rhbl ros2 "
                             "publishes (docs/ros2.md)")
    add_ros2_arguments(parser, bridge=True, when="with --ros2", domain=False)
    parser.add_argument("--wait-router", type=arguments.seconds_or_zero, default=0.0,
                        metavar="SECONDS",
                        help="while nothing listens on the --connect endpoints (no server or "
                             "router up yet), try again for this long (0 = forever, the "
                             "default)")
    add_report_arguments(parser)


def check_out(path: str | os.PathLike, overwrite: bool) -> None:
    """ValueError unless ``path`` can be the new recording: a regular file or a new one
    (``process.files``: never a device, a FIFO, a socket or a folder), not an existing file
    unless ``overwrite``; its folder is made."""
    target = files.check_output(path, "--out")
    if target.exists() and not overwrite:
        raise ValueError(f"--out {path} exists: choose another file or pass --overwrite (a "
                         f"recording is never replaced silently)")


def main(args: argparse.Namespace) -> int:
    def check() -> None:
        if args.ros2:
            options = Ros2Options.from_args(args)
            for r in args.robots or []:
                options.topics(r)
            if args.no_viewer:
                raise ValueError("--no-viewer: only without --ros2 (a ROS 2 recording has no "
                                 "viewer channels)")
        elif Ros2Options.given(args):
            raise ValueError(f"{', '.join(Ros2Options.given(args))}: only with --ros2")
        check_out(args.out, args.overwrite)

    check()  # a ValueError is one line, exit 2, before anything is opened (lab.cli)
    name = "all" if not args.robots else args.robots[0]  # in its liveliness token
    return run_process("recorder", args, lambda ctx: RecordProcess(ctx).run(),
                       ident=f"{name}-{os.getpid()}", wait_router=args.wait_router)


class RecordProcess:
    """The bus tap feeding one ``RecordingWriter`` until ``--duration``, a stop signal or a
    failure to write; its counters go to ``--stats``."""

    def __init__(self, ctx: Context):
        args = self.args = ctx.args
        self.session = ctx.session
        try:
            self.writer = self.open_writer()
        except RecordingError as exc:
            raise ProcessError(f"recorder: {exc}", EXIT_USAGE) from exc
        self.tap = BusTap(ctx.session, self.writer, robots=args.robots)
        self.error: RecordingError | None = None
        self.closed = False
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)
        log.info("recording %s to %s", ", ".join(args.robots) if args.robots else "every robot",
                 args.out)

    def open_writer(self) -> RecordingWriter | Ros2Recording:
        """The sink the tap feeds: the bus as it is, or with --ros2 its ROS 2 messages."""
        args = self.args
        if args.ros2:
            return Ros2Recording(args.out, Ros2Options.from_args(args), self.scan_time,
                                 overwrite=args.overwrite, chunk_seconds=args.chunk_seconds)
        return RecordingWriter(args.out, overwrite=args.overwrite, viewer=not args.no_viewer,
                               recorder="rhbl record", chunk_seconds=args.chunk_seconds,
                               metadata={"robots": ",".join(args.robots or ["*"])})

    def scan_time(self, robot: str) -> float:
        """--ros2: seconds between the robot's scans (its laser's get_config; 0 if unknown)."""
        try:
            for reply in self.session.get(keys.request_key(robot, "laser", "get_config"),
                                          timeout=1.0):
                if reply.ok is not None:
                    rate = LaserConfig.decode(reply.ok.payload.to_bytes()).rate
                    return 1.0 / rate if rate > 0 else 0.0
        except Exception as exc:  # noqa: BLE001 - a replay has no laser to ask
            log.debug("no laser configuration of robot %s: %s", robot, exc)
        return 0.0

    def run(self) -> int:
        t0 = last_note = time.monotonic()
        while not self.tap.failed:
            if self.args.duration is not None and time.monotonic() - t0 >= self.args.duration:
                log.info("recorded %.0f s: done", self.args.duration)
                break
            time.sleep(0.1)
            if time.monotonic() - last_note >= 10.0:
                last_note = time.monotonic()
                log.info("%d messages recorded (robots %s)", self.writer.messages,
                         ", ".join(sorted(self.tap.seen_robots)) or "none yet")
        return EXIT_FAILURE if self.close() is not None else 0

    def close(self) -> RecordingError | None:
        """Stop the tap and finish the file (once); the error that stopped the recording."""
        if not self.closed:
            self.closed = True
            self.tap.close()
            self.error = self.tap.error(self.writer)
            w, out = self.writer, self.args.out
            log.info("recorder stopped: %d messages on %d keys in %s (%.1f MB); at most %d "
                     "received messages waited to be written%s", w.messages, len(w.counts),
                     out, os.path.getsize(out) / 1e6 if os.path.exists(out) else 0.0,
                     self.tap.max_backlog, "" if self.error is None else "; FAILED")
        return self.error

    def counters(self) -> dict:
        w = self.writer
        extra = {"skipped_robots": w.skipped} if isinstance(w, Ros2Recording) else {}
        return {**extra, "messages": w.messages, "keys": len(w.counts),
                "robots": sorted(self.tap.seen_robots), "max_backlog": self.tap.max_backlog,
                "failed": None if self.error is None else str(self.error)}


# ---- rhbl demo --record --------------------------------------------------------------------
def demo_recording(record: str | None, out_dir, say=print) -> RecordingWriter | None:
    """``rhbl demo --record [FILE]``: the writer of the demo's recording (default
    ``OUT/run.mcap``), a sink for the demo's bus tap; None when not asked. ValueError when the
    file cannot be created."""
    if record is None:
        return None
    path = record or os.path.join(out_dir, "run.mcap")
    try:
        writer = RecordingWriter(path, overwrite=True, recorder="rhbl demo")
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    say(f"recording every bus message into {path}")
    return writer


def say_demo_recording(tap: BusTap, writer: RecordingWriter | None, say=print) -> None:
    """The demo's last word on its recording (after ``tap.close()``)."""
    if writer is None:
        return
    err = tap.error(writer)
    say(f"recording: {writer.messages} messages on {len(writer.counts)} keys in {writer.path}"
        + (f"; FAILED: {err}" if err else ""))
