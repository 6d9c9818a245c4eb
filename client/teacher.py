"""``rhbl teacher``: demonstrate a behaviour over zenoh (a scripted expert or keyboard teleop).

For every scan of the robot it publishes the executed velocity command on the per-source key
``.../cmd/vel/teacher`` (``source="teacher"``, ``scan_id`` set) and the demonstrated label on
``rhbl/<robot>/teacher/action`` (``TeacherAction``: the expert's choice for exactly that scan, and
the action executed, which differs while a perturbation runs).

    rhbl teacher --policy wall-follower --seconds 300     # scripted, perturbed demonstrations
    rhbl teacher --policy maze
    rhbl teacher --policy keyboard                        # a person at a terminal (arrows/WASD)
    rhbl teacher --policy keyboard --no-wait-learner      # pure teleop, nobody records

Nothing demonstrated is lost: before its first label the teacher waits (``--wait-learner-timeout``,
30 s; 0 = forever) for a learner's liveliness token ``rhbl/alive/learner/<robot>-<pid>``, which
a learner declares only once it subscribes to the labels; with no learner it exits with status 5.
"""

from __future__ import annotations

import argparse
import logging

import numpy as np
import zenoh

from client._process import (
    EXIT_USAGE,
    Context,
    ProcessError,
    ScanWatch,
    add_process_arguments,
    run,
    wait_for_learner,
    wait_for_server,
)
from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.policies import Demonstrator, make_policy
from protocol import keys
from protocol.messages import Scan, TeacherAction, VelCmd

__all__ = ["POLICIES", "add_arguments", "main"]

log = logging.getLogger(__name__)

SOURCE = "teacher"
# --policy name -> the behaviour package's task name
POLICIES = {"wall-follower": "wall-following", "maze": "maze", "keyboard": None}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    parser.add_argument("--policy", choices=list(POLICIES), default="wall-follower",
                        help="scripted expert of a task, or keyboard teleop")
    parser.add_argument("--seconds", type=float, default=None, metavar="S",
                        help="stop after demonstrating S seconds of sim time (default: until "
                             "stopped)")
    parser.add_argument("--perturb", type=float, default=0.05, metavar="P",
                        help="fraction of time a scripted demonstration executes a random action "
                             "(labels stay the expert's; 0 = off; default 0.05, the training "
                             "recipe measured in docs/experiments.md)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the perturbations")
    parser.add_argument("--no-wait-learner", dest="wait_learner", action="store_false",
                        help="demonstrate without waiting for a learner (e.g. pure teleop); "
                             "labels published while no learner listens are lost")
    parser.add_argument("--wait-learner-timeout", type=float, default=30.0, metavar="SECONDS",
                        help="how long to wait for a learner's liveliness token before "
                             "demonstrating; then exit with status 5 (0 = wait forever, "
                             "logging every few seconds; default: 30)")


def main(args: argparse.Namespace) -> int:
    return run("teacher", args, _body)


def _body(ctx: Context) -> int:
    args = ctx.args
    if args.policy == "keyboard":
        from client.keyboard import KeyboardPolicy

        demo = KeyboardPolicy(DEFAULT_ACTIONS)
    else:
        try:
            policy = make_policy(POLICIES[args.policy], DEFAULT_ACTIONS)
        except ValueError as exc:
            raise ProcessError(f"teacher: {exc}", EXIT_USAGE) from exc
        demo = Demonstrator(policy, perturb=args.perturb, rng=np.random.default_rng(args.seed))
    try:
        return _loop(ctx, demo)
    finally:
        close = getattr(demo, "close", None)
        if close:
            close()


def _loop(ctx: Context, demo) -> int:
    args, session, robot = ctx.args, ctx.session, ctx.robot
    cmd_pub = session.declare_publisher(keys.cmd_vel_key(robot, source=SOURCE),
                                        congestion_control=zenoh.CongestionControl.BLOCK,
                                        express=True)
    act_pub = session.declare_publisher(keys.teacher_action_key(robot),
                                        congestion_control=zenoh.CongestionControl.BLOCK)
    scan_k = keys.scan_key(robot)
    sub = session.declare_subscriber(scan_k, zenoh.handlers.RingChannel(1))
    wait_for_server(ctx)
    if args.wait_learner:
        wait_for_learner(ctx)
        # a scan kept from before the learner subscribed never reached it: its label could not
        # be paired. Drop it and start with the next scan.
        while sub.handler.try_recv() is not None:
            pass
    else:
        log.info("not waiting for a learner (--no-wait-learner): labels go to whoever listens")
    watch = ScanWatch("teacher", scan_k, stale=1.0).start()
    actions = DEFAULT_ACTIONS
    t0 = None
    n = 0
    perturbed = 0
    try:
        while True:
            sample = sub.handler.recv()
            watch.seen()
            try:
                scan = Scan.decode(sample.payload.to_bytes())
            except Exception as exc:  # noqa: BLE001 - DecodeError: count, log, keep running
                log.warning("dropped a malformed scan: %s", exc)
                continue
            if t0 is None:
                t0 = scan.ts
            if args.seconds is not None and scan.ts - t0 >= args.seconds:
                log.info("demonstrated %.1f s of sim time: done", scan.ts - t0)
                break
            label, executed = demo.step(scan.ranges, scan.pose)
            if label is None:  # keyboard: nothing pressed yet
                continue
            vx, va = actions[executed]
            if n == 0:
                log.info("first label: scan %d, %s", scan.id, label)
            cmd_pub.put(VelCmd(vx=vx, va=va, source=SOURCE, scan_id=scan.id, ts=scan.ts).encode())
            act_pub.put(TeacherAction(scan_id=scan.id, action=label, source=SOURCE, ts=scan.ts,
                                      executed=executed).encode())
            n += 1
            perturbed += executed != label
            if n % 500 == 0:
                log.info("%d labels, %.0f s sim, %.0f%% perturbed", n, scan.ts - t0,
                         100.0 * perturbed / n)
    finally:
        watch.stop()
        log.info("teacher stopped after %d labels (%d perturbed)", n, perturbed)
    return 0
