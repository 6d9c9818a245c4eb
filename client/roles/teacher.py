"""``rhbl teacher``: demonstrate a behaviour over zenoh (a scripted expert or keyboard teleop).

For every scan of the robot it publishes the executed velocity command on the per-source key
``.../cmd/vel/teacher`` (``source="teacher"``, ``scan_id`` set) and the demonstrated label on
``rhbl/<robot>/teacher/action`` (``TeacherAction``: the expert's choice for exactly that scan, and
the action executed, which differs while a perturbation runs).

    rhbl teacher --policy wall-follower --seconds 300     # scripted, perturbed demonstrations
    rhbl teacher --policy maze
    rhbl teacher --policy wall-follower --correct         # watch and correct (the controller drives)
    rhbl teacher --correct --demonstrate 60 --seconds 300 # demonstrate 60 s, then correct
    rhbl teacher --policy keyboard                        # a person at a terminal (arrows/WASD)
    rhbl teacher --policy keyboard --no-wait-learner      # pure teleop, nobody records

Nothing demonstrated is lost: before its first label the teacher waits (``--wait-learner-timeout``,
30 s; 0 = forever) for a learner's liveliness token ``rhbl/alive/learner/<robot>-<pid>``, which
a learner declares only once it subscribes to the labels; with no learner it exits with status 5.
When the last learner's token disappears while demonstrating (it stopped or crashed), the teacher
pauses (no commands, no labels: the server's watchdog stops the robot) and waits for a learner the
same way, or without a time limit while it holds labels no learner has acknowledged.

Nor is a label lost in flight when a learner is killed: each label carries the session's identity
(``origin``, a random id per process, and ``seq``, 0, 1, ...) and stays in the teacher's outbox
(``client.labels``: ``Outbox``, owned by ``LabelPublisher``) with the scan it answers until the learner
acknowledges it (``LearnerAck`` on ``rhbl/<robot>/learner/ack``: the labels in its
journal). Every unacknowledged label when a learner's token appears again, and a label missed
(unacknowledged after ``--resend-after``, 2 s, with backoff: ``Outbox``), is resent with its scan
on ``rhbl/<robot>/teacher/labeled`` (``LabeledScan``); the learner journals each label once. With ``--outbox`` (2000) labels
unacknowledged the teacher pauses as above rather than drop one. On exit it waits up to 10 s for
the last acknowledgements. The outbox lives in this process: a killed teacher loses the labels
not yet acknowledged. ``--no-wait-learner`` keeps no outbox.

Goals in order (``--behaviour`` of a behaviour with ``[goals]``, docs/goals.md): the teacher also
takes the fiducial message of each scan's tick; its goal state says when a goal is reached, and
each label carries the goal pursued, the goal reached at that scan and what the finder saw
(``TeacherAction``'s ``goal``, ``reached``, ``seen``). After the last goal it starts again with
the first, and so it does when the robot is put elsewhere (``client.behaviour.goals.Relocation``).

Correcting mode (``--correct``, the corrective (DAgger) rounds of the training recipe, Player
style "the teacher watches and corrects"): the controller drives; for every scan the teacher
publishes its label (the expert's choice, ``executed`` unset) but commands the robot only while
``client.behaviour.policies.takes_over`` says so (any beam closer than ``--takeover`` m: the
harness's rule), then with the label (``executed`` = the label). While it commands it also holds
the liveliness token ``rhbl/alive/teacher/<robot>-<pid>-hold`` and withdraws it when it stops
commanding: the server ends a teacher's hold when a teacher token disappears, so the controller
drives again on the very next tick instead of after the watchdog timeout.
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.given import behaviour_arg
from client.behaviour.goals import GoalExpert, Relocation
from client.behaviour.policies import STYLES, TAKEOVER, Demonstrator, takes_over
from client.behaviour.spec import behaviour
from client.behaviour.tasks import TASKS, make_policy, task_of_teacher
from client.labels import DRAIN, OUTBOX, RESEND_AFTER, Hold, LabelPublisher
from client.labels import SOURCE as LABEL_SOURCE
from client.player import PlayerClient
from client.roles.common import (
    ScanWatch,
    add_process_arguments,
    run_role,
    wait_for_learner,
    wait_for_server,
)
from process import arguments
from process.runtime import EXIT_USAGE, Context, ProcessError, uninterrupted
from protocol.messages import Scan

__all__ = ["TeacherProcess", "add_arguments", "main"]

log = logging.getLogger(__name__)

SOURCE = "teacher"
# scans kept for labelling in --correct mode (the oldest are dropped, counted and logged): a
# lock-step server runs at the controller's pace, ~10x real time, so 64 scans let the teacher be
# descheduled for ~0.6 s on a loaded machine without a state the controller visited going unlabelled
CORRECT_QUEUE = 64
# --policy: a task's scripted expert, or a person at the keyboard
POLICIES = (*(t.teacher for t in TASKS.values()), "keyboard")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    parser.add_argument("--policy", choices=POLICIES, default=None,
                        help="scripted expert of a task, or keyboard teleop (default: "
                             "wall-follower, or the expert of --behaviour)")
    parser.add_argument("--behaviour", default=None, type=behaviour_arg, metavar="NAME|FILE",
                        help="demonstrate this behaviour: its scripted expert with the "
                             "parameters of its file (a shipped behaviour's name or a "
                             "behaviour file; docs/behaviours.md); not with --policy")
    parser.add_argument("--seconds", type=arguments.seconds, default=None, metavar="S",
                        help="stop after demonstrating S seconds of sim time (default: until "
                             "stopped)")
    parser.add_argument("--perturb", type=arguments.fraction, default=0.05, metavar="P",
                        help="fraction of time a scripted demonstration executes a random action "
                             "(labels stay the expert's; 0 = off; default 0.05, the training "
                             "recipe measured in docs/experiments.md)")
    parser.add_argument("--seed", type=arguments.seed, default=0,
                        help="seed of the perturbations")
    parser.add_argument("--style", choices=STYLES, default="reactive",
                        help="scripted expert: 'reactive' (labels a function of the features; "
                             "the training recipe, default) or 'smooth' (the earlier teacher with "
                             "hysteresis and memory)")
    parser.add_argument("--correct", action="store_true",
                        help="watch and correct: label every scan but command the robot only "
                             "while a beam is closer than --takeover (the controller drives "
                             "otherwise); the corrective rounds of the training recipe")
    parser.add_argument("--demonstrate", type=arguments.seconds_or_zero, default=0.0, metavar="S",
                        help="with --correct: demonstrate (drive) for the first S seconds of sim "
                             "time, then correct (default 0)")
    parser.add_argument("--takeover", type=arguments.non_negative_float, default=TAKEOVER,
                        metavar="M",
                        help=f"with --correct: take over while any beam is closer than M metres "
                             f"(0 = never; default {TAKEOVER:g}, the training recipe)")
    parser.add_argument("--no-wait-learner", dest="wait_learner", action="store_false",
                        help="demonstrate without waiting for a learner (e.g. pure teleop); "
                             "labels published while no learner listens are lost (no outbox, "
                             "no resends)")
    parser.add_argument("--outbox", type=arguments.positive_int, default=OUTBOX, metavar="N",
                        help=f"labels kept until a learner acknowledges them (resent with their "
                             f"scan when unacknowledged); with N waiting the teacher pauses "
                             f"(default {OUTBOX})")
    parser.add_argument("--resend-after", type=arguments.seconds, default=RESEND_AFTER,
                        metavar="SECONDS",
                        help=f"resend a label (with its scan) not acknowledged after this long "
                             f"(default {RESEND_AFTER:g}); at once to a learner that (re)starts")
    parser.add_argument("--wait-learner-timeout", type=arguments.seconds_or_zero, default=30.0,
                        metavar="SECONDS",
                        help="how long to wait for a learner's liveliness token before "
                             "demonstrating; then exit with status 5 (0 = wait forever, "
                             "logging every few seconds; default: 30; a paused teacher "
                             "holding unacknowledged labels waits forever)")


def check(args: argparse.Namespace) -> None:
    """What the options say together, before any connection (ValueError: exit 2)."""
    if args.behaviour is not None and args.policy is not None:
        raise ValueError("--behaviour names the expert: give it or --policy, not both")
    if args.policy is None:
        args.policy = "wall-follower" if args.behaviour is None else \
            behaviour(args.behaviour).expert_name
    if args.correct and args.policy == "keyboard":
        raise ValueError("--correct needs a scripted expert (--policy wall-follower or maze), "
                         "not the keyboard")
    if args.demonstrate and not args.correct:
        raise ValueError("--demonstrate goes with --correct (demonstrate, then correct)")


def main(args: argparse.Namespace) -> int:
    return run_role("teacher", args, _body, check=lambda: check(args))


def _body(ctx: Context) -> int:
    demo = _demonstrator(ctx.args)
    close = getattr(demo, "close", None)
    if close:
        ctx.scope.callback(close)  # the keyboard restores the terminal
    return TeacherProcess(ctx, demo).run()


def _demonstrator(args: argparse.Namespace):
    if args.policy == "keyboard":
        from client.roles.keyboard import KeyboardPolicy

        return KeyboardPolicy(DEFAULT_ACTIONS)
    try:
        policy = (behaviour(args.behaviour).expert(args.style, DEFAULT_ACTIONS)
                  if args.behaviour is not None else
                  make_policy(task_of_teacher(args.policy), DEFAULT_ACTIONS, style=args.style))
        goals = None if args.behaviour is None else behaviour(args.behaviour).goals
        if goals is not None:  # goals in order: the seeker with the goal state it teaches
            policy = GoalExpert(goals, policy)
    except ValueError as exc:
        raise ProcessError(f"teacher: {exc}", EXIT_USAGE) from exc
    return Demonstrator(policy, perturb=args.perturb, rng=np.random.default_rng(args.seed))


class TeacherProcess:
    """For every scan: the demonstrator's label on ``rhbl/<robot>/teacher/action`` and, when it
    drives, the executed action's command on ``.../cmd/vel/teacher``."""

    def __init__(self, ctx: Context, demo):
        self.ctx, self.args, self.demo = ctx, ctx.args, demo
        robot = ctx.robot
        # the outbox (labels kept until acknowledged, resent) only when a learner records
        self.labels = LabelPublisher(
            ctx.session, robot, outbox=self.args.outbox if self.args.wait_learner else 0,
            resend_after=self.args.resend_after,
            # a person's labels at the keyboard say so: a learner's --teacher auto then
            # learns them by the person rule
            source="keyboard" if self.args.policy == "keyboard" else LABEL_SOURCE)
        ctx.scope.callback(self.labels.close)
        # commands on .../cmd/vel/teacher, express and never dropped
        self.client = PlayerClient(session=ctx.session, robot=robot, source=SOURCE,
                                   express=True, block=True)
        ctx.scope.callback(self.client.close)
        # the latest scan wins (a teacher never acts on a backlog); correcting, a short queue:
        # the server does not wait for a teacher that does not drive, and every state the
        # controller visits should get its label (a lock-step run only falls a scan or two behind)
        self.scans = self.client.scans(depth=CORRECT_QUEUE if self.args.correct else 1)
        self.learners = self.labels.learners  # None with --no-wait-learner
        self.hold = Hold(ctx.session, ctx.ident) if self.args.correct else None
        if self.hold is not None:
            ctx.scope.callback(self.hold.release)
        self.watch = ScanWatch("teacher", self.scans.key, stale=1.0)
        ctx.scope.callback(self.watch.stop)
        self.t0: float | None = None
        self.n = self.perturbed = self.took = self.bad = 0
        self.first_scan: int | None = None  # the scan the first label answered
        # a behaviour with goals: the fiducial finder's messages, each scan's labelled with the
        # goal pursued, the one reached and what was seen (docs/goals.md)
        policy = getattr(self.demo, "policy", None)
        self.goals = policy if isinstance(policy, GoalExpert) else None
        self.fiducials = self.client.fiducials() if self.goals is not None else None
        if self.fiducials is not None:
            ctx.scope.callback(self.fiducials.close)
        self.relocation = Relocation()
        self.reached = self.unseen = 0
        self.correcting = False
        self.last_id, self.missed = -1, 0  # correcting: scans dropped from the queue unlabelled
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)

    def run(self) -> int:
        wait_for_server(self.ctx)
        if self.learners is not None:
            self.wait_learner()
        else:
            log.info("not waiting for a learner (--no-wait-learner): labels go to whoever "
                     "listens")
        self.watch.start()
        while self.step():
            pass
        return 0

    def wait_learner(self, timeout: float | None = None) -> None:
        found = wait_for_learner(self.ctx, timeout)
        end = time.monotonic() + 2.0  # the subscriber sees the token too (normally at once)
        while not self.learners and time.monotonic() < end:
            time.sleep(0.01)
        if not self.learners:
            self.learners.add(found)
        # a scan kept from before the learner subscribed never reached it: its label could not
        # be paired. Skip it and start with the next scan.
        self.skip_stale()

    def skip_stale(self) -> None:
        """Scans that waited while the teacher could not label (before a learner subscribed,
        or paused) are skipped: their labels could not be paired. A demonstrating teacher
        answers the latest with a stop, so a lock-step server steps on at once rather than
        after its timeout (the scans stopped meanwhile; the watch would say so)."""
        stale = self.scans.latest()
        if stale is not None and not self.args.correct:
            self.client.answer(stale, 0.0, 0.0)
    def step(self) -> bool:
        """Answer the next scan; False when done (``--seconds``)."""
        scan = self.scans.recv()  # None: a malformed one (dropped, counted)
        self.watch.seen()
        if scan is None:
            return True
        if self.learners is not None and not self.learners:
            self.pause(scan)
            return True
        if self.labels.outbox is not None and self.labels.outbox.full:
            self.pause_full(scan)
            return True
        if not self.track(scan):
            return False
        goal = self.see_goals(scan)
        if goal is None:
            return True
        choice = self.choose(scan)
        if choice is not None:
            self.publish(scan, *choice, goal)
        return True

    def see_goals(self, scan: Scan) -> dict | None:
        """A behaviour with goals: what the fiducial finder saw at ``scan`` goes to the
        teacher's goal state (a goal may be reached: logged), and the label's ``goal``,
        ``reached`` and ``seen`` (``{}`` without goals). None: that tick's fiducial message did
        not come (nothing is known of the beacons: the scan is not labelled, the robot stands)."""
        if self.goals is None:
            return {}
        msg = self.fiducials.at(scan.id, timeout=1.0 if self.fiducials.latest else 0.2)
        if msg is None:
            self.unseen += 1
            if self.unseen <= 3 or self.unseen % 100 == 0:
                log.warning("scan %d: no fiducial message of its tick (%d so far): not "
                            "labelled (a behaviour with goals needs what the robot sees of "
                            "its beacons)", scan.id, self.unseen)
            if not self.correcting:
                self.client.answer(scan, 0.0, 0.0)
            return None
        if self.relocation.moved(msg):  # a new demonstration: from the first goal again
            self.goals.reset()
            log.info("the robot was put elsewhere at %.1f s: %s", scan.ts,
                     self.goals.tracker.describe())
        seen = {int(i.id): i for i in msg.items if i.id}  # (as the controller's, by id)
        before = self.goals.tracker.describe()
        goal, reached = self.goals.label_state(seen, scan.ts)
        if reached is not None:
            self.reached += 1
            log.info("%s: reached beacon %d at %.1f s; now %s", before, reached, scan.ts,
                     self.goals.tracker.describe())
        return {"goal": goal, "reached": reached, "seen": msg.items}

    def pause(self, scan: Scan) -> None:
        """The learner stopped or crashed: a label now would be lost. Stand still (now, not
        after the watchdog) and wait until a learner is up again."""
        log.warning("teacher: no learner of robot %s is up any more: pausing (no commands, no "
                    "labels)", self.ctx.robot)
        self.client.answer(scan, 0.0, 0.0)
        box = self.labels.outbox
        if box is not None and len(box):  # giving up would drop them: wait for a learner
            log.warning("teacher: %d labels unacknowledged: waiting for a learner without a "
                        "time limit (--wait-learner-timeout applies when none are)", len(box))
            self.wait_learner(timeout=0)
        else:
            self.wait_learner()
        self.last_id = -1  # the scans of the pause were skipped on purpose, not missed

    def pause_full(self, scan: Scan) -> None:
        """The outbox is full (the learner acknowledges nothing: stuck, or its journal cannot
        be written): a label now could not be kept. Stand still until acknowledgements come
        (the outbox resends meanwhile), or a learner is gone (then ``pause``)."""
        box = self.labels.outbox
        log.warning("teacher: %d labels wait for the learner's acknowledgement (--outbox %d): "
                    "pausing (no commands, no labels) until it acknowledges", len(box), box.cap)
        self.client.answer(scan, 0.0, 0.0)
        t0 = next_note = time.monotonic()
        while box.full and self.learners:
            time.sleep(0.05)
            if time.monotonic() >= next_note + 5.0:
                next_note = time.monotonic()
                log.warning("teacher: still paused: %d labels unacknowledged (%.0f s)",
                            len(box), next_note - t0)
        log.info("teacher: %d labels unacknowledged after %.1f s: demonstrating again",
                 len(box), time.monotonic() - t0)
        self.skip_stale()  # the scans of the pause
        self.last_id = -1

    def track(self, scan: Scan) -> bool:
        """Sim time, scans missed while correcting, the switch to correcting; False when done."""
        args = self.args
        if self.t0 is None:
            self.t0 = scan.ts
        elif self.correcting and self.last_id >= 0 and scan.id > self.last_id + 1:
            before = self.missed  # the queue overflowed
            self.missed += scan.id - self.last_id - 1
            if before == 0 or self.missed // 100 > before // 100:
                log.warning("teacher fell behind the controller: %d scans not labelled so far",
                            self.missed)
        self.last_id = scan.id
        if args.seconds is not None and scan.ts - self.t0 >= args.seconds:
            log.info("demonstrated %.1f s of sim time: done", scan.ts - self.t0)
            return False
        if args.correct and not self.correcting and scan.ts - self.t0 >= args.demonstrate:
            self.correcting = True
            log.info("correcting from %.1f s of sim time: the controller drives, the teacher "
                     "labels every scan and takes over while a beam is closer than %g m",
                     scan.ts - self.t0, args.takeover)
        return True

    def choose(self, scan: Scan) -> tuple[str, str | None, tuple[float, float]] | None:
        """(label, executed action or None, its velocity), or None when there is nothing to
        demonstrate."""
        try:
            if self.correcting:
                # the expert's choice on the state the controller put the robot in; the wheels
                # only when the harness's takeover rule says so
                label = self.demo.policy.act(scan.ranges, scan.pose)
                executed = label if takes_over(scan.ranges, self.args.takeover) else None
            else:
                label, executed = self.demo.step(scan.ranges, scan.pose)
            vel = DEFAULT_ACTIONS[executed] if label is not None and executed else (0.0, 0.0)
        except Exception as exc:  # noqa: BLE001 - a scan the policy cannot use
            self.bad += 1
            if self.bad <= 10 or self.bad % 100 == 0:
                log.warning("scan %d not demonstrated (%d so far): %s: %s", scan.id, self.bad,
                            type(exc).__name__, exc)
            return None
        return None if label is None else (label, executed, vel)  # keyboard: nothing pressed

    def publish(self, scan: Scan, label: str, executed: str | None,
                vel: tuple[float, float], goal: dict | None = None) -> None:
        if self.n == 0:
            self.first_scan = scan.id
            log.info("first label: scan %d, %s", scan.id, label)
        if executed is not None:
            vx, va = vel
            if self.hold is not None:
                self.hold.acquire()  # before the command: the server may release at once
            self.client.answer(scan, vx, va)
        elif self.hold is not None:
            self.hold.release()  # the controller drives from the next tick on
        with uninterrupted():  # a stop does not leave a label sent and uncounted
            self.labels.label(scan, label, executed, **{
                k: v for k, v in (goal or {}).items() if v is not None})
            self.n += 1
        if self.correcting:
            self.took += executed is not None
        else:
            self.perturbed += executed != label
        if self.n % 500 == 0:
            log.info("%d labels, %.0f s sim, %.0f%% perturbed, %d taken over", self.n,
                     scan.ts - self.t0, 100.0 * self.perturbed / self.n, self.took)

    def close(self) -> None:
        self.watch.stop()
        if self.hold is not None:
            self.hold.release()
        self.labels.drain(DRAIN)
        box = self.labels.outbox
        log.info("teacher stopped after %d labels (%d perturbed, %d taken over)%s%s", self.n,
                 self.perturbed, self.took,
                 f"; {self.missed} scans not labelled (fell behind)" if self.missed else "",
                 "" if box is None else
                 f"; {box.stats['resent']} resends, {len(box)} unacknowledged at exit")

    def counters(self) -> dict:
        box = self.labels.outbox
        return {"labels": self.n, "first_label_scan": self.first_scan,
                "perturbed": self.perturbed, "taken_over": self.took,
                "missed": self.missed, "not_demonstrated": self.bad,
                "goals_reached": self.reached, "no_fiducial": self.unseen,
                "handbacks": 0 if self.hold is None else self.hold.handbacks,
                "outbox": None if box is None else {**box.stats, "unacknowledged": len(box)},
                "dropped": {**self.client.decoder.counts, **self.labels.decoder.counts}}
