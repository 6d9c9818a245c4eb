"""``rhbl record``: keep every message of the robots' keys in an MCAP file (Player's
``writelog``, a ROS bag). docs/recording.md describes the file.

    rhbl record --out run.mcap                      # every robot it sees, until Ctrl-C
    rhbl record --out run.mcap --robot r0 --duration 120

SIGINT/SIGTERM finish the file (summary and indexes); a SIGKILL leaves every message up to
the last chunk (closed every second) readable. A full disk stops it with one clear error
(exit 1); what was written stays readable.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time

from client.recording.mcap_file import CHUNK_SECONDS, BusRecorder, RecordingError, RecordingWriter
from client.roles.common import run_role
from protocol import keys
from protocol.runtime import EXIT_FAILURE, EXIT_USAGE, Context, ProcessError, add_logging_arguments
from protocol.session import add_zenoh_arguments

__all__ = ["add_arguments", "finish_demo_recording", "main", "start_demo_recording",
           "start_recording"]

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_zenoh_arguments(parser)
    parser.add_argument("--out", required=True, metavar="FILE",
                        help="the MCAP file to write (refused if it exists, unless --overwrite)")
    parser.add_argument("--robot", action="append", dest="robots", metavar="NAME",
                        help="record this robot's keys (repeatable; default: every robot seen)")
    parser.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                        help="stop after this many seconds (wall time; default: until stopped)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.add_argument("--no-viewer", action="store_true",
                        help="only the bus messages, no Foxglove viewer channels")
    parser.add_argument("--chunk-seconds", type=float, default=CHUNK_SECONDS, metavar="S",
                        help=f"close a chunk at least this often (default {CHUNK_SECONDS:g}): "
                             f"what a killed recorder can lose at most")
    add_logging_arguments(parser)


def start_recording(session, out, robots=None, overwrite: bool = False, viewer: bool = True,
                    recorder: str = "rhbl record", chunk_seconds: float = CHUNK_SECONDS,
                    metadata: dict | None = None) -> BusRecorder:
    """Record a session's bus into ``out`` until ``.close()`` (``rhbl record``, ``rhbl demo
    --record``). Raises RecordingError (the file cannot be created)."""
    writer = RecordingWriter(out, overwrite=overwrite, viewer=viewer, recorder=recorder,
                             chunk_seconds=chunk_seconds, metadata=metadata)
    return BusRecorder(session, writer, robots=robots)


def start_demo_recording(session, record: str | None, out_dir, say=print) -> BusRecorder | None:
    """``rhbl demo --record [FILE]``: record the demo's rendezvous (default ``OUT/run.mcap``);
    None when not asked."""
    if record is None:
        return None
    path = record or os.path.join(out_dir, "run.mcap")
    try:
        rec = start_recording(session, path, overwrite=True, recorder="rhbl demo")
    except RecordingError as exc:
        raise ValueError(str(exc)) from None
    say(f"recording every bus message into {path}")
    return rec


def finish_demo_recording(rec: BusRecorder | None, say=print) -> None:
    if rec is None:
        return
    err = rec.close()
    w = rec.writer
    say(f"recording: {w.messages} messages on {len(w.counts)} keys in {w.path}"
        + (f"; FAILED: {err}" if err else ""))


def main(args: argparse.Namespace) -> int:
    for r in args.robots or []:
        try:
            keys.check_chunk(r, "--robot")
        except ValueError as exc:
            print(f"rhbl record: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    if args.duration is not None and not args.duration > 0:
        print("rhbl record: error: --duration must be > 0", file=sys.stderr)
        return EXIT_USAGE
    args.robot = "all" if not args.robots else args.robots[0]  # the liveliness token's name
    return run_role("recorder", args, _body)


def _body(ctx: Context) -> int:
    args = ctx.args
    try:
        rec = start_recording(ctx.session, args.out, args.robots, args.overwrite,
                              not args.no_viewer, chunk_seconds=args.chunk_seconds,
                              metadata={"robots": ",".join(args.robots or ["*"])})
    except RecordingError as exc:
        raise ProcessError(f"recorder: {exc}", EXIT_USAGE) from exc
    log.info("recording %s to %s", ", ".join(args.robots) if args.robots else "every robot",
             args.out)
    t0 = time.monotonic()
    last_note = t0
    try:
        while not rec.failed:
            if args.duration is not None and time.monotonic() - t0 >= args.duration:
                log.info("recorded %.0f s: done", args.duration)
                break
            time.sleep(0.1)
            if time.monotonic() - last_note >= 10.0:
                last_note = time.monotonic()
                log.info("%d messages recorded (robots %s)", rec.writer.messages,
                         ", ".join(sorted(rec.seen_robots)) or "none yet")
    finally:
        err = rec.close()
        w = rec.writer
        log.info("recorder stopped: %d messages on %d keys in %s (%.1f MB); at most %d "
                 "received messages waited to be written%s", w.messages, len(w.counts),
                 args.out, os.path.getsize(args.out) / 1e6 if os.path.exists(args.out) else 0.0,
                 rec.max_backlog, "" if err is None else "; FAILED")
    return EXIT_FAILURE if err is not None else 0
