"""``rhbl controller``: drive the robot with a learned tree over zenoh.

For every scan it extracts the features the tree was trained with (from the snapshot's metadata),
classifies them with ``predict_one`` and publishes the action's velocity on ``.../cmd/vel/controller``
(``source="controller"``, ``scan_id`` set). It only acts on scans: when scans stop it stops
commanding (and logs it), and the server's watchdog stops the robot.

    rhbl controller --tree tree.rhbl
    rhbl controller --from-learner --follow     # fetch the learner's tree, swap in newer ones
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import threading
import time

import zenoh

from client._process import (
    EXIT_NO_SERVER,
    EXIT_USAGE,
    Context,
    ProcessError,
    ScanWatch,
    add_process_arguments,
    run,
    wait_for_server,
)
from client.behaviour.actions import ActionSet
from client.behaviour.features import FEATURES, FeatureSpec
from client.behaviour.learning import IncompatibleSnapshotError, TreePolicy, check_compatible
from client.decision import Decider
from protocol import keys
from protocol.messages import Scan, TreeNotice, VelCmd

__all__ = ["add_arguments", "fetch_snapshot", "load_tree", "main"]

log = logging.getLogger(__name__)

SOURCE = "controller"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--tree", metavar="PATH", help="a snapshot written by the learner")
    src.add_argument("--from-learner", action="store_true",
                     help="fetch the learner's latest snapshot with a zenoh query")
    parser.add_argument("--follow", action="store_true",
                        help="with --from-learner: swap in each newer tree the learner announces")
    parser.add_argument("--features", choices=sorted(FEATURES),
                        help="expected feature specification (a tree trained otherwise is an error)")
    parser.add_argument("--seconds", type=float, default=None, metavar="S",
                        help="stop after driving S seconds of sim time (default: until stopped)")
    parser.add_argument("--query-timeout", type=float, default=5.0, metavar="SECONDS",
                        help="how long to wait for the learner's snapshot (default 5)")


def main(args: argparse.Namespace) -> int:
    return run("controller", args, _body)


def _policy_from(clf_bytes_or_path, features: str | None) -> TreePolicy:
    from rhbl import load, loads

    try:
        if isinstance(clf_bytes_or_path, bytes | bytearray):
            clf = loads(bytes(clf_bytes_or_path), source="learner snapshot")
        else:
            clf = load(clf_bytes_or_path)
        meta = dict(clf.metadata or {})
        check_compatible(meta, FEATURES[features] if features else None)
    except IncompatibleSnapshotError as exc:
        raise ProcessError(f"controller: {exc}", EXIT_USAGE) from exc
    except FileNotFoundError as exc:
        raise ProcessError(f"controller: snapshot {clf_bytes_or_path} does not exist",
                           EXIT_USAGE) from exc
    except Exception as exc:  # rhbl.SnapshotError
        raise ProcessError(f"controller: cannot load the tree: {exc}", EXIT_USAGE) from exc
    return TreePolicy(clf, FeatureSpec.from_dict(meta["features"]),
                      ActionSet.from_dict(meta["actions"]), meta)


def load_tree(path: str, features: str | None = None) -> TreePolicy:
    """A snapshot file as a policy (its metadata's features/actions; checked against ``features``)."""
    return _policy_from(path, features)


def fetch_snapshot(session: zenoh.Session, robot: str, timeout: float = 5.0) -> bytes:
    """The learner's latest snapshot bytes (ProcessError when no learner answers)."""
    key = keys.learner_snapshot_key(robot)
    errors = []
    for reply in session.get(key, timeout=timeout):
        if reply.ok is not None:
            return reply.ok.payload.to_bytes()
        errors.append(reply.err.payload.to_bytes().decode("utf-8", "replace"))
    if errors:
        raise ProcessError(f"controller: the learner has no tree to give yet ({'; '.join(errors)})",
                           EXIT_NO_SERVER)
    raise ProcessError(f"controller: no learner answered on {key} within {timeout:g} s "
                       f"(is `rhbl learner` running for robot {robot!r}?)", EXIT_NO_SERVER)


def _describe(p: TreePolicy) -> str:
    c = p.classifier
    return (f"{getattr(c, 'node_count_', '?')} nodes, height {getattr(c, 'height_', '?')}, "
            f"{(p.metadata.get('provenance') or {}).get('vectors', '?')} vectors")


def _body(ctx: Context) -> int:
    args, session, robot = ctx.args, ctx.session, ctx.robot
    if args.follow and not args.from_learner:
        raise ProcessError("controller: --follow needs --from-learner", EXIT_USAGE)
    if args.tree:
        policy = load_tree(args.tree, args.features)
    else:
        policy = _policy_from(fetch_snapshot(session, robot, args.query_timeout), args.features)
    log.info("tree loaded: %s; features %s", _describe(policy), policy.features.to_dict())
    current = {"policy": policy}
    updater = None
    if args.follow:
        updater = _Follower(session, robot, args, current)
    cmd_pub = session.declare_publisher(keys.cmd_vel_key(robot, source=SOURCE),
                                        congestion_control=zenoh.CongestionControl.BLOCK,
                                        express=True)
    scan_k = keys.scan_key(robot)
    sub = session.declare_subscriber(scan_k, zenoh.handlers.RingChannel(1))
    wait_for_server(ctx)
    watch = ScanWatch("controller", scan_k, stale=1.0).start()
    decider = Decider(session, robot)
    t0 = None
    n = 0
    bad = 0
    try:
        while True:
            sample = sub.handler.recv()
            watch.seen()
            try:
                scan = Scan.decode(sample.payload.to_bytes())
            except Exception as exc:  # noqa: BLE001 - DecodeError: log and keep running
                log.warning("dropped a malformed scan: %s", exc)
                continue
            if t0 is None:
                t0 = scan.ts
            if args.seconds is not None and scan.ts - t0 >= args.seconds:
                log.info("drove %.1f s of sim time: done", scan.ts - t0)
                break
            p = current["policy"]  # swapped between scans by --follow
            try:
                action = decider.decide(p, scan)  # classify, publish the decision
                vx, va = p.actions[action]
            except Exception as exc:  # noqa: BLE001 - a scan the tree cannot use: no command
                bad += 1
                if bad <= 10 or bad % 100 == 0:
                    log.warning("scan %d not answered (%d so far; the watchdog stops the "
                                "robot): %s: %s", scan.id, bad, type(exc).__name__, exc)
                continue
            cmd_pub.put(VelCmd(vx=vx, va=va, source=SOURCE, scan_id=scan.id, ts=scan.ts).encode())
            n += 1
            if n % 1000 == 0:
                log.info("%d commands, %.0f s sim", n, scan.ts - t0)
    finally:
        watch.stop()
        if updater is not None:
            updater.stop()
        log.info("controller stopped after %d commands", n)
    return 0


class _Follower:
    """Subscribes to tree notices; fetches the newer snapshot in a thread and swaps it in."""

    def __init__(self, session, robot, args, current):
        self.session, self.robot, self.args, self.current = session, robot, args, current
        self._want = threading.Event()
        self._stop = threading.Event()
        self.seen_seq = -1
        self.swaps = 0
        self._sub = session.declare_subscriber(keys.learner_notice_key(robot), self._on_notice)
        self._thread = threading.Thread(target=self._loop, name="controller-follow", daemon=True)
        self._thread.start()

    def _on_notice(self, sample) -> None:
        try:
            note = TreeNotice.decode(sample.payload.to_bytes())
        except Exception as exc:  # noqa: BLE001
            log.warning("dropped a malformed tree notice: %s", exc)
            return
        log.debug("tree notice %s", note)
        self._want.set()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if not self._want.wait(0.2):
                continue
            self._want.clear()
            try:
                data = fetch_snapshot(self.session, self.robot, self.args.query_timeout)
                policy = _policy_from(data, self.args.features)
            except ProcessError as exc:
                log.warning("could not swap the tree: %s", exc)
                continue
            except Exception as exc:  # noqa: BLE001 - the session closing under us
                if not self._stop.is_set():
                    log.warning("could not swap the tree: %s", exc)
                continue
            self.current["policy"] = policy
            self.swaps += 1
            log.info("swapped in a newer tree: %s", _describe(policy))
            time.sleep(0.0)

    def stop(self) -> None:
        self._stop.set()
        with contextlib.suppress(Exception):
            self._sub.undeclare()
