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

    rhbl learner --features wall --out tree.rhbl                 # new tree (or continue tree.rhbl)
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

import numpy as np

from client.behaviour.actions import DEFAULT_ACTIONS, ActionSet
from client.behaviour.features import FEATURES, FeatureError, FeatureSpec
from client.behaviour.learning import (
    DemonstrationLearner,
    IncompatibleSnapshotError,
    check_compatible,
    load_snapshot,
)
from client.behaviour.tasks import task_of_features
from client.behaviour.teaching import (
    MAX_LAG,
    PERSON_RULE,
    VOTES,
    PersonLearner,
    add_person_arguments,
)
from client.journal import (
    Journal,
    JournalError,
    JournalWithdrawal,
    LabelSet,
    Withdrawals,
    journal_path,
)
from client.labels import MAX_BACKLOG, Acknowledgements, Pairing, by_person
from client.roles.common import ScanWatch, add_process_arguments, run_role, wait_for_server
from process import arguments, files
from process.runtime import EXIT_USAGE, Context, ProcessError, on_stop_signal
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import Scan, TeacherAction, TreeNotice, Withdrawal
from rhbl import SnapshotError

__all__ = ["LearnerCore", "LearnerProcess", "Pairing", "add_arguments", "main"]

log = logging.getLogger(__name__)

_RETRY = 1.0  # s between attempts to write the journal again


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_process_arguments(parser)
    parser.add_argument("--features", choices=sorted(FEATURES),
                        help="feature specification (required for a new tree; checked against "
                             "the tree when continuing or resuming)")
    parser.add_argument("--out", required=True, metavar="PATH", type=arguments.output_file,
                        help="snapshot path; the journal is PATH.journal. If they exist the "
                             "learner continues them (after a crash: snapshot + journal)")
    parser.add_argument("--resume", metavar="SNAPSHOT", type=arguments.input_file,
                        help="extend an existing tree: start a new lineage at --out from it "
                             "(its path is recorded as the parent in the provenance)")
    parser.add_argument("--task", default=None, type=arguments.key_chunk,
                        help="task stored in the metadata (default: from --features)")
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
    parser.add_argument("--scan-buffer", type=arguments.positive_int, default=512,
                        help="how many recent unlabeled scans are kept for pairing")
    parser.add_argument("--teacher", choices=["auto", "script", "person"], default="auto",
                        help="who labels a new tree: 'auto' (default) chooses by the first "
                             "label's source, the person rule for a person's (rhbl console, "
                             "rhbl teacher --policy keyboard), else the script rule (with "
                             "--resume or --fold-journal: the script rule); 'script' forces "
                             "the script rule (each label learned as it arrives); 'person' the "
                             "person rule (labels paired with the scan a reaction time --lag "
                             "earlier, the tree rebuilt from every label by the vote of its "
                             "nearest labels). A lineage keeps the rule it was made with (its "
                             "journal's header)")
    add_person_arguments(parser)


# ---- the learning core (no zenoh: testable on its own) --------------------------------------
def _replay(learner: DemonstrationLearner, rec) -> None:
    """Learn one journal record again (a person's label with the scans journaled before it)."""
    if rec.earlier is not None and isinstance(learner, PersonLearner):
        learner.observe(rec.ranges, rec.yaw, rec.label, earlier=rec.earlier)
    else:
        learner.observe(rec.ranges, rec.yaw, rec.label)


class LearnerCore:
    """Snapshot + journal + DemonstrationLearner: ``learn`` a labeled scan, ``snapshot``."""

    def __init__(self, out: str | os.PathLike, features: str | None = None,
                 resume: str | None = None, task: str | None = None,
                 tree_params: dict | None = None, stride: int = 1, min_delta: float = 0.0,
                 fsync_interval: float = 1.0, actions: ActionSet = DEFAULT_ACTIONS,
                 fold_journal: bool = False, journal_write=os.write, teacher: str = "script",
                 lag: int | None = None, vote: str | None = None):
        if lag is not None and not (isinstance(lag, int) and 0 <= lag <= MAX_LAG):
            raise ProcessError(f"learner: --lag must be 0..{MAX_LAG} scans, got {lag!r}",
                               EXIT_USAGE)
        if vote is not None and vote not in VOTES:
            raise ProcessError(f"learner: --vote must be one of {', '.join(VOTES)}, got {vote!r}",
                               EXIT_USAGE)
        if vote is not None and (teacher == "script" or resume is not None or fold_journal):
            raise ProcessError("learner: --vote is the person rule's, for a new tree (--teacher "
                               "person or auto, no --resume or --fold-journal)", EXIT_USAGE)
        self.out = Path(out)
        self.fold_journal = bool(fold_journal)
        self.jpath = journal_path(self.out)
        self.out.parent.mkdir(parents=True, exist_ok=True)
        spec = FEATURES[features] if features else None
        self.replayed = 0
        self.labels = LabelSet()  # the labels (origin, seq) journaled: deduplication and acks
        self.withdrawals = Withdrawals()  # what teachers took back (tombstones, provenance)
        self.spans: dict[str, tuple[int, int]] = {}  # origin -> lowest, highest seq journaled
        self.standing = 0  # labelled vectors journaled and not withdrawn
        self.rebuilds = 0
        self._early: list[Withdrawal] = []  # withdrawals before the lineage's first label
        if self.jpath.exists():
            self.journal = Journal.open(self.jpath, fsync_interval=fsync_interval,
                                        write=journal_write)
            self.learner, self.applied = self._recover(spec, resume)
        else:
            if self.out.exists() and (resume is None or Path(resume).resolve() != self.out.resolve()):
                raise ProcessError(
                    f"{self.out} exists but has no journal {self.jpath.name}: it was not written "
                    f"by a learner. Extend it with --resume {self.out} --out NEW_PATH", EXIT_USAGE)
            if teacher == "person" and fold_journal:
                raise ProcessError("--teacher person rebuilds its tree from every label of its "
                                   "journal: --fold-journal cannot be used with it", EXIT_USAGE)
            if resume is not None and teacher == "person":
                raise ProcessError("--teacher person builds its tree from its own labels: "
                                   "it cannot --resume another tree", EXIT_USAGE)
            if resume is None and spec is None:
                raise ProcessError("a new tree needs --features (wall or maze)", EXIT_USAGE)
            self._new = {"spec": spec, "resume": resume, "features": features, "task": task,
                         "params": {"spawn": "winner", **(tree_params or {})},
                         "stride": stride, "min_delta": min_delta, "lag": lag, "vote": vote,
                         "fsync_interval": fsync_interval, "write": journal_write,
                         "actions": actions}
            self.journal = None
            if teacher == "auto" and (resume is not None or fold_journal):
                log.info("--teacher auto with %s: the scripted rule (a person's rule "
                         "rebuilds its tree from its own whole journal)",
                         "--resume" if resume is not None else "--fold-journal")
                teacher = "script"
            if teacher == "auto":
                # the rule is chosen by the first label's source (``choose``): until then a
                # scripted learner stands in (it learns nothing) and no journal exists
                self.learner = self._start_learner("script")
                self.applied = 0
                log.info("new tree lineage at %s: its rule is chosen by the first label "
                         "(a person's at the console or keyboard: the person rule; else the "
                         "scripted teacher's)", self.out)
            else:
                self._create("person" if teacher == "person" else "script")
        if self.journal is not None:
            self._started()
        self.saved_applied = self.applied if self.out.exists() else -1
        self.seq = 0

    def _start_learner(self, rule: str) -> DemonstrationLearner:
        """A new lineage's learner for ``rule`` (``script`` or ``person``), or its parent's
        (``--resume``)."""
        n = self._new
        if n["resume"] is not None:
            return _resume(n["resume"], n["spec"])
        task = n["task"] or task_of_features(n["features"])
        if rule == "person":
            return PersonLearner(n["spec"], n["actions"], task=task, lag=n["lag"],
                                 vote=n["vote"], **n["params"])
        return DemonstrationLearner(n["spec"], n["actions"], task=task,
                                    stride=n["stride"], min_delta=n["min_delta"], **n["params"])

    def _create(self, rule: str, why: str = "") -> None:
        """Start the new lineage: its learner for ``rule`` and its journal (the header keeps
        the rule). Raises JournalError (nothing written: call again later)."""
        n = self._new
        learner = self._start_learner(rule)
        fork = parent = None  # fork: where the parent's journal stood when it was extended
        if n["resume"] is not None:
            parent = str(Path(n["resume"]).resolve())
            j = (load_snapshot(n["resume"])[3].get("provenance") or {}).get("journal") or {}
            if j.get("lineage"):
                fork = {"lineage": j["lineage"], "records": int(j.get("records", 0))}
        header = {"parent": parent, "fork": fork, "meta": learner.metadata()}
        self.journal = Journal.create(self.jpath, header, fsync_interval=n["fsync_interval"],
                                      write=n["write"])
        self.learner, self.applied = learner, 0
        log.info("new tree lineage %s at %s%s%s", self.journal.lineage, self.out,
                 f" (extending {parent})" if parent else "", why)

    @property
    def undecided(self) -> bool:
        """A new lineage whose rule waits for its first label (``--teacher auto``)."""
        return self.journal is None

    def lag_for(self, source: str | None) -> tuple[int, int]:
        """``(lag, window)`` of the pairing of a label from ``source`` (``Pairing``): this
        lineage's, or, while the rule is not chosen yet, the one it would take for that label
        (a person's: ``--lag N`` shifts it, ``--lag auto`` keeps the scans before it)."""
        if not self.undecided:
            return self.pairing()
        if not by_person(source):
            return 0, 0
        lag = self._new["lag"]
        return (0, MAX_LAG) if lag is None else (lag, 0)

    def pairing(self) -> tuple[int, int]:
        """``(lag, window)`` of this lineage's pairing (``Pairing(lag=..., window=...)``)."""
        return self.lag or 0, MAX_LAG if self.estimates else 0

    def choose(self, source: str | None) -> None:
        """The first label came from ``source``: start the lineage by the person rule when a
        person gave it (``client.labels.by_person``), else by the scripted teacher's; the
        withdrawals that came before it are journaled. Raises JournalError (call again)."""
        if not self.undecided:
            return
        rule = "person" if by_person(source) else "script"
        self._create(rule, f": the first label came from {source or 'an unnamed teacher'!r}, "
                           f"so it learns by the {'person' if rule == 'person' else 'scripted'}"
                           f" rule ({self.describe_rule() or 'each label as it arrives'})")
        self._started()
        self._journal_early()

    def _journal_early(self) -> None:
        """Journal the withdrawals that came before the lineage's first label (each once,
        also when a write failed half way: called again before the next label)."""
        while self._early:
            w = self._early[0]
            self.journal.append_withdrawal(w.origin, w.id, w.first, w.upto, w.ts, w.reason)
            self._early.pop(0)
            self.applied += 1

    def describe_rule(self) -> str:
        """How a person's lineage learns (its lag, its vote); "" for the script rule."""
        if not self.person:
            return ""
        learner = self.learner
        lag = (f"the lag estimated, {learner.estimated_lag} scans so far" if self.estimates
               else f"shifted {learner.lag} scans back")
        copies = (f", {learner.copies} jittered cop{'y' if learner.copies == 1 else 'ies'} a label"
                  if learner.copies else "")
        return f"{lag}, the {learner.vote} vote of {learner.k} nearest{copies}"

    def _started(self) -> None:
        self.learner.parent = self.journal.header.get("parent")
        if self.person and self.fold_journal:
            raise ProcessError(f"{self.out} is a person's tree, rebuilt from every label of its "
                               "journal: --fold-journal cannot be used with it", EXIT_USAGE)

    @property
    def features(self) -> FeatureSpec:
        return self.learner.features

    @property
    def person(self) -> bool:
        """A person's lineage (``--teacher person``): labels shifted by ``lag``, tree rebuilt."""
        return isinstance(self.learner, PersonLearner)

    @property
    def lag(self) -> int | None:
        """Scans a label is shifted back by when paired (0: the scan it names; None: a person's
        lag estimated by the learner from the scans before each label, ``estimates``)."""
        return self.learner.lag if self.person else 0

    @property
    def estimates(self) -> bool:
        """A person's lineage whose lag is estimated from the data: each label is journaled
        and learned with the scans displayed before it (``Pairing(window=MAX_LAG)``)."""
        return self.person and self.learner.lag is None

    @property
    def actions(self) -> ActionSet:
        return self.learner.actions

    def _recover(self, spec: FeatureSpec | None, resume: str | None):
        header = self.journal.header
        lineage = self.journal.lineage
        parent = header.get("parent")
        if resume is not None and (parent is None
                                   or Path(parent).resolve() != Path(resume).resolve()):
            raise ProcessError(
                f"{self.out} already holds a tree lineage ({'extending ' + parent if parent else 'a new tree'}"
                f"), not one extending {resume}: choose another --out", EXIT_USAGE)
        try:
            check_compatible(header.get("meta"), spec)
        except IncompatibleSnapshotError as exc:
            raise ProcessError(f"cannot continue {self.out}: {exc}", EXIT_USAGE) from exc
        start = 0
        learner = None
        if self.out.exists():
            _clf, _f, _a, meta = load_snapshot(self.out)
            prov = meta.get("provenance") or {}
            j = prov.get("journal") or {}
            if j.get("lineage") == lineage:
                learner = _resume(self.out, None)
                start = int(j.get("records", 0))
                try:  # the labels the snapshot holds (folded out of the journal, maybe)
                    self.labels = LabelSet.from_dict(j.get("labels"))
                    self.withdrawals = Withdrawals.from_dict(j.get("withdrawn"))
                except ValueError as exc:
                    raise ProcessError(f"snapshot {self.out}: {exc}", EXIT_USAGE) from exc
                self.standing = int(prov.get("standing", start))
            elif parent is None or Path(parent).resolve() != self.out.resolve():
                raise ProcessError(
                    f"snapshot {self.out} does not belong to journal {self.jpath} (lineage "
                    f"{j.get('lineage')!r} != {lineage!r}); move one of them aside", EXIT_USAGE)
        if learner is None:  # killed before its first snapshot: start where the lineage started
            learner = self._lineage_start()
        if self._person_rule():
            # a person's tree is rebuilt from every label: the whole journal again (the
            # withdrawals in it are held again below and stay out)
            learner = self._lineage_start()
            start, self.labels, self.standing = 0, LabelSet(), 0
        if start > len(self.journal):
            raise ProcessError(
                f"snapshot {self.out} includes {start} journal records but {self.jpath} holds "
                f"only {len(self.journal)}: the journal lost records", EXIT_USAGE)
        t0 = time.monotonic()
        withdrawn_later = False  # a tombstone after the snapshot: its tree may hold them
        for rec in self.journal.records(self.journal.base):  # what deduplication needs
            if not isinstance(rec, JournalWithdrawal):
                self._journaled(rec.origin, rec.seq)
            elif rec.index >= start:
                self._hold_withdrawal(rec.origin, rec.id, rec.first, rec.upto)
                withdrawn_later = True
        if withdrawn_later and not self.journal.base:
            learner = self._rebuilt()
        else:
            if withdrawn_later:
                log.error("labels were withdrawn after the last snapshot, but the journal was "
                          "folded (--fold-journal): those in the snapshot stay in the tree")
            for rec in self.journal.standing(start, withdrawn=self.withdrawals):
                _replay(learner, rec)
                self.standing += 1
        self.replayed = len(self.journal) - start
        log.info("recovered lineage %s: snapshot held %d journal records, replayed %d more in "
                 "%.2f s (%d nodes); %d identified labels held, %d withdrawals", lineage, start,
                 self.replayed, time.monotonic() - t0, learner.nodes, len(self.labels),
                 len(self.withdrawals))
        return learner, len(self.journal)

    def _person_rule(self) -> bool:
        meta = self.journal.header.get("meta") or {}
        return (meta.get("learning") or {}).get("rule") == PERSON_RULE

    def _lineage_start(self) -> DemonstrationLearner:
        """The tree this lineage started from: a person's learner (rebuilt from the whole
        journal), its parent's (``--resume``) or a new one."""
        header = self.journal.header
        if self._person_rule():
            meta = header["meta"]
            return PersonLearner.from_metadata(meta, FeatureSpec.from_dict(meta["features"]),
                                               ActionSet.from_dict(meta["actions"]))
        if header.get("parent") is not None:
            return _resume(header["parent"], None)
        meta = header["meta"]
        learning = meta.get("learning") or {}
        return DemonstrationLearner(
            FeatureSpec.from_dict(meta["features"]), ActionSet.from_dict(meta["actions"]),
            task=meta.get("task"), stride=int(learning.get("stride", 1)),
            min_delta=float(learning.get("min_delta", 0.0)), **(meta.get("tree_params") or {}))

    def _journaled(self, origin: str | None, seq: int | None) -> None:
        """A label record of ``origin`` is in the journal: held, and within its span."""
        if origin is None:
            return
        self.labels.add(origin, seq)
        lo, hi = self.spans.get(origin, (seq, seq))
        self.spans[origin] = (min(lo, seq), max(hi, seq))

    def _hold_withdrawal(self, origin: str, wid: int, first: int, upto: int) -> bool:
        """Record a withdrawal; True when it was not held before."""
        self.labels.add_range(origin, first, upto)  # never journaled, never resent
        return self.withdrawals.add(origin, wid, first, upto)

    def _rebuilt(self) -> DemonstrationLearner:
        """The lineage's start plus every labelled vector of the journal that stands."""
        learner = self._lineage_start()
        self.standing = 0
        for rec in self.journal.standing(withdrawn=self.withdrawals):
            _replay(learner, rec)
            self.standing += 1
        learner.parent = self.journal.header.get("parent")
        self.rebuilds += 1
        return learner

    def withdraw(self, w: Withdrawal) -> bool | None:
        """Journal a teacher's withdrawal (a tombstone, flushed) and hold it: its labels are
        never learned from now on. True when the tree holds some of them (``rebuild``), False
        when none, None when the withdrawal was held already. Raises JournalError (nothing
        written: call again later)."""
        if self.withdrawals.holds(w.origin, w.id):
            self._hold_withdrawal(w.origin, w.id, w.first, w.upto)
            return None
        if self.undecided:  # no label journaled yet: journaled with the lineage (``choose``)
            self._early.append(w)
            self._hold_withdrawal(w.origin, w.id, w.first, w.upto)
            return False
        self.journal.append_withdrawal(w.origin, w.id, w.first, w.upto, w.ts, w.reason)
        self.applied += 1
        self._hold_withdrawal(w.origin, w.id, w.first, w.upto)
        lo, hi = self.spans.get(w.origin, (0, -1))
        return w.first <= hi and w.upto > lo

    def rebuild(self) -> bool:
        """Rebuild the tree without the withdrawn labels; False (logged) when the journal was
        folded (``--fold-journal``): the records the tree was learned from are gone."""
        if self.journal.base:
            log.error("labels were withdrawn, but the journal's first %d records were folded "
                      "into the snapshot (--fold-journal): the tree cannot be rebuilt without "
                      "them; they stay in the tree (the later ones are never learned)",
                      self.journal.base)
            return False
        before = self.learner.nodes
        t0 = time.monotonic()
        self.learner = self._rebuilt()
        log.info("rebuilt the tree without the withdrawn labels (%d withdrawals, %d labels): "
                 "%d labelled vectors stand, %d -> %d nodes, in %.2f s", len(self.withdrawals),
                 self.withdrawals.labels(), self.standing, before, self.learner.nodes,
                 time.monotonic() - t0)
        return True

    def learn(self, scan_id: int, ts: float, ranges, yaw: float, label: str,
              origin: str | None = None, seq: int | None = None,
              earlier=(), source: str | None = None) -> bool | None:
        """Journal (flushed) then learn one labeled scan; True when it reached the tree. A label
        with an identity (``origin``, ``seq``) is recorded in ``labels`` once journaled; one
        held already (a resend) is neither journaled nor learned again: None. Raises
        FeatureError (a scan the features cannot use: nothing written) or JournalError (the
        journal cannot be written, e.g. disk full: nothing written, nothing learned; call again
        later with the same vector). The first label of a lineage whose rule is not chosen
        yet chooses it by its ``source`` (``choose``)."""
        if self.holds(origin, seq):
            return None
        if self.undecided:
            self.choose(source)
        elif self._early:
            self._journal_early()
        x = self.learner.features.extract(ranges, yaw)
        back = None
        if self.estimates:  # the scans before it, (ranges, yaw) nearest first: the lag's data
            back = np.zeros((len(earlier), len(x)), np.float32)
            for i, (r, a) in enumerate(earlier):
                back[i] = self.learner.features.extract(r, a)
        self.journal.append(scan_id, ts, label, ranges, yaw, x.astype(np.float32), origin, seq,
                            back)
        self._journaled(origin, seq)
        learned = (self.learner.observe(ranges, yaw, label, earlier=back) if self.estimates
                   else self.learner.observe(ranges, yaw, label))
        self.applied += 1
        self.standing += 1
        return learned

    def holds(self, origin: str | None, seq: int | None) -> bool:
        """True when the label (origin, seq) is journaled already (or was refused)."""
        return origin is not None and (origin, seq) in self.labels

    def describe(self) -> str:
        """What the tree is, for the learner's first line: its features, the vectors it was
        learned from (a tree extended with ``--resume`` holds its parent's too) and how many of
        them this lineage's journal holds, its size."""
        learner = self.learner
        if self.undecided:
            return (f"features {self.features.to_dict()['beams']}, a new tree: its rule is "
                    f"chosen by the first label's source (--teacher auto)")
        rule = f"; a person's labels ({self.describe_rule()})" if self.person else ""
        return (f"features {self.features.to_dict()['beams']}, {learner.vectors} vectors so far "
                f"({self.applied} journaled in lineage {self.journal.lineage}), "
                f"{learner.nodes} nodes{rule}")

    @property
    def dirty(self) -> bool:
        """Labeled vectors not in the snapshot yet (and a tree to write: an empty one is not)."""
        return self.applied != self.saved_applied and self.learner.vectors > 0

    def metadata(self) -> dict:
        meta = self.learner.metadata()
        prov = meta["provenance"]
        prov["journal"] = {"path": self.jpath.name, "lineage": self.journal.lineage,
                           "records": self.applied, "labels": self.labels.to_dict(),
                           "withdrawn": self.withdrawals.to_dict()}
        prov["labeled"] = self.applied
        prov["standing"] = self.standing
        prov["time"] = time.time()
        return meta

    def snapshot(self) -> bytes:
        """Write the snapshot atomically (journal fsync'd first); returns its bytes."""
        self.journal.sync()
        self.learner.classifier.save(str(self.out), metadata=self.metadata())
        self.saved_applied = self.applied
        if self.fold_journal:  # the snapshot (durable: written atomically) holds them now
            try:
                self.journal.fold(self.applied)
            except JournalError as exc:  # the journal is whole either way: retried next time
                log.warning("%s", exc)
        self.seq += 1
        return self.out.read_bytes()

    def close(self) -> None:
        if self.journal is not None:
            self.journal.close()


def _resume(path, spec: FeatureSpec | None) -> DemonstrationLearner:
    try:
        return DemonstrationLearner.resume(path, spec)
    except IncompatibleSnapshotError as exc:  # names the file
        raise ProcessError(f"cannot extend {exc}", EXIT_USAGE) from exc
    except FileNotFoundError as exc:
        raise ProcessError(f"snapshot {path} does not exist", EXIT_USAGE) from exc
    except SnapshotError as exc:  # names the file
        raise ProcessError(f"cannot load snapshot {exc}", EXIT_USAGE) from exc
    except Exception as exc:  # anything else a hostile snapshot makes fail
        raise ProcessError(f"cannot load snapshot {path}: {exc}", EXIT_USAGE) from exc




# ---- the process --------------------------------------------------------------------------
def main(args: argparse.Namespace, *, journal_write=os.write) -> int:
    """``rhbl learner``; ``journal_write`` writes the journal's records (``client.journal``'s
    seam for injected write failures: campaigns/full_disk.py)."""
    core: list[LearnerCore] = []

    def check() -> None:  # the snapshot and journal, opened before any connection: bad ones
        files.check_output(args.out, "--out", make=True)  # exit 2 at once (its folder made)
        files.check_output(journal_path(args.out), "--out's journal")
        core.append(LearnerProcess.open_core(args, journal_write))

    # the token is declared once the label subscription is in place: a teacher that waits for
    # it (rhbl teacher) then loses no label
    return run_role("learner", args, lambda ctx: LearnerProcess(ctx, core[0]).run(),
                    early_token=False, check=check)


class LearnerProcess:
    """The learner over zenoh: scans and labels paired as they arrive (``Pairing``), learned in
    order by ``LearnerCore``; snapshots announced with a ``TreeNotice`` and served on a query.

    SIGINT/SIGTERM set ``stopping``: the loop withdraws the token, learns what already arrived
    (up to ``--drain`` s), writes the final snapshot and returns."""

    def __init__(self, ctx: Context, core: LearnerCore):
        self.ctx, self.args = ctx, ctx.args
        self.stopping = False
        on_stop_signal(self.request_stop)
        self.core = core
        ctx.scope.callback(self.close_journal)  # also on a path that never reaches finish()
        self.latest = self.core.out.read_bytes() if self.core.out.exists() else None
        self.snap_key = keys.learner_snapshot_key(ctx.robot)
        self.watch = ScanWatch("learner", keys.scan_key(ctx.robot), stale=3.0)
        # labels are paired with their scans as they arrive: nothing but labeled scans is queued
        # (a lineage whose rule is not chosen yet shifts a person's labels only: ``lag_for``)
        self.pairing = Pairing(self.args.scan_buffer, self.args.match_timeout,
                               on_scan_seen=self.watch.seen,
                               **({"lag_of": self._lag_of} if self.core.undecided else
                                  {"lag": self.core.lag or 0,
                                   "window": MAX_LAG if self.core.estimates else 0}))
        self.stats = {"learned": 0, "paired": 0, "rejected": 0, "lost": 0, "duplicates": 0,
                      "withdrawals": 0, "withdrawn_skipped": 0}
        # teachers' withdrawals as they arrive (decoded in zenoh's thread), applied by the loop
        self.taken_back: deque[Withdrawal] = deque()
        self.withdraw_decoder = Decoder(log)
        ctx.report(self.counters)
        # labeled scans waiting to be journaled (in order): empty unless the journal cannot be
        # written (disk full); nothing is learned before it is journaled
        self.backlog: deque[tuple[Scan, TeacherAction]] = deque()
        self.waiting: set[tuple[str, int]] = set()  # (origin, seq) of the backlog's labels
        self.retry_at = 0.0
        self.failures = 0  # journal writes failed in a row
        self.drain_until: float | None = None  # after a stop request: finish what arrived
        self.notice_pub = self.subs = None
        self.tree_size = (0, 0)  # nodes, height of the last snapshot written
        self.acks: Acknowledgements | None = None  # once the ack publisher is declared

    def _lag_of(self, act: TeacherAction) -> int:  # zenoh's threads, under the pairing's lock
        return self.core.lag_for(act.source)

    @staticmethod
    def open_core(args: argparse.Namespace, journal_write=os.write) -> LearnerCore:
        """The learner's snapshot and journal of ``args`` (``--out``, ``--resume``, ...);
        ProcessError when they cannot be used."""
        try:
            return LearnerCore(
                args.out, features=args.features, resume=args.resume, task=args.task,
                tree_params={"spawn": args.spawn,
                             **({"max_nodes": args.max_nodes} if args.max_nodes else {})},
                stride=args.stride, min_delta=args.min_delta,
                fsync_interval=args.fsync_interval, fold_journal=args.fold_journal,
                journal_write=journal_write, teacher=args.teacher, lag=args.lag,
                vote=args.vote)
        except JournalError as exc:
            raise ProcessError(f"learner: {exc}") from exc

    def request_stop(self) -> None:
        self.stopping = True

    # -- zenoh --
    def declare(self) -> None:
        ctx, robot = self.ctx, self.ctx.robot
        self.notice_pub = ctx.publisher(keys.learner_notice_key(robot))
        self.acks = Acknowledgements(ctx.publisher(keys.learner_ack_key(robot)).put,
                                     self.core.labels, withdrawals=self.core.withdrawals)
        self.subs = [
            ctx.subscriber(keys.scan_key(robot), self.on_scan),
            ctx.subscriber(keys.teacher_action_key(robot), self.on_label),
            ctx.subscriber(keys.teacher_labeled_key(robot), self.on_labeled),
            ctx.subscriber(keys.teacher_withdraw_key(robot), self.on_withdraw),
        ]
        ctx.queryable(self.snap_key, self.on_query)
        # what survived (journal + snapshot), for a teacher that resends what we do not hold
        self.acks.publish(set(self.core.labels.origins()) | set(self.core.withdrawals.origins()))
        ctx.declare_token()  # after the subscriptions: the token means "ready to receive labels"

    def on_scan(self, sample) -> None:
        self.pairing.on_scan(sample.payload.to_bytes())

    def on_label(self, sample) -> None:
        self.pairing.on_label(sample.payload.to_bytes())

    def on_labeled(self, sample) -> None:
        self.pairing.on_labeled(sample.payload.to_bytes())

    def on_withdraw(self, sample) -> None:
        w = self.withdraw_decoder.decode(Withdrawal, sample.payload.to_bytes())
        if w is not None:
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
        core = self.core
        try:
            self.latest = core.snapshot()
        except OSError as exc:  # disk full, ...: the journal still holds every vector
            log.error("cannot write snapshot %s (%s); retrying in %.0f s (the journal holds "
                      "every labeled vector)", core.out, exc, self.args.snapshot_every)
            return False
        self.tree_size = (core.learner.nodes, core.learner.height)  # as just written
        note = TreeNotice(seq=core.seq, nodes=self.tree_size[0], height=self.tree_size[1],
                          vectors=core.standing,
                          snapshot_id=f"{core.journal.lineage}:{core.applied}", ts=time.time())
        self.notice_pub.put(note.encode())
        return True

    # -- learning --
    def learn(self, scan: Scan, act: TeacherAction) -> None:
        if act.action not in self.core.actions:
            self.stats["rejected"] += 1
            log.warning("label %r for scan %d is not an action of this tree %s: dropped",
                        act.action, act.scan_id, self.core.actions.names)
            self.acks.handled(act, journaled=False)
            return
        key = (act.origin, act.seq)
        if key in self.core.withdrawals:  # taken back by its teacher before it came
            self.stats["withdrawn_skipped"] += 1
            self.acks.handled(act, journaled=True)
            return
        if act.origin is not None and (self.core.holds(act.origin, act.seq)
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
        if act.origin is not None:
            self.waiting.add(key)
        if len(self.backlog) == 1 or time.monotonic() >= self.retry_at:
            self.flush_backlog()

    def flush_backlog(self) -> None:
        """Journal and learn the waiting labeled scans, in order, until the journal fails."""
        while self.backlog:
            scan, act = self.backlog[0]
            undecided = self.core.undecided
            try:
                learned = self.core.learn(
                    scan.id, scan.ts, scan.ranges, float(scan.pose[2]), act.action, act.origin,
                    act.seq, [(s.ranges, float(s.pose[2])) for s in getattr(scan, "earlier", ())],
                    act.source)
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
            if undecided and not self.core.undecided:  # this label chose the rule
                self.pairing.settle(*self.core.pairing())
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
                held = self.core.withdraw(w)
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
        if rebuild and self.core.rebuild():
            self.publish()

    def _pop(self) -> None:
        """Take the oldest labeled scan off the backlog."""
        _, act = self.backlog.popleft()
        self.waiting.discard((act.origin, act.seq))

    def _journal_failed(self, exc: Exception) -> None:
        self.retry_at = time.monotonic() + _RETRY
        self.failures += 1
        n = self.failures
        if n <= 3 or n % 60 == 0:
            log.error("cannot write the journal (%s): %d labeled vectors kept in memory "
                      "(at most %d), retrying every %.0f s; nothing is learned before "
                      "it is journaled", exc, len(self.backlog), MAX_BACKLOG, _RETRY)
        while len(self.backlog) > MAX_BACKLOG:
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
        core = self.core
        if core.dirty:
            try:
                self.latest = core.snapshot()
            except OSError as exc:  # the journal holds every vector; retried while learning
                log.error("cannot write snapshot %s (%s); retrying later", core.out, exc)
        log.info("learning: %s; snapshot %s", core.describe(), core.out)
        self.tree_size = (core.learner.nodes, core.learner.height)

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
            if self.core.dirty and now - last_snap >= self.args.snapshot_every:
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
        ps, core = self.pairing.stats, self.core
        nodes, height = self.tree_size
        log.info("vectors %d (learned %d this run), nodes %d, height %d (last snapshot), "
                 "unmatched %d; %d labeled scans waiting, %d unlabeled scans forgotten",
                 core.applied, self.stats["learned"], nodes, height, ps["unmatched"],
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
            if lost or (self.core.dirty and not self.publish()):
                code = 1
            self.report(lost)
        finally:
            if not self.close_journal():
                code = 1
        return code

    def close_journal(self) -> bool:
        """Close (fsync) the journal; False (logged) when that failed. Idempotent."""
        try:
            self.core.close()
        except OSError as exc:
            log.error("closing the journal %s failed: %s", self.core.jpath, exc)
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
        core = self.core
        rule = "undecided" if core.undecided else "person" if core.person else "script"
        return {**self.stats, "rule": rule, "vectors": core.applied, "replayed": core.replayed,
                "standing": core.standing, "rebuilds": core.rebuilds,
                "withdrawn_labels": core.withdrawals.labels(),
                "nodes": core.learner.nodes, "height": core.learner.height,
                "pairing": dict(self.pairing.stats), "backlog": len(self.backlog),
                "dropped": {**self.pairing.decoder.counts, **self.withdraw_decoder.counts}}

    def report(self, lost: int) -> None:
        ps, st, core = self.pairing.stats, self.stats, self.core
        log.info("stopped: %d labeled vectors (%d this run, %d learned, %d unmatched "
                 "labels, %d malformed, %d rejected, %d resent by the teacher, %d duplicates "
                 "skipped, %d lost), %d nodes, height %d; snapshot %s; %d scans received, "
                 "%d unlabeled ones forgotten, at most %d labeled scans waited to be learned",
                 core.applied, st["paired"], st["learned"], ps["unmatched"], self.pairing.decoder.total,
                 st["rejected"], ps["resent"], st["duplicates"], lost, core.learner.nodes,
                 core.learner.height, core.out, ps["scans"], ps["forgotten"], ps["max_ready"])
