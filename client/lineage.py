"""A learner's lineage: its snapshot, its journal and the tree learned from them.

A ``Lineage`` is what ``rhbl learner`` keeps on disk and in memory, without zenoh (testable on
its own): the journal ``<out>.journal`` every labeled vector is appended to (flushed) before it
is learned (``client.journal``), the snapshot written atomically that records how many journal
records it includes, the recovery of a killed learner (last snapshot + the journal records after
it), the labels held (``LabelSet``: deduplication and acknowledgements), the teachers'
withdrawals (tombstones; the tree rebuilt without their labels) and the rule checks of a new
lineage (``--teacher``, ``--lag``, ``--resume``, ``--fold-journal``). The learning rule is
``client.behaviour.rule``'s (``rule_for``), kept in the journal's header and every snapshot;
a recovered lineage learns by the rule its header records (``LearningRule.of``). The process
around it (session, pairing, publishing, stats) is ``client.roles.learner``.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import time
from pathlib import Path

import numpy as np

from client.behaviour.actions import DEFAULT_ACTIONS, ActionSet
from client.behaviour.features import DEFAULT_FEATURES, FEATURES, FeatureSpec
from client.behaviour.goals import (
    GoalLearner,
    Goals,
    GoalStep,
    PersonGoalLearner,
    learner_of,
    resume_learner,
)
from client.behaviour.learning import (
    DemonstrationLearner,
    IncompatibleSnapshotError,
    check_compatible,
    load_snapshot,
)
from client.behaviour.rule import PERSON, LearningRule, rule_for
from client.behaviour.tasks import task_of_features
from client.behaviour.teaching import PersonLearner
from client.journal import (
    Journal,
    JournalError,
    JournalWithdrawal,
    LabelSet,
    Withdrawals,
    journal_path,
)
from client.labels import OUTBOX, by_person
from process.runtime import EXIT_USAGE, ProcessError
from protocol.messages import Withdrawal
from rhbl import SnapshotError

__all__ = ["AHEAD", "Lineage", "LineageLock", "Refused", "lock_path"]

log = logging.getLogger(__name__)


AHEAD = OUTBOX
"""How far past the highest label a learner holds of a teacher session a withdrawal may reach:
a teacher keeps at most ``client.labels.OUTBOX`` labels unacknowledged, so it has given none
further than that beyond what the learner holds (acknowledged labels are journaled)."""


class Refused(ValueError):
    """Bad input refused for good (nothing journaled, nothing acknowledged); ``kind`` names
    what was wrong, for the learner's counters (``--stats``: ``refused``)."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


def lock_path(snapshot: str | os.PathLike) -> Path:
    """The lock file of the lineage at ``snapshot``: ``<snapshot>.lock``."""
    return Path(f"{os.fspath(snapshot)}.lock")


class LineageLock:
    """One learner per lineage: an exclusive OS lock on ``<snapshot>.lock`` for as long as the
    learner runs (as SQLite and rosbag2 lock what they write). Two learners journaling the same
    lineage interleave their records and leave a journal no learner can open again.

    The lock is ``fcntl.lockf`` (POSIX record locks): the kernel drops it when the process
    ends however it ends (SIGKILL, a crash), so a dead learner never leaves a stale lock; the
    file stays, holding the last holder's pid for the message a refused learner gives. It is
    held per process, so one process that opens a lineage twice (a test that "restarts" a
    learner in-process) is not refused. ``wait`` s: how long to wait for a learner that still
    holds it (one draining after SIGTERM) before refusing; ProcessError (exit 1) naming the
    holder's pid when it is still held."""

    def __init__(self, snapshot: str | os.PathLike, wait: float = 0.0):
        self.path = lock_path(snapshot)
        self.fd: int | None = None
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise ProcessError(f"learner: cannot open the lineage's lock {self.path}: "
                               f"{exc.strerror or exc}") from exc
        deadline = time.monotonic() + max(0.0, float(wait))
        said = False
        while True:
            try:
                fcntl.lockf(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as exc:
                if exc.errno not in (errno.EACCES, errno.EAGAIN):
                    self.close()
                    raise ProcessError(f"learner: cannot lock {self.path}: {exc}") from exc
            holder = self._holder()
            if time.monotonic() >= deadline:
                self.close()
                raise ProcessError(
                    f"learner: the lineage {snapshot} is held by another learner (pid "
                    f"{holder}, lock {self.path}): one learner per lineage. Stop it first (a "
                    f"stopping learner drains for up to its --drain s), or wait for it with "
                    f"--lock-wait SECONDS")
            if not said:
                log.info("the lineage %s is held by another learner (pid %s): waiting up to "
                         "%.0f s for it to finish", snapshot, holder, wait)
                said = True
            time.sleep(0.1)
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, f"{os.getpid()}\n".encode(), 0)

    def _holder(self) -> str:
        try:
            return os.pread(self.fd, 32, 0).decode(errors="replace").strip() or "unknown"
        except OSError:
            return "unknown"

    def close(self) -> None:
        """Release the lock (closing the file releases it). Idempotent."""
        if self.fd is not None:
            fd, self.fd = self.fd, None
            os.close(fd)


def _replay(learner: DemonstrationLearner, rec) -> None:
    """Learn one journal record again (a person's label with the scans journaled before it, a
    goal behaviour's with its goal and what was seen)."""
    kw = ({"earlier": rec.earlier} if rec.earlier is not None
          and isinstance(learner, PersonLearner) else {})
    if rec.goal is not None and isinstance(learner, GoalLearner):
        learner.observe(rec.ranges, rec.yaw, rec.label,
                        GoalStep.of(rec.goal, rec.reached, rec.seen), **kw)
    else:
        learner.observe(rec.ranges, rec.yaw, rec.label, **kw)


class Lineage:
    """Snapshot + journal + DemonstrationLearner: ``learn`` a labeled scan, ``snapshot``.

    Held by one process at a time (``LineageLock`` on ``<out>.lock``, taken before anything of
    the lineage is read, released by ``close``; ``lock_wait`` s to wait for another holder).
    A lineage learns from one laser: ``beams``, the beam count of its journal's labels. A new
    tree told no ``features`` (and no ``resume``) sees all round: ``DEFAULT_FEATURES``."""

    def __init__(self, out: str | os.PathLike, features: str | FeatureSpec | None = None,
                 resume: str | None = None, task: str | None = None,
                 tree_params: dict | None = None, stride: int = 1, min_delta: float = 0.0,
                 fsync_interval: float = 1.0, actions: ActionSet = DEFAULT_ACTIONS,
                 fold_journal: bool = False, journal_write=os.write, teacher: str = "script",
                 lag: int | None = None, lock_wait: float = 0.0, guard: bool | None = None,
                 goals: Goals | None = None):
        max_lag = PERSON.alignment.max_lag
        if lag is not None and not (isinstance(lag, int) and 0 <= lag <= max_lag):
            raise ProcessError(f"learner: --lag must be 0..{max_lag} scans, got {lag!r}",
                               EXIT_USAGE)
        self.out = Path(out)
        self.fold_journal = bool(fold_journal)
        self.jpath = journal_path(self.out)
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.lock = LineageLock(self.out, lock_wait)  # before anything of the lineage is read
        try:
            self._open(features, resume, task, tree_params, stride, min_delta, fsync_interval,
                       actions, fold_journal, journal_write, teacher, lag, guard, goals)
        except BaseException:
            self.close()
            raise

    def _open(self, features, resume, task, tree_params, stride, min_delta, fsync_interval,
              actions, fold_journal, journal_write, teacher, lag, guard, goals) -> None:
        """Recover the lineage at ``out`` or start a new one (``__init__``'s arguments)."""
        # a shipped spec's name, or a spec itself (a behaviour's inline perception)
        spec = features if isinstance(features, FeatureSpec) else (
            FEATURES[features] if features else None)
        self.replayed = 0
        self.labels = LabelSet()  # the labels (origin, seq) journaled: deduplication and acks
        self.withdrawals = Withdrawals()  # what teachers took back (tombstones, provenance)
        self.spans: dict[str, tuple[int, int]] = {}  # origin -> lowest, highest seq journaled
        self.standing = 0  # labelled vectors journaled and not withdrawn
        self.beams: int | None = None  # the laser's beam count of the journal's labels
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
            if resume is None and spec is None:  # a new tree told no perception: all round
                features, spec = DEFAULT_FEATURES, FEATURES[DEFAULT_FEATURES]
                log.info("new tree with the default perception --features %s", features)
            self._new = {"spec": spec, "resume": resume, "features": features, "task": task,
                         "params": {"spawn": "winner", **(tree_params or {})},
                         "stride": stride, "min_delta": min_delta, "lag": lag, "guard": guard,
                         "fsync_interval": fsync_interval, "write": journal_write,
                         "actions": actions, "goals": goals}
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
        have = getattr(self.learner, "goals", None)
        if goals is not None and have != goals:
            told = "no goals" if have is None else f"the goals {list(have.beacons)}"
            raise ProcessError(f"{self.out}: its tree learns {told}, not the behaviour's "
                               f"{list(goals.beacons)} (within {list(goals.within)}): choose "
                               "another --out", EXIT_USAGE)
        if self.journal is not None:
            self._started()
        self.saved_applied = self.applied if self.out.exists() else -1
        self.seq = 0

    def _start_learner(self, rule: str) -> DemonstrationLearner:
        """A new lineage's learner for ``rule`` (``script`` or ``person``: ``rule_for``, with
        ``--lag`` and the behaviour's guard), or its parent's (``--resume``)."""
        n = self._new
        if n["resume"] is not None:
            return _resume(n["resume"], n["spec"])
        task = n["task"] or task_of_features(n["features"])
        chosen = rule_for(rule).replace(guard=n["guard"])
        if n["goals"] is not None and chosen.person:  # goals in order, a person's labels
            return PersonGoalLearner(n["spec"], n["goals"], n["actions"], task=task,
                                     background=True, rule=chosen.replace(lag=n["lag"]),
                                     **n["params"])
        if n["goals"] is not None:
            return GoalLearner(n["spec"], n["goals"], n["actions"], task=task, rule=chosen,
                               stride=n["stride"], min_delta=n["min_delta"], **n["params"])
        if chosen.person:
            return PersonLearner(n["spec"], n["actions"], task=task, background=True,
                                 rule=chosen.replace(lag=n["lag"]), **n["params"])
        return DemonstrationLearner(n["spec"], n["actions"], task=task, rule=chosen,
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
        return (0, PERSON.alignment.max_lag) if lag is None else (lag, 0)

    def pairing(self) -> tuple[int, int]:
        """``(lag, window)`` of this lineage's pairing (``Pairing(lag=..., window=...)``)."""
        return self.lag or 0, self.learner.rule.alignment.max_lag if self.estimates else 0

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
        """How a person's lineage learns (its lag, its editing); "" for the script rule."""
        if not self.person:
            return ""
        learner = self.learner
        lag = (f"the lag estimated, {learner.estimated_lag} scans so far" if self.estimates
               else f"shifted {learner.lag} scans back")
        copies = (f", {learner.copies} jittered cop{'y' if learner.copies == 1 else 'ies'} a label"
                  if learner.copies else "")
        return f"{lag}, edited by the sided vote of {learner.k} nearest{copies}"

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
        and learned with the scans displayed before it (``Pairing(window=max_lag)``)."""
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
                if self.beams is None:
                    self.beams = len(rec.ranges)
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
        return LearningRule.of(self.journal.header.get("meta")).person

    def _lineage_start(self) -> DemonstrationLearner:
        """The tree this lineage started from: a person's learner (rebuilt from the whole
        journal), its parent's (``--resume``) or a new one."""
        header = self.journal.header
        meta = header["meta"]
        rule = LearningRule.of(meta)
        if rule.person:
            cls = PersonGoalLearner if isinstance(meta.get("goals"), dict) else PersonLearner
            return cls.from_metadata(meta, FeatureSpec.from_dict(meta["features"]),
                                     ActionSet.from_dict(meta["actions"]), background=True)
        if header.get("parent") is not None:
            return _resume(header["parent"], None)
        return learner_of(meta)

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
        written: call again later) or ``Refused`` (``withdrawal_ahead``: it reaches more than
        ``AHEAD`` labels past the highest of the session held; nothing written, not held: a
        teacher that gave those labels resends it once they are journaled)."""
        if self.withdrawals.holds(w.origin, w.id):
            self._hold_withdrawal(w.origin, w.id, w.first, w.upto)
            return None
        top = self.highest(w.origin)
        if w.upto > top + 1 + AHEAD:
            raise Refused("withdrawal_ahead", (
                f"withdrawal {w.id} of teacher session {w.origin} names labels {w.first}.."
                f"{w.upto - 1}, but the highest label of that session held is {top} "
                f"(allowed: up to {top + AHEAD}): refused"))
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
              earlier=(), source: str | None = None, step: GoalStep | None = None
              ) -> bool | None:
        """Journal (flushed) then learn one labeled scan; True when it reached the tree. A label
        with an identity (``origin``, ``seq``) is recorded in ``labels`` once journaled; one
        held already (a resend) is neither journaled nor learned again: None. Raises
        FeatureError (a scan the features cannot use: nothing written) or JournalError (the
        journal cannot be written, e.g. disk full: nothing written, nothing learned; call again
        later with the same vector) or ``Refused`` (nothing written: ranges that are negative
        or not finite, or of another beam count than the journal's labels, ``beams``: a
        lineage learns from one laser, client.laser). The first label of a lineage whose rule
        is not chosen yet chooses it by its ``source`` (``choose``). A lineage of a behaviour with
        goals learns ``step`` (``GoalStep``: the goal pursued, the one reached, what was seen)
        with each scan; a label without it, or naming a beacon its goals do not, is ``Refused``
        (``goal``: nothing written)."""
        if self.holds(origin, seq):
            return None
        ranges = np.asarray(ranges)
        if self.beams is not None and len(ranges) != self.beams:
            raise Refused("beams", f"the scan of label {seq} of teacher session {origin} has "
                                   f"{len(ranges)} beams, the lineage's laser {self.beams}")
        if ranges.size and not (np.isfinite(ranges).all() and ranges.min() >= 0):
            raise Refused("ranges", f"the scan of label {seq} of teacher session {origin} has "
                                    "ranges that are negative or not finite")
        goals = isinstance(self.learner, GoalLearner)
        if goals and step is None:
            raise Refused("goal", f"label {seq} of teacher session {origin} names no goal: "
                                  "a tree with goals learns labels that say the goal pursued "
                                  "and what the fiducial finder saw (rhbl teacher --behaviour "
                                  "of a behaviour with goals)")
        try:
            for beacon in (step.goal, step.reached) if goals else ():
                if beacon is not None:
                    self.learner.goals.index_of(beacon)
        except ValueError as exc:
            raise Refused("goal", f"label {seq} of teacher session {origin}: {exc}") from None
        if self.undecided:
            self.choose(source)
        elif self._early:
            self._journal_early()
        x = self.learner.vector(ranges, yaw, step if goals else None)
        back = None
        if self.estimates and goals:  # the scans before it with the label's goal and sighting
            back = self.learner.earlier_vectors(earlier, step)
        elif self.estimates:  # the scans before it, (ranges, yaw) nearest first: the lag's data
            back = np.zeros((len(earlier), len(x)), np.float32)
            for i, (r, a) in enumerate(earlier):
                back[i] = self.learner.features.extract(r, a)
        self.journal.append(scan_id, ts, label, ranges, yaw, x.astype(np.float32), origin, seq,
                            back, **({} if not goals else {
                                "goal": step.goal, "reached": step.reached, "seen": step.rows()}))
        self._journaled(origin, seq)
        if self.beams is None:
            self.beams = len(ranges)
        kw = {"earlier": back} if self.estimates else {}
        learned = (self.learner.observe(ranges, yaw, label, step, **kw) if goals
                   else self.learner.observe(ranges, yaw, label, **kw))
        self.applied += 1
        self.standing += 1
        return learned

    def highest(self, origin: str) -> int:
        """The highest label number of teacher session ``origin`` held (journaled, or taken back
        by a withdrawal held); -1 when none."""
        top = self.spans.get(origin, (0, -1))[1]
        upto, above = self.labels.ack(origin)
        return max(top, upto - 1, max(above, default=-1))

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
        """Close (fsync) the journal, then release the lineage's lock. Idempotent."""
        try:
            if getattr(self, "journal", None) is not None:
                self.journal.close()
        finally:
            self.lock.close()


def _resume(path, spec: FeatureSpec | None) -> DemonstrationLearner:
    try:
        return resume_learner(path, spec)
    except IncompatibleSnapshotError as exc:  # names the file
        raise ProcessError(f"cannot extend {exc}", EXIT_USAGE) from exc
    except FileNotFoundError as exc:
        raise ProcessError(f"snapshot {path} does not exist", EXIT_USAGE) from exc
    except SnapshotError as exc:  # names the file
        raise ProcessError(f"cannot load snapshot {exc}", EXIT_USAGE) from exc
    except Exception as exc:  # anything else a hostile snapshot makes fail
        raise ProcessError(f"cannot load snapshot {path}: {exc}", EXIT_USAGE) from exc
