"""``rhbl learner``: grow a hypersphere tree from a teacher's demonstrations over zenoh.

Pairs every ``TeacherAction`` label with exactly the scan it answers (by scan id, whichever
arrives first), appends the labeled vector to the journal ``<out>.journal`` (flushed before it is
learned) and learns it with ``client.behaviour.learning.DemonstrationLearner`` (the in-process
harness's code path). Snapshots are written atomically every ``--snapshot-every`` seconds when the
tree changed and on exit; each records how many journal records it includes, so a killed learner
restarted with the same command rebuilds exactly (last snapshot + the journal records after it).

It publishes a ``TreeNotice`` on ``rhbl/<robot>/learner/notice`` after each snapshot and answers
queries on ``rhbl/<robot>/learner/snapshot`` with the latest snapshot's bytes.

Labels with an identity (the teacher session's ``origin`` and ``seq``) are acknowledged once
journaled: a ``LearnerAck`` on ``rhbl/<robot>/learner/ack`` (batched, every 0.15 s or 50 labels,
and for everything held right after a restart's recovery, before the liveliness token). A teacher
resends what is not acknowledged with its scan on ``rhbl/<robot>/teacher/labeled``
(``LabeledScan``: learned without pairing); a label already held (``client.journal.LabelSet``,
rebuilt on restart from the snapshot's provenance and the journal) is acknowledged again, not
journaled or learned twice.

A teacher takes labels back with a ``Withdrawal`` on ``rhbl/<robot>/teacher/withdraw`` (an undo,
a discarded episode): the learner journals it (a tombstone), acknowledges it
(``LearnerAck.withdrawn``), never learns those labels and rebuilds its tree from the journal
without them (the lineage's start plus every labelled vector that stands); a restart keeps them
out. A journal folded with ``--fold-journal`` no longer holds the records a rebuild needs: a
withdrawal of labels folded into a snapshot is journaled but cannot take them out of the tree
(logged as an error).

One learner per lineage (``client.lineage.LineageLock`` on ``<out>.lock``: a second one is
refused, or waits ``--lock-wait`` s). Scans and resent labels that do not fit the robot's laser
(``client.laser.Laser``) and withdrawals far past what their session gave are refused, counted
in ``--stats`` ``refused`` by kind.

    rhbl learner --out tree.rhbl                                 # new tree, all round (or continue)
    rhbl learner --features wall --out tree.rhbl                 # new tree with the paper's spec
    rhbl learner --resume tree.rhbl --out tree2.rhbl             # extend a tree: a new lineage
    rhbl learner --features wall --teacher person --out tree.rhbl  # force the person rule

``--teacher auto`` (the default) chooses a new lineage's rule by its first label's ``source``
(``client.labels.by_person``): a person's (``console``, ``keyboard``) gives the person rule, any
other the script rule (the paper's: each label learned as it arrives); the journal's header keeps
it. The person rule (labels given by hand at ``rhbl console``): a person's key answers what
they saw a reaction time earlier: each label is journaled with the scans displayed before it
and the lag is estimated from the labels (``--lag auto``, the default), or paired with the scan
``--lag N`` scans before the one it names (``client.labels.Pairing``), and the tree is rebuilt from every label journaled,
each taking what its nearest labels vote
(``client.behaviour.teaching.PersonLearner``: one wrong key does not carve a sphere for ever).
Such a lineage is rebuilt from its whole journal on a restart (no ``--fold-journal``, no
``--resume``); docs/teaching.md has the study behind it.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import time
from collections import deque
from pathlib import Path

from client.behaviour.features import DEFAULT_FEATURES, FEATURES, FeatureError
from client.behaviour.given import behaviour_arg
from client.behaviour.goals import GoalStep
from client.behaviour.spec import behaviour
from client.behaviour.teaching import add_person_arguments
from client.journal import JournalError, journal_path
from client.labels import MAX_BACKLOG, MAX_BACKLOG_BYTES, Acknowledgements, Pairing, scan_bytes
from client.laser import Laser
from client.lineage import Lineage, Refused, lock_path
from client.roles.common import ScanWatch, add_process_arguments, run_role, wait_for_server
from process import arguments, files
from process.runtime import Context, ProcessError, on_stop_signal
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import SEEN_BYTES, Scan, TeacherAction, TreeNotice, Withdrawal

__all__ = ["LearnerProcess", "Pairing", "add_arguments", "main"]

log = logging.getLogger(__name__)

_RETRY = 1.0  # s between attempts to write the journal again
_MAX_TAKEN_BACK = 4096  # withdrawals waiting to be journaled (each under 1 KB decoded)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    parser.add_argument("--features", choices=sorted(FEATURES),
                        help=f"feature specification of a new tree (default: {DEFAULT_FEATURES}, "
                             "nine sector minima over the whole field of view; wall and maze are "
                             "the paper's five pings); checked against the tree when continuing "
                             "or resuming, which otherwise keep the tree's")
    parser.add_argument("--out", required=True, metavar="PATH", type=arguments.output_file,
                        help="snapshot path; the journal is PATH.journal. If they exist the "
                             "learner continues them (after a crash: snapshot + journal)")
    parser.add_argument("--resume", metavar="SNAPSHOT", type=arguments.input_file,
                        help="extend an existing tree: start a new lineage at --out from it "
                             "(its path is recorded as the parent in the provenance)")
    parser.add_argument("--task", default=None, type=arguments.key_chunk,
                        help="task stored in the metadata (default: the one task whose spec --features "
                             "is, if one is; none for around)")
    parser.add_argument("--spawn", choices=["winner", "all"], default="winner",
                        help="tree growth rule: 'all' = the paper's literal rule, 'winner' = "
                             "spawn under the winning sphere only (smaller trees; default)")
    parser.add_argument("--stride", type=arguments.positive_int, default=1,
                        help="learn every n-th labeled vector")
    parser.add_argument("--min-delta", type=arguments.non_negative_float, default=0.0,
                        help="skip a vector that moved less than this with an unchanged label")
    parser.add_argument("--max-nodes", type=arguments.positive_int, default=None,
                        help="cap on the tree size")
    parser.add_argument("--snapshot-every", type=arguments.seconds, default=2.0,
                        metavar="SECONDS",
                        help="write a snapshot this often (wall time) when the tree changed")
    parser.add_argument("--fold-journal", action="store_true",
                        help="after each snapshot drop the journal records it holds (bounded "
                             "disk; the raw scans before it can no longer be relearned)")
    parser.add_argument("--fsync-interval", type=arguments.seconds_or_zero, default=1.0,
                        metavar="SECONDS",
                        help="fsync the journal at most this long after an append (default 1)")
    parser.add_argument("--match-timeout", type=arguments.seconds, default=2.0,
                        metavar="SECONDS",
                        help="a label whose scan has not arrived after this is dropped and counted")
    parser.add_argument("--drain", type=arguments.seconds_or_zero, default=5.0,
                        metavar="SECONDS",
                        help="on SIGINT/SIGTERM, keep learning what already arrived for at most "
                             "this long before the final snapshot (default 5)")
    parser.add_argument("--lock-wait", type=arguments.seconds_or_zero, default=0.0,
                        metavar="SECONDS",
                        help="when another learner holds the lineage (one still draining "
                             "after a stop), wait this long for it before refusing (default 0: "
                             "refuse at once, naming its pid)")
    parser.add_argument("--scan-buffer", type=arguments.positive_int, default=512,
                        help="how many recent unlabeled scans are kept for pairing")
    parser.add_argument("--teacher", choices=["auto", "script", "person"], default="auto",
                        help="who labels a new tree: 'auto' (default) chooses by the first "
                             "label's source, the person rule for a person's (rhbl console, "
                             "rhbl teacher --policy keyboard), else the script rule (with "
                             "--resume or --fold-journal: the script rule); 'script' forces "
                             "the script rule (each label learned as it arrives); 'person' the "
                             "person rule (labels paired with the scan a reaction time --lag "
                             "earlier, the tree learned from every label edited by the vote of "
                             "its nearest labels; client.behaviour.rule). A lineage keeps the "
                             "rule it was made with (its journal's header)")
    add_person_arguments(parser)
    parser.add_argument("--behaviour", default=None, type=behaviour_arg, metavar="NAME|FILE",
                        help="learn this behaviour: its perception is the feature spec (a "
                             "file's inline one too) and its name the task in the metadata (a "
                             "shipped behaviour's name or a behaviour file; docs/behaviours.md); "
                             "not with --features or --task")


def features_of(args: argparse.Namespace) -> tuple:
    """The feature spec (a name or a spec), the task and the goals (None: none) the options
    give: ``--features`` and ``--task``, or ``--behaviour``'s perception, name and goals
    (ValueError: not both)."""
    if args.behaviour is None:
        return args.features, args.task, None
    if args.features is not None or args.task is not None:
        raise ValueError("--behaviour gives the features and the task: not with --features "
                         "or --task")
    b = behaviour(args.behaviour)
    return b.perception or b.features, b.name, b.goals


def guard_of(args: argparse.Namespace) -> bool | None:
    """False when ``--behaviour`` turns the controller's guard off for its trees (its file's
    ``guard = false``), else None (the rule's)."""
    return None if args.behaviour is None or behaviour(args.behaviour).guard else False


# ---- the process --------------------------------------------------------------------------
def main(args: argparse.Namespace, *, journal_write=os.write) -> int:
    """``rhbl learner``; ``journal_write`` writes the journal's records (``client.journal``'s
    seam for injected write failures: campaigns/full_disk.py)."""
    lineage: list[Lineage] = []

    def check() -> None:  # the snapshot and journal, opened before any connection: bad ones
        if args.behaviour is not None:
            features_of(args)
        files.check_output(args.out, "--out", make=True)  # exit 2 at once (its folder made)
        files.check_output(journal_path(args.out), "--out's journal")
        files.check_output(lock_path(args.out), "--out's lock")
        lineage.append(LearnerProcess.open_lineage(args, journal_write))

    # the token is declared once the label subscription is in place: a teacher that waits for
    # it (rhbl teacher) then loses no label
    return run_role("learner", args, lambda ctx: LearnerProcess(ctx, lineage[0]).run(),
                    early_token=False, check=check)


class LearnerProcess:
    """The learner over zenoh: scans and labels paired as they arrive (``Pairing``), learned in
    order by ``Lineage``; snapshots announced with a ``TreeNotice`` and served on a query.

    SIGINT/SIGTERM set ``stopping``: the loop withdraws the token, learns what already arrived
    (up to ``--drain`` s), writes the final snapshot and returns."""

    def __init__(self, ctx: Context, lineage: Lineage):
        self.ctx, self.args = ctx, ctx.args
        self.stopping = False
        on_stop_signal(self.request_stop)
        self.lineage = lineage
        ctx.scope.callback(self.close_journal)  # also on a path that never reaches finish()
        # the tree it answers with: its snapshot; before its first one, the tree it extends
        # (--resume: what drives, and what a console shows, until the first label is learned)
        self.latest = (self.lineage.out.read_bytes() if self.lineage.out.exists()
                       else Path(self.args.resume).read_bytes() if self.args.resume else None)
        self.snap_key = keys.learner_snapshot_key(ctx.robot)
        self.watch = ScanWatch("learner", keys.scan_key(ctx.robot), stale=3.0)
        # labels are paired with their scans as they arrive: nothing but labeled scans is queued
        # (a lineage whose rule is not chosen yet shifts a person's labels only: ``lag_for``)
        # the robot's laser: scans and resent labels that do not fit it are refused on arrival
        # (client.laser), before they take memory, the journal or the tree
        self.laser = Laser(beams=self.lineage.beams)
        self.pairing = Pairing(self.args.scan_buffer, self.args.match_timeout,
                               on_scan_seen=self.watch.seen, laser=self.laser,
                               **({"lag_of": self._lag_of} if self.lineage.undecided else
                                  dict(zip(("lag", "window"), self.lineage.pairing(),
                                           strict=True))))
        self.stats = {"learned": 0, "paired": 0, "rejected": 0, "lost": 0, "duplicates": 0,
                      "withdrawals": 0, "withdrawn_skipped": 0}
        # teachers' withdrawals as they arrive (decoded in zenoh's thread), applied by the loop
        self.taken_back: deque[Withdrawal] = deque()
        self.refused: dict[str, int] = {}  # bad input refused for good, by kind (``refuse``)
        self.withdraw_decoder = Decoder(log)
        ctx.report(self.counters)
        # labeled scans waiting to be journaled (in order): empty unless the journal cannot be
        # written (disk full); nothing is learned before it is journaled
        self.backlog: deque[tuple[Scan, TeacherAction]] = deque()
        self.backlog_bytes = 0  # the ranges the backlog holds (``scan_bytes``)
        self.waiting: set[tuple[str, int]] = set()  # (origin, seq) of the backlog's labels
        self.retry_at = 0.0
        self.failures = 0  # journal writes failed in a row
        self.drain_until: float | None = None  # after a stop request: finish what arrived
        self.notice_pub = self.subs = None
        self.tree_size = (0, 0)  # nodes, height of the last snapshot written
        self.acks: Acknowledgements | None = None  # once the ack publisher is declared

    def _lag_of(self, act: TeacherAction) -> int:  # zenoh's threads, under the pairing's lock
        return self.lineage.lag_for(act.source)

    @staticmethod
    def open_lineage(args: argparse.Namespace, journal_write=os.write) -> Lineage:
        """The learner's snapshot and journal of ``args`` (``--out``, ``--resume``, ...);
        ProcessError when they cannot be used."""
        try:
            features, task, goals = features_of(args)
            return Lineage(
                args.out, features=features, resume=args.resume, task=task,
                tree_params={"spawn": args.spawn,
                             **({"max_nodes": args.max_nodes} if args.max_nodes else {})},
                stride=args.stride, min_delta=args.min_delta,
                fsync_interval=args.fsync_interval, fold_journal=args.fold_journal,
                journal_write=journal_write, teacher=args.teacher, lag=args.lag,
                guard=guard_of(args), lock_wait=args.lock_wait, goals=goals)
        except JournalError as exc:
            raise ProcessError(f"learner: {exc}") from exc

    def request_stop(self) -> None:
        self.stopping = True

    # -- zenoh --
    def declare(self) -> None:
        ctx, robot = self.ctx, self.ctx.robot
        self.notice_pub = ctx.publisher(keys.learner_notice_key(robot))
        self.acks = Acknowledgements(ctx.publisher(keys.learner_ack_key(robot)).put,
                                     self.lineage.labels, withdrawals=self.lineage.withdrawals)
        self.subs = [
            ctx.subscriber(keys.scan_key(robot), self.on_scan),
            ctx.subscriber(keys.teacher_action_key(robot), self.on_label),
            ctx.subscriber(keys.teacher_labeled_key(robot), self.on_labeled),
            ctx.subscriber(keys.teacher_withdraw_key(robot), self.on_withdraw),
        ]
        ctx.queryable(self.snap_key, self.on_query)
        # what survived (journal + snapshot), for a teacher that resends what we do not hold
        self.acks.publish(set(self.lineage.labels.origins()) | set(self.lineage.withdrawals.origins()))
        ctx.declare_token()  # after the subscriptions: the token means "ready to receive labels"

    def on_scan(self, sample) -> None:
        if not self.laser.too_big(len(sample.payload), "a scan"):
            self.pairing.on_scan(sample.payload.to_bytes())

    def on_label(self, sample) -> None:
        self.pairing.on_label(sample.payload.to_bytes())

    def on_labeled(self, sample) -> None:
        if not self.laser.too_big(len(sample.payload), "a label resent with its scan",
                                  "teacher/labeled", extra=SEEN_BYTES):
            self.pairing.on_labeled(sample.payload.to_bytes())

    def on_withdraw(self, sample) -> None:
        w = self.withdraw_decoder.decode(Withdrawal, sample.payload.to_bytes())
        if w is None:
            return
        if len(self.taken_back) >= _MAX_TAKEN_BACK:  # a flood: its teacher resends it later
            self.refuse(Refused("withdrawal_flood", (
                f"withdrawal {w.id} of teacher session {w.origin}: {_MAX_TAKEN_BACK} "
                "withdrawals wait already; not held (a teacher resends what is not "
                "acknowledged)")))
            return
        self.taken_back.append(w)

    def on_query(self, query) -> None:
        data = self.latest
        try:
            if data is None:
                query.reply_err(b"no snapshot yet")
            else:
                query.reply(self.snap_key, data)
        except Exception as exc:  # noqa: BLE001 - the querier went away
            log.debug("snapshot reply failed: %s", exc)

    def publish(self) -> bool:
        """Write the snapshot and announce it; False (logged) when it cannot be written."""
        lineage = self.lineage
        try:
            self.latest = lineage.snapshot()
        except OSError as exc:  # disk full, ...: the journal still holds every vector
            log.error("cannot write snapshot %s (%s); retrying in %.0f s (the journal holds "
                      "every labeled vector)", lineage.out, exc, self.args.snapshot_every)
            return False
        self.tree_size = (lineage.learner.nodes, lineage.learner.height)  # as just written
        note = TreeNotice(seq=lineage.seq, nodes=self.tree_size[0], height=self.tree_size[1],
                          vectors=lineage.standing,
                          snapshot_id=f"{lineage.journal.lineage}:{lineage.applied}", ts=time.time())
        self.notice_pub.put(note.encode())
        return True

    # -- learning --
    def learn(self, scan: Scan, act: TeacherAction) -> None:
        if act.action not in self.lineage.actions:
            self.stats["rejected"] += 1
            log.warning("label %r for scan %d is not an action of this tree %s: dropped",
                        act.action, act.scan_id, self.lineage.actions.names)
            self.acks.handled(act, journaled=False)
            return
        key = (act.origin, act.seq)
        if key in self.lineage.withdrawals:  # taken back by its teacher before it came
            self.stats["withdrawn_skipped"] += 1
            self.acks.handled(act, journaled=True)
            return
        if act.origin is not None and (self.lineage.holds(act.origin, act.seq)
                                       or key in self.waiting):
            # a resend of a label journaled already (acknowledged again: the ack was lost), or
            # of one waiting in the backlog (the journal cannot be written and the teacher
            # resends what it does not see acknowledged): one copy is kept, not one per resend
            self.stats["duplicates"] += 1
            if key not in self.waiting:
                self.acks.handled(act, journaled=True)
            return
        self.stats["paired"] += 1
        self.backlog.append((scan, act))
        self.backlog_bytes += scan_bytes(scan)
        if act.origin is not None:
            self.waiting.add(key)
        if len(self.backlog) == 1 or time.monotonic() >= self.retry_at:
            self.flush_backlog()

    def flush_backlog(self) -> None:
        """Journal and learn the waiting labeled scans, in order, until the journal fails."""
        while self.backlog:
            scan, act = self.backlog[0]
            undecided = self.lineage.undecided
            try:
                learned = self.lineage.learn(
                    scan.id, scan.ts, scan.ranges, float(scan.pose[2]), act.action, act.origin,
                    act.seq, [(s.ranges, float(s.pose[2])) for s in getattr(scan, "earlier", ())],
                    act.source, None if act.goal is None else
                    GoalStep.of(act.goal, act.reached, act.seen))
            except Refused as exc:  # not this lineage's laser: not journaled, not acknowledged
                self._pop()
                self.refuse(exc)
                continue
            except FeatureError as exc:  # a scan the features cannot use (bad input)
                self._pop()
                self.stats["rejected"] += 1
                log.warning("label %r for scan %d dropped: %s", act.action, scan.id, exc)
                self.acks.handled(act, journaled=False)
                continue
            except (JournalError, OSError) as exc:
                self._journal_failed(exc)
                return
            self._pop()
            if undecided and not self.lineage.undecided:  # this label chose the rule
                self.pairing.settle(*self.lineage.pairing())
            self.acks.handled(act, journaled=True)  # (again, for a duplicate: its ack was lost)
            if learned is None:  # resent, or live and resent: journaled once only
                self.stats["duplicates"] += 1
            self.stats["learned"] += bool(learned)
        if self.failures:
            log.warning("the journal is writable again after %d failed attempts", self.failures)
            self.failures = 0

    def apply_withdrawals(self) -> None:
        """Journal and hold the withdrawals that arrived; then rebuild the tree once if it
        holds some of their labels, and announce the new tree at once. A journal that cannot
        be written keeps them waiting (retried with the backlog)."""
        rebuild = False
        while self.taken_back:
            w = self.taken_back[0]
            try:
                held = self.lineage.withdraw(w)
            except Refused as exc:
                self.taken_back.popleft()
                self.refuse(exc)
                continue
            except (JournalError, OSError) as exc:
                self._journal_failed(exc)
                break
            self.taken_back.popleft()
            self.acks.withdrawn(w.origin)
            if held is not None:
                self.stats["withdrawals"] += 1
                log.info("teacher session %s withdrew its labels %d..%d (%s)", w.origin,
                         w.first, w.upto - 1, w.reason or "no reason given")
                rebuild = rebuild or held
        if rebuild and self.lineage.rebuild():
            self.publish()

    def refuse(self, exc: Refused) -> None:
        """Count input refused (``--stats``: ``refused``, by kind; not acknowledged); logged the
        first time of each kind, then every 1000th."""
        n = self.refused[exc.kind] = self.refused.get(exc.kind, 0) + 1
        if n == 1 or n % 1000 == 0:
            log.warning("%s (%d %s refused so far%s)", exc, n, exc.kind,
                        "; the next ones of this kind are counted, logged every 1000th"
                        if n == 1 else "")

    def _pop(self) -> None:
        """Take the oldest labeled scan off the backlog."""
        scan, act = self.backlog.popleft()
        self.backlog_bytes -= scan_bytes(scan)
        self.waiting.discard((act.origin, act.seq))

    def _journal_failed(self, exc: Exception) -> None:
        self.retry_at = time.monotonic() + _RETRY
        self.failures += 1
        n = self.failures
        if n <= 3 or n % 60 == 0:
            log.error("cannot write the journal (%s): %d labeled vectors kept in memory "
                      "(at most %d), retrying every %.0f s; nothing is learned before "
                      "it is journaled", exc, len(self.backlog), MAX_BACKLOG, _RETRY)
        while len(self.backlog) > MAX_BACKLOG or self.backlog_bytes > MAX_BACKLOG_BYTES:
            self._pop()
            self.stats["lost"] += 1
            if self.stats["lost"] <= 3 or self.stats["lost"] % 1000 == 0:
                log.error("journal still failing: dropped the oldest labeled vector "
                          "kept in memory (%d lost so far)", self.stats["lost"])

    # -- the loop --
    def run(self) -> int:
        self.declare()
        self.first_snapshot()
        if not self.stopping:
            wait_for_server(self.ctx, got=self.watch.first, stop=lambda: self.stopping)
        self.ctx.scope.callback(self.watch.stop)
        self.watch.start()
        try:
            self.loop()
        finally:
            code = self.finish()
        return code

    def first_snapshot(self) -> None:
        lineage = self.lineage
        if lineage.dirty:
            try:
                self.latest = lineage.snapshot()
            except OSError as exc:  # the journal holds every vector; retried while learning
                log.error("cannot write snapshot %s (%s); retrying later", lineage.out, exc)
        log.info("learning: %s; snapshot %s", lineage.describe(), lineage.out)
        self.tree_size = (lineage.learner.nodes, lineage.learner.height)

    def loop(self) -> None:
        now = time.monotonic()
        last_snap = last_log = last_expire = now
        while True:
            if self.stopping and self.drain_until is None:
                self.begin_drain()
            item = self.pairing.get(timeout=0.1 if self.drain_until is None else 0.05)
            if self.drain_until is not None and (item is None or self._out_of_drain(item)):
                return  # quiet (everything that arrived is learned), or out of time
            if item is not None:
                self.learn(*item)
            if self.taken_back and time.monotonic() >= self.retry_at:
                self.apply_withdrawals()
            now = time.monotonic()
            if self.backlog and now >= self.retry_at:
                self.flush_backlog()
            if item is None or now - last_expire >= 0.5:
                last_expire = now
                self.pairing.expire()
            if self.acks.due(now):
                self.acks.publish()
            if self.lineage.dirty and now - last_snap >= self.args.snapshot_every:
                self.publish()
                # from the end of this snapshot: a snapshot that takes longer than
                # --snapshot-every (a person's tree rebuilt from thousands of labels on a busy
                # machine) still leaves that long to learning, or the learner would learn one
                # label per rebuild and fall ever further behind its teacher
                last_snap = now = time.monotonic()
            if now - last_log >= 5.0:
                last_log = now
                self.log_progress()

    def begin_drain(self) -> None:
        self.drain_until = time.monotonic() + self.args.drain
        log.info("stopping: learning what already arrived (up to %.1f s)", self.args.drain)
        # withdraw the token first: a teacher pauses instead of labelling into the void
        self.ctx.withdraw_token()

    def _out_of_drain(self, item) -> bool:
        if time.monotonic() <= self.drain_until:
            return False
        left = self.pairing.discard() + 1  # + the item at hand
        self.stats["lost"] += left
        log.error("stopping with %d labeled scans not learned (--drain %.1f s limit): lost",
                  left, self.args.drain)
        return True

    def log_progress(self) -> None:
        """The progress line; the tree's size as last written (a person's tree is rebuilt
        when asked for its size: asking here cost a rebuild every 5 s)."""
        ps, lineage = self.pairing.stats, self.lineage
        nodes, height = self.tree_size
        log.info("vectors %d (learned %d this run), nodes %d, height %d (last snapshot), "
                 "unmatched %d; %d labeled scans waiting, %d unlabeled scans forgotten",
                 lineage.applied, self.stats["learned"], nodes, height, ps["unmatched"],
                 self.pairing.waiting(), ps["forgotten"])

    # -- stopping --
    def finish(self) -> int:
        """Stop receiving, learn or count what is left, the final snapshot, close the journal:
        the exit code (1 when a labeled vector was lost or the last snapshot not written)."""
        self.watch.stop()
        self.ctx.withdraw_token()
        for sub in self.subs or []:
            with contextlib.suppress(Exception):
                sub.undeclare()
        code = 0
        try:
            self.learn_leftovers()
            if self.taken_back:
                self.apply_withdrawals()
            if self.taken_back:
                log.error("%d withdrawals could not be journaled (the journal is not writable);"
                          " their teacher resends them to the next learner",
                          len(self.taken_back))
            if self.acks.pending:
                self.acks.publish()
            lost = self.stats["lost"] + self.pairing.stats["lost"]
            if lost or (self.lineage.dirty and not self.publish()):
                code = 1
            self.report(lost)
        finally:
            if not self.close_journal():
                code = 1
        return code

    def close_journal(self) -> bool:
        """Close (fsync) the journal; False (logged) when that failed. Idempotent."""
        try:
            self.lineage.close()
        except OSError as exc:
            log.error("closing the journal %s failed: %s", self.lineage.jpath, exc)
            return False
        return True

    def learn_leftovers(self) -> None:
        """Labeled scans that arrived after the loop's last look (a stop, an error): learned
        after a stop, counted lost otherwise; never dropped silently."""
        while self.drain_until is not None and time.monotonic() <= self.drain_until + 1.0:
            item = self.pairing.get(0.0)
            if item is None:
                break
            self.learn(*item)
        if left := self.pairing.discard():
            self.stats["lost"] += left
            log.error("%d labeled scans not learned (the learner is failing or out of "
                      "--drain time): lost", left)
        if self.backlog:
            self.flush_backlog()
        if self.backlog:
            self.stats["lost"] += len(self.backlog)
            log.error("%d labeled vectors could not be journaled (the journal is not "
                      "writable) and are lost", len(self.backlog))
        self.pairing.close()

    def counters(self) -> dict:
        """The learner's counters (``--stats``): this run's, the pairing's and the tree's."""
        lineage = self.lineage
        rule = "undecided" if lineage.undecided else "person" if lineage.person else "script"
        return {**self.stats, "rule": rule, "vectors": lineage.applied, "replayed": lineage.replayed,
                "standing": lineage.standing, "rebuilds": lineage.rebuilds,
                "withdrawn_labels": lineage.withdrawals.labels(),
                "nodes": lineage.learner.nodes, "height": lineage.learner.height,
                "refused": {k: self.refused.get(k, 0) + self.laser.refused.get(k, 0)
                            for k in {**self.refused, **self.laser.refused}},
                # the same misfits by the kind of message that carried them
                "refused_messages": dict(self.laser.by_key),
                "pairing": dict(self.pairing.stats), "backlog": len(self.backlog),
                "dropped": {**self.pairing.decoder.counts, **self.withdraw_decoder.counts}}

    def report(self, lost: int) -> None:
        ps, st, lineage = self.pairing.stats, self.stats, self.lineage
        log.info("stopped: %d labeled vectors (%d this run, %d learned, %d unmatched "
                 "labels, %d malformed, %d rejected, %d resent by the teacher, %d duplicates "
                 "skipped, %d lost), %d nodes, height %d; snapshot %s; %d scans received, "
                 "%d unlabeled ones forgotten, at most %d labeled scans waited to be learned",
                 lineage.applied, st["paired"], st["learned"], ps["unmatched"], self.pairing.decoder.total,
                 st["rejected"], ps["resent"], st["duplicates"], lost, lineage.learner.nodes,
                 lineage.learner.height, lineage.out, ps["scans"], ps["forgotten"], ps["max_ready"])
