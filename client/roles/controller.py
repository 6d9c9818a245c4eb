"""``rhbl controller``: drive the robot with a learned tree over zenoh.

For every scan it extracts the features the tree was trained with (from the snapshot's metadata),
classifies them with ``predict_one`` and publishes the action's velocity on ``.../cmd/vel/controller``
(``source="controller"``, ``scan_id`` set). It only acts on scans: when scans stop it stops
commanding (and logs it), and the server's watchdog stops the robot.

    rhbl controller --tree tree.rhbl
    rhbl controller --from-learner --follow     # fetch the learner's tree, swap in newer ones

With ``--follow`` the starting order does not matter: started before the learner (or before its
first snapshot) it waits for the first tree (``--wait-tree``, forever by default), then drives.

The tree's actions go through the guard its learning rule says (a safety layer,
``client.behaviour.guard.RotationGuard``; the snapshot's ``client.behaviour.rule.GuardSettings``,
read again for every tree swapped in; ``--no-guard`` drives the tree's answers as they are, the
other ``--guard-*`` options replace one part): an order to rotate the other way within 5 scans
of a rotation is overruled (the robot keeps turning as it was, for at most ``--guard-hold``
scans in a row), so the robot does not bounce between a rot-left and a rot-right sphere for
ever; every overruled reversal is counted (``--stats``: ``overruled``) and logged at a bounded
rate; and, with the rule's path check (a tree taught by hand: 0.3 m; ``--guard-clearance M``
for any tree), a forward order while a laser return lies in the robot's path (within 0.5 m
ahead and 0.3 m of its centre line) becomes a rotation in place (``--stats``: ``avoided``), and
an overruled reversal drives straight on while that path is clear (``--stats``:
``straight_on``; ``--no-guard-straight``: keep turning; docs/teaching.md has the study behind
all three). Its
decisions (``Decision``, for viewers) say when the guard stepped in lately on a reversal
(``looping``) and what it commanded instead of the tree's (``executed``): ``rhbl console``
then asks the person to show the robot the way out; a tree with goals, the goal pursued and why
the last goal changed (``goal``, ``goal_why``).

A tree with goals in order (docs/goals.md) takes the fiducial message of each scan's tick and
ends once every goal is reached; with ``--goals-again`` it stands still then instead, and pursues
the goals from the first again whenever the robot is put elsewhere (what ``rhbl demo`` runs
from each start pose); ``--follow`` swaps in a newer tree with the goal being pursued kept.

With ``--ros2`` it drives a ROS 2 robot instead (``client.ros2.nodes.Ros2Robot``, docs/ros2.md): its
``LaserScan`` (any beam count and span, resampled to the tree's features, or refused with exit 2
when they cannot be had from that laser) and ``Odometry`` in, a ``Twist`` on ``cmd_vel`` out.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time

import zenoh

from client.behaviour import guard
from client.behaviour.actions import ActionSet
from client.behaviour.features import FEATURES, FeatureSpec, PayloadReader
from client.behaviour.goals import GoalPolicy, Relocation
from client.behaviour.learning import IncompatibleSnapshotError, TreePolicy, check_compatible
from client.behaviour.rule import LearningRule
from client.decision import Decider
from client.player import PlayerClient
from client.roles.common import ScanWatch, add_process_arguments, run_role, wait_for_server
from client.ros2.nodes import Ros2Options, Ros2Robot, add_ros2_arguments
from process import arguments
from process.runtime import EXIT_NO_SERVER, EXIT_USAGE, Context, ProcessError, uninterrupted
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import DecisionGoal, Scan, TreeNotice

__all__ = ["ControllerProcess", "add_arguments", "fetch_snapshot", "load_tree", "main"]

log = logging.getLogger(__name__)

SOURCE = "controller"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--tree", metavar="PATH", type=arguments.input_file,
                     help="a snapshot (of rhbl learner, rhbl train, rhbl refine, ...; a goal "
                          "behaviour's with both its trees, docs/goals.md)")
    src.add_argument("--from-learner", action="store_true",
                     help="fetch the learner's latest snapshot with a zenoh query")
    parser.add_argument("--follow", action="store_true",
                        help="with --from-learner: swap in each newer tree the learner announces")
    parser.add_argument("--features", choices=sorted(FEATURES),
                        help="expected feature specification (a tree trained otherwise is an error)")
    parser.add_argument("--seconds", type=arguments.seconds, default=None, metavar="S",
                        help="stop after driving S seconds of sim time (default: until stopped)")
    parser.add_argument("--goals-again", action="store_true",
                        help="a tree with goals: after the last goal stand still instead of "
                             "ending, and whenever the robot is put elsewhere (the simulator's "
                             "set_pose) pursue the goals from the first again (rhbl demo drives "
                             "so from each start pose)")
    parser.add_argument("--query-timeout", type=arguments.seconds, default=5.0, metavar="SECONDS",
                        help="how long one query waits for the learner's snapshot (default 5)")
    parser.add_argument("--wait-tree", type=arguments.seconds_or_zero, default=None,
                        metavar="SECONDS",
                        help="with --from-learner: wait this long for the learner's first tree "
                             "(queried again at each tree notice and every second, logging "
                             "every few seconds; 0 = forever). Default: forever with --follow, "
                             "otherwise one query (no learner or no tree yet: exit 4)")
    guard.add_arguments(parser)
    parser.add_argument("--ros2", action="store_true",
                        help="drive a ROS 2 robot (rmw_zenoh's keys): its LaserScan and Odometry "
                             "in, a Twist on cmd_vel out; --robot names its topics "
                             "(docs/ros2.md)")
    add_ros2_arguments(parser, bridge=False, when="with --ros2")


def _check_ros2(args: argparse.Namespace) -> None:
    """The ROS 2 options, before any connection (ValueError: one line, exit 2)."""
    if args.ros2:
        Ros2Options.from_args(args).topics(args.robot)
    elif Ros2Options.given(args):
        raise ValueError(f"{', '.join(Ros2Options.given(args))}: only with --ros2")


def check(args: argparse.Namespace) -> None:
    """What the options say together, before any connection (ValueError: exit 2)."""
    if args.follow and not args.from_learner:
        raise ValueError("--follow needs --from-learner")
    if args.wait_tree is not None and not args.from_learner:
        raise ValueError("--wait-tree goes with --from-learner")
    _check_ros2(args)


def main(args: argparse.Namespace) -> int:
    return run_role("controller", args, lambda ctx: ControllerProcess(ctx).run(),
                    check=lambda: check(args))


def _policy_from(clf_bytes_or_path, features: str | None) -> TreePolicy:
    """The policy of a snapshot (bytes from the learner, or a file); a ``ProcessError`` in one
    line naming the file (or "learner snapshot") for anything wrong with it."""
    from rhbl import SnapshotError, load, loads

    source = ("learner snapshot" if isinstance(clf_bytes_or_path, bytes | bytearray)
              else str(clf_bytes_or_path))
    try:
        if isinstance(clf_bytes_or_path, bytes | bytearray):
            clf = loads(bytes(clf_bytes_or_path), source=source)
        else:
            clf = load(clf_bytes_or_path)
        meta = dict(clf.metadata or {})
        check_compatible(meta, FEATURES[features] if features else None)
        spec, actions = FeatureSpec.from_dict(meta["features"]), ActionSet.from_dict(meta["actions"])
        LearningRule.of(meta)  # the rule (its guard) the tree is driven by: readable
    except IncompatibleSnapshotError as exc:
        raise ProcessError(f"controller: {source}: {exc}", EXIT_USAGE) from exc
    except FileNotFoundError as exc:
        raise ProcessError(f"controller: snapshot {source} does not exist", EXIT_USAGE) from exc
    except SnapshotError as exc:  # names the file
        raise ProcessError(f"controller: cannot load the tree: {exc}", EXIT_USAGE) from exc
    except Exception as exc:  # noqa: BLE001 - its metadata: features or actions malformed
        raise ProcessError(f"controller: cannot load the tree: {source}: invalid metadata: "
                           f"{exc}", EXIT_USAGE) from exc
    if isinstance(meta.get("goals"), dict):  # two trees and a goal state (docs/goals.md)
        from client.behaviour.goals import GoalPolicy

        try:
            return GoalPolicy.from_classifier(clf, source)
        except SnapshotError as exc:
            raise ProcessError(f"controller: cannot load the tree: {exc}", EXIT_USAGE) from exc
    return TreePolicy(clf, spec, actions, meta)


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


class ControllerProcess:
    """For every scan: the tree's action as a command on ``.../cmd/vel/controller``. With
    ``--follow`` a newer tree the learner announces is swapped in between two scans."""

    def __init__(self, ctx: Context):
        self.ctx, self.args = ctx, ctx.args
        # kept across tree swaps: a new tree does not reset what the robot is doing; its
        # settings are each tree's rule's (``_guard``), ``guarding`` whether it is on for it
        self.guard = guard.RotationGuard()
        self.guarding = False
        self.policy: TreePolicy | None = None  # swapped between scans by the follower
        self.reader: PayloadReader | None = None  # the policy's features read with each scan
        # subscribed before the first query: a tree announced meanwhile is not missed
        self.follower = _Follower(ctx, self.swap) if self.args.follow else None
        self.client = self.robot()
        ctx.scope.callback(self.client.close)
        self.scans = self.client.scans(depth=1)
        self.watch = ScanWatch("controller", self.scans.key, stale=1.0)
        ctx.scope.callback(self.watch.stop)
        self.decider = Decider(ctx.session, ctx.robot)
        ctx.scope.callback(self.decider.close)
        self.t0: float | None = None
        self.executed: str | None = None  # the action commanded for the last scan answered
        self.fiducials = None  # a tree with goals: the robot's fiducial log (run)
        self.finished = False  # a tree with goals: every goal reached
        self.goal_why: str | None = None  # a tree with goals: why the last goal changed
        self.relocation = Relocation()  # --goals-again: the robot put elsewhere
        self.n = self.bad = 0
        ctx.scope.callback(self.close)  # on every path, after "stopping (signal)"
        ctx.report(self.counters)

    def robot(self) -> PlayerClient | Ros2Robot:
        """What it drives: the rhbl robot (commands on .../cmd/vel/controller, express and never
        dropped) or, with --ros2, a ROS 2 robot whose scans come resampled to the tree's."""
        ctx = self.ctx
        if self.args.ros2:
            return Ros2Robot(ctx.session, ctx.robot, Ros2Options.from_args(self.args),
                             spec=lambda: self.policy.features)
        return PlayerClient(session=ctx.session, robot=ctx.robot, source=SOURCE, express=True,
                            block=True)

    def swap(self, policy: TreePolicy) -> None:
        old = self.policy
        if isinstance(policy, GoalPolicy) and isinstance(old, GoalPolicy):
            # a newer tree goes on with the goal being pursued (the state is the robot's)
            policy.tracker, policy._sightings = old.tracker, old._sightings
        self._guard(policy)
        self._reader(policy)
        self.policy = policy

    def _reader(self, policy: TreePolicy) -> None:
        """The payload reader of ``policy``'s features (none for a ROS 2 robot's scans)."""
        self.reader = None if self.args.ros2 else policy.features.reader()

    def _guard(self, policy: TreePolicy) -> None:
        """The guard this tree is driven through: its rule's (``LearningRule.of`` its
        metadata; a tree with goals: with the path check, ``rule.for_goals``), the options given
        replacing parts of it (``guard.settings``)."""
        settings = guard.settings(self.args, policy.metadata)
        self.guard.apply(settings)
        self.guarding = settings.on

    def run(self) -> int:
        self.policy = self.first_tree()
        self._guard(self.policy)
        self._reader(self.policy)
        log.info("tree loaded: %s; features %s", _describe(self.policy),
                 self.policy.features.to_dict())
        if isinstance(self.policy, GoalPolicy):  # goals in order: the beacons of every scan
            if self.args.ros2:
                raise ProcessError("controller: a tree with goals drives an rhbl robot, without "
                                   "--ros2 (docs/goals.md)", EXIT_USAGE)
            self.fiducials = self.client.fiducials()
            self.policy.reset()
            log.info("pursuing %s", self.policy.tracker.describe())
        if self.follower is not None:
            self.follower.start()
        # the first scan is taken from the controller's own subscription and answered: a
        # lock-step server or replay sends no other scan until it has that answer
        first = wait_for_server(self.ctx, ring=self.scans)
        self.watch.start()
        while self.step(first):
            first = None
        return 0

    def close(self) -> None:
        self.watch.stop()
        log.info("controller stopped after %d commands", self.n)

    def counters(self) -> dict:
        return {"commands": self.n, "unanswered": self.bad,
                **self.guard.interventions,
                "swaps": 0 if self.follower is None else self.follower.swaps,
                "refused_trees": 0 if self.follower is None else self.follower.refused,
                "dropped": {**self.client.decoder.counts,
                            **({} if self.follower is None else self.follower.decoder.counts)}}

    def first_tree(self) -> TreePolicy:
        args = self.args
        if args.tree:
            return load_tree(args.tree, args.features)
        wait = args.wait_tree if args.wait_tree is not None else (0.0 if args.follow else None)
        if wait is None:
            return _policy_from(fetch_snapshot(self.ctx.session, self.ctx.robot,
                                               args.query_timeout), args.features)
        return self.wait_for_tree(wait)

    def wait_for_tree(self, timeout: float) -> TreePolicy:
        """Query the learner until it gives a tree, again at each tree notice and every few
        seconds, logging what it waits for; ``timeout`` s (0 = forever) then the last reason."""
        ctx, args = self.ctx, self.args
        t0 = time.monotonic()
        next_note = t0
        while True:
            if self.follower is not None:
                self.follower.clear()  # a notice from now on means a tree newer than this query
            try:
                data = fetch_snapshot(ctx.session, ctx.robot, args.query_timeout)
                return _policy_from(data, args.features)
            except ProcessError as exc:
                if exc.code == EXIT_USAGE:  # a tree that does not fit: waiting will not help
                    raise
                waited = time.monotonic() - t0
                if timeout and waited >= timeout:
                    raise ProcessError(f"{exc} (waited --wait-tree {timeout:g} s)",
                                       exc.code) from exc
                if time.monotonic() >= next_note:
                    log.info("waiting for the learner's first tree on %s (%s; %.0f s%s)",
                             keys.learner_snapshot_key(ctx.robot), exc, waited,
                             f" of {timeout:g}" if timeout else "")
                    next_note = time.monotonic() + 3.0
            if self.follower is not None:
                self.follower.wait_notice(1.0)
            else:
                time.sleep(1.0)

    def step(self, scan: Scan | None = None) -> bool:
        """Answer ``scan`` or the next one; False when done (``--seconds``)."""
        if scan is None:
            scan = self.receive()  # None: a malformed one (dropped, counted)
            self.watch.seen()
            if scan is None:
                return True
        else:
            self.watch.seen()
        if self.t0 is None:
            self.t0 = scan.ts
        if self.args.seconds is not None and scan.ts - self.t0 >= self.args.seconds:
            log.info("drove %.1f s of sim time: done", scan.ts - self.t0)
            return False
        answered = self.answer(scan)
        if self.finished and not self.args.goals_again:
            log.info("every goal reached (%s): done", self.policy.tracker.describe())
            return False
        if self.finished:  # --goals-again: the robot stands until it is put elsewhere
            with uninterrupted():
                self.client.answer(scan, 0.0, 0.0)
            return True
        if answered is not None:
            (vx, va), policy, x = answered
            with uninterrupted():  # a stop does not leave a command sent and uncounted
                self.client.answer(scan, vx, va)
                self.n += 1
            if self.n % 1000 == 0:
                log.info("%d commands, %.0f s sim", self.n, scan.ts - self.t0)
            self.publish_decision(policy, x, scan)  # after the command: for viewers only
        return True

    def receive(self) -> Scan | PayloadReader | None:
        """The next scan: read in place by the tree's ``PayloadReader`` (its features with it:
        the hot path), else decoded (None: malformed, dropped and counted). The reader holds it
        until the next scan is received."""
        reader = self.reader
        if reader is None:  # a ROS 2 robot's scans: resampled, then decoded
            return self.scans.recv()
        data = self.scans.recv_payload()
        return reader if reader.read(data) else self.scans.decode(data)

    def answer(self, scan: Scan | PayloadReader):
        """``((vx, va), policy, features)`` of the tree's action for ``scan`` (the policy that
        answered: a follower may swap in another one meanwhile); None (logged) when it cannot."""
        p = self.policy
        try:
            if isinstance(p, GoalPolicy):
                x = self.goal_features(p, scan)
                if x is None:
                    return None
            elif type(scan) is PayloadReader and scan.spec is p.features:
                x = scan.x  # read with the scan
            else:
                x = p.features.extract(scan.ranges, scan.pose[2])
            name = str(p.classifier.predict_one(x))
            if self.guarding:
                name = self.guard_choose(name, scan)
            self.executed = name
            return p.actions[name], p, x
        except Exception as exc:  # noqa: BLE001 - a scan the tree cannot use: no command
            self.bad += 1
            if self.bad <= 10 or self.bad % 100 == 0:
                log.warning("scan %d not answered (%d so far; the watchdog stops the robot): "
                            "%s: %s", scan.id, self.bad, type(exc).__name__, exc)
            return None

    def goal_features(self, p, scan: Scan | PayloadReader):
        """A tree with goals: the beacons seen at ``scan`` (the fiducial message of its tick)
        go to the completion tree, which may finish the current goal (logged, with why); the
        features are then the scan's and the current goal's beacon's. None: every goal is
        reached (``finished``)."""
        # the message of the scan's tick, waited for longer once messages flow (it is sent
        # before the scan, on another subscriber); none came (the subscription was not up yet,
        # or lost): nothing is known of the beacons, so no goal is judged done on this scan
        if self.fiducials is None:  # a tree with goals swapped in for one without
            self.fiducials = self.client.fiducials()
        msg = self.fiducials.at(scan.id, timeout=1.0 if self.fiducials.latest else 0.2)
        if msg is not None and self.args.goals_again and self.relocation.moved(msg):
            p.reset()
            self.finished, self.goal_why = False, None
            log.info("the robot was put elsewhere at %.1f s: pursuing %s", scan.ts,
                     p.tracker.describe())
        seen = () if msg is None else msg.items
        ev = None if msg is None else p.see({int(item.id): item for item in seen if item.id},
                                            t=scan.ts)
        if ev is not None:  # the decisions say it too (``Decision.goal_why``)
            self.goal_why = (f"goal {ev['visit'] + 1}/{len(p.goals.visits)} (beacon "
                             f"{ev['beacon']}) done at {scan.ts:.1f} s: {ev['why']}")
            log.info("%s; now %s", self.goal_why, p.tracker.describe())
        if p.tracker.finished:
            self.finished = True
            return None
        if type(scan) is PayloadReader and scan.spec is p.features:
            scan.see(seen, target=p.tracker.beacon)
            return scan.x
        return p.features.extract(scan.ranges, scan.pose[2], seen=seen,
                                  target=p.tracker.beacon)

    def guard_choose(self, name: str, scan: Scan) -> str:
        """The loop guard's action for the tree's ``name`` (an overruled reversal logged at a
        bounded rate)."""
        before = self.guard.overruled
        # the beams' bearings only for the path check (off for the scripted teacher's trees)
        chosen = self.guard.choose(name, scan.ranges,
                                   scan.bearings() if self.guard.clearance > 0 else None)
        n = self.guard.overruled
        if n > before and (n <= 3 or n % 100 == 0):
            log.info("loop guard: the tree reversed its rotation at scan %d (%s): drove %s "
                     "(%d overruled so far)", scan.id, name, chosen, n)
        return chosen

    def publish_decision(self, policy, x, scan: Scan) -> None:
        """The decision of the scan just answered, for viewers; a failure here is logged and
        never stops the controller (the command is already out)."""
        goal = None
        if isinstance(policy, GoalPolicy) and not policy.tracker.finished:
            t = policy.tracker
            goal = DecisionGoal(t.visit, len(t.goals.visits), t.beacon)
        try:  # with the loop guard's state: a console asks the person to show the way out
            self.decider.publish(policy, x, scan, executed=self.executed,
                                 looping=self.guarding and self.guard.looping, goal=goal,
                                 goal_why=self.goal_why if goal is not None else None)
        except Exception as exc:  # noqa: BLE001 - viewers only
            log.debug("decision of scan %d not published: %s", scan.id, exc)


class _Follower:
    """Subscribes to tree notices; a thread fetches the newer snapshot and swaps it in."""

    def __init__(self, ctx: Context, swap):
        self.ctx, self.args, self._swap = ctx, ctx.args, swap
        self._want = threading.Event()
        self._stop = threading.Event()
        self.swaps = 0
        self.refused = 0  # snapshots the learner gave that could not be loaded
        self.decoder = Decoder(log)
        ctx.subscriber(keys.learner_notice_key(ctx.robot), self._on_notice)
        self._thread = threading.Thread(target=self._loop, name="controller-follow", daemon=True)
        ctx.scope.callback(self.stop)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():  # a fetch in flight ends within --query-timeout
            self._thread.join(self.args.query_timeout + 1.0)

    def clear(self) -> None:
        self._want.clear()

    def wait_notice(self, timeout: float) -> bool:
        return self._want.wait(timeout)

    def _on_notice(self, sample) -> None:
        note = self.decoder.decode(TreeNotice, sample.payload.to_bytes())
        if note is None:
            return
        log.debug("tree notice %s", note)
        self._want.set()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self._want.wait(0.2):
                self._want.clear()
                self._fetch()

    def _fetch(self) -> None:
        try:
            data = fetch_snapshot(self.ctx.session, self.ctx.robot, self.args.query_timeout)
        except ProcessError as exc:
            log.warning("could not swap the tree: %s", exc)
            return
        except Exception as exc:  # noqa: BLE001 - the session closing under us
            if not self._stop.is_set():
                log.warning("could not swap the tree: %s", exc)
            return
        try:
            policy = _policy_from(data, self.args.features)
        except ProcessError as exc:  # a malformed or unfit tree: this one keeps driving
            self.refused += 1
            log.warning("could not swap the tree: %s", exc)
            return
        self._swap(policy)
        self.swaps += 1
        log.info("swapped in a newer tree: %s", _describe(policy))
