"""Label delivery, both ends: how a teacher's label reaches the learner's journal exactly once.

The teacher's end (``rhbl teacher``, ``rhbl console``):

- ``Outbox``: the labels a teacher session published and no learner acknowledged yet, each with
  the scan it answers, to be resent until one does (no zenoh: testable alone).
- ``LabelPublisher``: publishes a robot's labels (``rhbl/<robot>/teacher/action``), keeps
  them in the outbox (from the first, also before any learner is up), takes the
  acknowledgements (``rhbl/<robot>/learner/ack``) and resends what was missed
  (``rhbl/<robot>/teacher/labeled``); withdraws labels the person takes back
  (``rhbl/<robot>/teacher/withdraw``: an undo, a discarded episode), kept and resent alike.
- ``Learners``: which learners of the robot are up (their liveliness tokens).
- ``Hold``: the teacher's hold token, held while a teacher commands the robot.

The learner's end (``rhbl learner``, and offline ``rhbl train --from-recording``):

- ``Pairing``: pairs every label with exactly the scan it answers, as they arrive.
- ``Acknowledgements``: which labels were journaled, published in batches.

Importing this module loads no zenoh (retraining from a recording pairs without a session).
docs/reliability.md measures what it guarantees.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
import uuid
from collections import OrderedDict, deque
from dataclasses import dataclass, fields

from client.journal import LabelSet, Withdrawals
from protocol import keys
from protocol.decoding import Decoder
from protocol.messages import LabeledScan, LearnerAck, Scan, TeacherAction, Withdrawal

__all__ = [
    "ACK_BATCH",
    "ACK_EVERY",
    "BEHIND",
    "DRAIN",
    "MAX_BACKLOG",
    "MAX_BACKLOG_BYTES",
    "MAX_PENDING",
    "OUTBOX",
    "PERSON_SOURCES",
    "RESEND_AFTER",
    "Acknowledgements",
    "AnsweredScan",
    "Hold",
    "Learners",
    "Outbox",
    "Pairing",
    "LabelPublisher",
    "SOURCE",
    "by_person",
    "scan_bytes",
]

log = logging.getLogger(__name__)

SOURCE = "teacher"  # the labels' ``source`` of a scripted teacher (rhbl teacher --policy wall...)
# the labels' ``source`` of a person teaching by hand: at the console's page, at a terminal
# (rhbl teacher --policy keyboard); a learner's ``--teacher auto`` learns a new lineage by the
# person rule when its first label comes from one of these (``by_person``)
PERSON_SOURCES = ("console", "keyboard")


def by_person(source: str | None) -> bool:
    """True when a label's ``source`` says a person gave it by hand (``PERSON_SOURCES``)."""
    return source in PERSON_SOURCES

# labels published and not yet acknowledged by a learner, at most (then the teacher pauses):
# about 3 minutes of labels at 10 Hz, ~1.5 KB each (the label and its scan)
OUTBOX = 2000


RESEND_AFTER = 2.0  # s without an acknowledgement before a label is resent with its scan


DRAIN = 10.0  # s a stopping teacher waits for the acknowledgements of its last labels


# labeled scans kept in memory while the journal cannot be written (disk full): about an hour
# of demonstration at 10 Hz (~2 KB each); beyond that the oldest are dropped, counted and logged
MAX_BACKLOG = 36_000
MAX_BACKLOG_BYTES = 96 << 20  # and at most this much of their scans (``scan_bytes``)
MAX_PENDING = 4096  # labels waiting for their scan (a flood of labels naming scans never sent)


# labeled scans waiting to be learned beyond which the learner says (error) it falls behind
BEHIND = 600  # about a minute of demonstration at 10 Hz


# acknowledgements are batched: published at most this often (s), or after this many labels
ACK_EVERY = 0.15


ACK_BATCH = 50


class Outbox:
    """The labels a teacher session published and no learner acknowledged yet, each with the
    scan it answers (``LabeledScan``), to be resent until one does (no zenoh: testable alone).

    ``origin`` is the session's identity (random), ``seq`` numbers its labels from 0. ``label``
    at publishing (a dict insert), ``ack`` removes what a ``LearnerAck`` names, ``due`` gives
    the labels to resend now, ``everything`` all of them (a learner that (re)started). A label
    is due ``resend_after`` s after it was sent, then after twice as long each time (at most 16
    times), and only when the learner acknowledged a later label (this one was missed: its scan
    never reached the learner, say) or acknowledged nothing for ``resend_after`` s (stuck): a
    learner that is merely behind, acknowledging in order, gets no resends that would slow it
    down further. At most ``cap`` entries: ``full`` says the publisher must stop labelling
    (nothing is ever dropped). Thread-safe.

    ``withdraw(first, upto)`` takes the session's labels ``first <= seq < upto`` back (a
    ``Withdrawal``, numbered from 0): those not acknowledged yet are never sent again, and the
    withdrawal is kept until an acknowledgement's ``withdrawn`` covers it, resent like a label
    (``due_withdrawals``; ``withdrawals`` all of them, for a learner that (re)started)."""

    def __init__(self, cap: int = OUTBOX, resend_after: float = RESEND_AFTER,
                 origin: str | None = None, clock=time.monotonic):
        self.origin = origin or uuid.uuid4().hex[:16]
        self.cap, self.resend_after, self._clock = int(cap), float(resend_after), clock
        self._next = 0
        self._lock = threading.Lock()
        self._entries: dict[int, list] = {}  # seq -> [the label with its scan, due at, resends]
        self._next_due = float("inf")  # no entry is due before this
        self._acked_max = -1  # the highest seq acknowledged
        self._progress = clock()  # when an acknowledgement last removed a label
        self._withdrawals: dict[int, list] = {}  # id -> [the Withdrawal, due at, resends]
        self._next_wid = 0
        self.stats = {"published": 0, "acked": 0, "resent": 0, "max": 0, "withdrawals": 0,
                      "withdrawn": 0, "withdrawals_acked": 0, "refused": 0}

    def label(self, scan: Scan, action: str, executed: str | None,
              source: str = "teacher", **goal) -> LabeledScan:
        """The next label of this session for ``scan``, kept until acknowledged (``goal``: a
        goal behaviour's ``goal``, ``reached`` and ``seen``, ``TeacherAction``'s)."""
        with self._lock:
            seq, self._next = self._next, self._next + 1
            item = LabeledScan(scan_id=scan.id, action=action, origin=self.origin, seq=seq,
                               ranges=scan.ranges, yaw=float(scan.pose[2]), source=source,
                               ts=scan.ts, executed=executed, **goal)
            due = self._clock() + self.resend_after
            self._entries[seq] = [item, due, 0]
            self._next_due = min(self._next_due, due)
            self.stats["published"] += 1
            self.stats["max"] = max(self.stats["max"], len(self._entries))
        return item

    def withdraw(self, first: int, upto: int, reason: str = "") -> Withdrawal:
        """Take back this session's labels ``first <= seq < upto`` (clipped to those published;
        ValueError when none is left): a ``Withdrawal`` kept until acknowledged."""
        with self._lock:
            first, upto = max(0, int(first)), min(int(upto), self._next)
            if first >= upto:
                raise ValueError(f"no label of session {self.origin} to withdraw in "
                                 f"[{first}, {upto}) ({self._next} published)")
            w = Withdrawal(origin=self.origin, id=self._next_wid, first=first, upto=upto,
                           ts=time.time(), reason=reason)
            self._next_wid += 1
            for q in [q for q in self._entries if first <= q < upto]:
                del self._entries[q]  # never sent again: the learner holds them as withdrawn
            self._withdrawals[w.id] = [w, self._clock() + self.resend_after, 0]
            self.stats["withdrawals"] += 1
            self.stats["withdrawn"] += upto - first
        return w

    def ack(self, upto: int, seqs=(), withdrawn: int | None = None,
            refused: int | None = None) -> int:
        """Forget the labels with ``seq < upto`` and those in ``seqs`` (and the withdrawals with
        ``id < withdrawn``); how many labels were held. ``refused``: how many of this
        session's labels the learner refused as bad input (``stats["refused"]``: acknowledged,
        never journaled, so not held)."""
        with self._lock:
            if refused is not None:
                self.stats["refused"] = max(self.stats["refused"], int(refused))
            if withdrawn is not None:
                for wid in [k for k in self._withdrawals if k < withdrawn]:
                    del self._withdrawals[wid]
                    self.stats["withdrawals_acked"] += 1
            gone = [q for q in self._entries if q < upto]
            gone += [q for q in set(seqs) if q >= upto and q in self._entries]
            for q in gone:
                del self._entries[q]
            self._acked_max = max(self._acked_max, upto - 1, max(seqs, default=-1))
            if gone:
                self._progress = self._clock()
            self.stats["acked"] += len(gone)
            return len(gone)

    def due(self) -> list[LabeledScan]:
        """The labels to resend now (see the class), marked resent."""
        now = self._clock()
        out = []
        with self._lock:
            if now < self._next_due:
                return out
            stalled = now - self._progress >= self.resend_after
            nxt = float("inf")
            for q, e in self._entries.items():
                if e[1] <= now:
                    if q < self._acked_max or stalled:
                        e[2] += 1
                        e[1] = now + self.resend_after * 2 ** min(e[2], 4)
                        out.append(e[0])
                    else:  # waiting its turn at a learner that acknowledges in order
                        e[1] = now + self.resend_after / 4
                nxt = min(nxt, e[1])
            self._next_due = nxt
            self.stats["resent"] += len(out)
        return out

    def due_withdrawals(self) -> list[Withdrawal]:
        """The withdrawals unacknowledged for their resend time (doubling), marked resent."""
        now = self._clock()
        with self._lock:
            out = []
            for e in self._withdrawals.values():
                if e[1] <= now:
                    e[2] += 1
                    e[1] = now + self.resend_after * 2 ** min(e[2], 4)
                    out.append(e[0])
            return out

    def withdrawals(self) -> list[Withdrawal]:
        """Every unacknowledged withdrawal, in order, marked sent now."""
        with self._lock:
            now = self._clock()
            for e in self._withdrawals.values():
                e[1], e[2] = now + self.resend_after, 0
            return [self._withdrawals[k][0] for k in sorted(self._withdrawals)]

    @property
    def unacknowledged_withdrawals(self) -> int:
        with self._lock:
            return len(self._withdrawals)

    @property
    def next_seq(self) -> int:
        """The seq the next label gets (every label below it was published)."""
        with self._lock:
            return self._next

    def everything(self) -> list[LabeledScan]:
        """Every unacknowledged label, marked sent now (for a learner that (re)started)."""
        with self._lock:
            now = self._clock()
            for e in self._entries.values():
                e[1], e[2] = now + self.resend_after, 0
            if self._entries:
                self._next_due = now + self.resend_after
            self._progress = now  # a new learner: give it resend_after to acknowledge
            self.stats["resent"] += len(self._entries)
            return [e[0] for e in sorted(self._entries.values(), key=lambda e: e[0].seq)]

    def seqs(self) -> list[int]:
        """The seqs of the unacknowledged labels, in order."""
        with self._lock:
            return sorted(self._entries)

    @property
    def full(self) -> bool:
        return len(self) >= self.cap

    def __len__(self) -> int:
        with self._lock:
            return len(self._entries)


class LabelPublisher:
    """A teacher's labels for a robot, on ``.../teacher/action`` (never dropped). Shared by
    ``rhbl teacher`` and ``rhbl console``, so both label alike (their commands go through
    ``client.player.PlayerClient``).

    With an ``outbox`` (its size; 0 = none, pure teleop: labels without identity, unkept) labels
    are delivered at least once: each label carries the session's ``origin`` and a ``seq`` and
    stays in the ``Outbox`` with its scan until a learner acknowledges it on
    ``rhbl/<robot>/learner/ack``, also a label given before any learner was up; a background
    thread resends (``rhbl/<robot>/teacher/labeled``, the label with its scan) all of them at
    once when a learner's token appears (the first learner, a restarted one) and the missed
    ones (``Outbox.due``), while a learner is up. The caller stops labelling while
    ``outbox.full``. ``withdraw`` takes labels back (``rhbl/<robot>/teacher/withdraw``), kept
    and resent the same way until acknowledged. ``source`` is the labels' ``source`` field:
    ``SOURCE`` for a scripted teacher, one of ``PERSON_SOURCES`` for a person (the learner's
    ``--teacher auto`` picks its rule by it)."""

    def __init__(self, session, robot: str, outbox: int = OUTBOX,
                 resend_after: float = RESEND_AFTER, source: str = SOURCE):
        import zenoh

        self.robot = robot
        self.source = source
        self.act_pub = session.declare_publisher(keys.teacher_action_key(robot),
                                                 congestion_control=zenoh.CongestionControl.BLOCK)
        self.outbox: Outbox | None = None
        self.learners: Learners | None = None
        self.decoder = Decoder(log)  # malformed acknowledgements, dropped and counted
        self.published = 0  # labels published (kept in the outbox or not)
        self._decls = [self.act_pub]
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if outbox:
            self.outbox = Outbox(outbox, resend_after)
            self.resend_pub = session.declare_publisher(
                keys.teacher_labeled_key(robot), congestion_control=zenoh.CongestionControl.BLOCK)
            self.withdraw_pub = session.declare_publisher(
                keys.teacher_withdraw_key(robot),
                congestion_control=zenoh.CongestionControl.BLOCK)
            self.learners = Learners(session, robot)
            self._decls += [self.resend_pub, self.withdraw_pub, self.learners.sub,
                            session.declare_subscriber(keys.learner_ack_key(robot), self._on_ack)]
            self._arrivals = 0
            self._thread = threading.Thread(target=self._resender, daemon=True,
                                            name=f"teacher-resend-{robot}")
            self._thread.start()
            log.info("labels of robot %s carry session %s; kept until a learner acknowledges "
                     "them (at most %d), resent after %g s", robot, self.outbox.origin,
                     outbox, resend_after)

    def label(self, scan: Scan, action: str, executed: str | None, **goal) -> int | None:
        """Publish the label of ``scan`` (kept in the outbox until acknowledged; ``goal``: a
        goal behaviour's ``goal``, ``reached`` and ``seen``); its seq (None without an
        outbox)."""
        self.published += 1
        if self.outbox is None:
            act = TeacherAction(scan_id=scan.id, action=action, source=self.source, ts=scan.ts,
                                executed=executed, **goal)
        else:  # kept before it is published: an acknowledgement cannot come first
            act = self.outbox.label(scan, action, executed, self.source, **goal).action_message()
        self.act_pub.put(act.encode())
        return act.seq

    def withdraw(self, first: int, upto: int, reason: str = "") -> Withdrawal:
        """Take back the labels ``first <= seq < upto`` of this session (an undo, a discarded
        episode): published now, kept and resent until a learner acknowledges it. ValueError
        without an outbox (labels without identity cannot be named) or when none is left."""
        if self.outbox is None:
            raise ValueError("labels without identity (no outbox) cannot be withdrawn")
        w = self.outbox.withdraw(first, upto, reason)
        self.withdraw_pub.put(w.encode())
        log.info("withdrew labels %d..%d of session %s (%s)", w.first, w.upto - 1, w.origin,
                 reason or "no reason given")
        return w

    # -- acknowledgements and resends --
    def _on_ack(self, sample) -> None:
        ack = self.decoder.decode(LearnerAck, sample.payload.to_bytes())
        if ack is not None and ack.origin == self.outbox.origin:
            self.outbox.ack(ack.upto, ack.seqs, ack.withdrawn, ack.refused)

    def _resender(self) -> None:
        said = 0.0
        while not self._stop.wait(0.1):
            try:
                if not self.learners:
                    continue  # nobody to resend to: at once when a learner (re)appears
                arrivals = self.learners.arrivals
                if arrivals != self._arrivals:
                    # a learner appeared (the first, or one that restarted): everything it
                    # has not acknowledged, also what was labelled before any learner was up
                    self._arrivals = arrivals
                    taken = self.outbox.withdrawals()
                    items = self.outbox.everything()
                    if items:
                        log.info("a learner is up: sending the %d labels it has not "
                                 "acknowledged (seq %d..%d) with their scans", len(items),
                                 items[0].seq, items[-1].seq)
                else:
                    taken = self.outbox.due_withdrawals()
                    items = self.outbox.due()
                    if items and time.monotonic() - said >= 5.0:
                        said = time.monotonic()
                        log.info("resending %d labels not acknowledged within %g s (%d "
                                 "resends so far)", len(items), self.outbox.resend_after,
                                 self.outbox.stats["resent"])
                for w in taken:  # first: the learner then never learns what was taken back
                    self.withdraw_pub.put(w.encode())
                for item in items:
                    self.resend_pub.put(item.encode())
            except Exception as exc:  # noqa: BLE001 - the session is closing
                if not self._stop.is_set():
                    log.warning("resending failed: %s", exc)

    def drain(self, timeout: float) -> bool:
        """Wait (at most ``timeout`` s, while a learner is up) until every label is
        acknowledged; True when none is left. The resend thread keeps working meanwhile."""
        if self.outbox is None:
            return True
        end = time.monotonic() + timeout
        box = self.outbox
        while ((len(box) or box.unacknowledged_withdrawals) and self.learners
               and time.monotonic() < end):
            time.sleep(0.05)
        if box.unacknowledged_withdrawals:
            log.error("%d withdrawals of session %s not acknowledged by a learner: a learner "
                      "that restarts may still hold those labels", box.unacknowledged_withdrawals,
                      box.origin)
        left = len(self.outbox)
        if left:  # the learner may hold them (an acknowledgement it had no time to send, a
            # learner that stopped first): only its journal knows, so they are not called lost
            seqs = self.outbox.seqs()
            log.warning("%d labels of session %s (seq %d..%d) unacknowledged at exit%s: a "
                        "learner that journaled them holds them (its journal says); they are "
                        "not resent after this process exits", left, self.outbox.origin,
                        seqs[0], seqs[-1],
                        "" if self.learners else " (no learner up: it stopped first)")
        elif self.outbox.stats["published"]:
            log.info("all %d labels acknowledged by the learner (%d resends)",
                     self.outbox.stats["published"], self.outbox.stats["resent"])
        return not left

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        for decl in self._decls:
            with contextlib.suppress(Exception):  # the session is closing
                decl.undeclare()


class Hold:
    """While the correcting teacher commands the robot it holds the liveliness token
    ``rhbl/alive/teacher/<robot>-<pid>-hold``; withdrawing it makes the server end the teacher's
    hold at once (docs/protocol.md section 6), so the controller drives on the next tick rather
    than after the watchdog timeout (and a lock-step server does not wait for answers the
    teacher no longer gives)."""

    def __init__(self, session, ident: str):
        self._session = session
        self._key = keys.alive_key("teacher", f"{ident}-hold")
        self._token = None
        self.handbacks = 0

    def acquire(self) -> None:
        if self._token is None:
            self._token = self._session.liveliness().declare_token(self._key)

    def release(self) -> None:
        if self._token is not None:
            token, self._token = self._token, None
            with contextlib.suppress(Exception):  # the session is closing
                token.undeclare()
            self.handbacks += 1


class Learners:
    """The liveliness tokens of the robot's learners now up (``rhbl/alive/learner/<robot>-*``),
    kept current by a liveliness subscriber (a callback of a few microseconds); ``arrivals``
    counts the tokens that appeared (a learner started or restarted)."""

    def __init__(self, session, robot: str):
        import zenoh

        self._delete = zenoh.SampleKind.DELETE
        self._robot = robot
        self._keys: set[str] = set()
        self._lock = threading.Lock()
        self.arrivals = 0
        self.sub = session.liveliness().declare_subscriber(
            keys.alive_key("learner", "*"), self._on_token, history=True)

    def _on_token(self, sample) -> None:
        key = str(sample.key_expr)
        if not keys.parse(key).names_robot(self._robot):
            return
        with self._lock:
            if sample.kind == self._delete:
                self._keys.discard(key)
            elif key not in self._keys:
                self._keys.add(key)
                self.arrivals += 1

    def add(self, found) -> None:
        with self._lock:
            new = set(found) - self._keys
            self._keys |= new
            self.arrivals += len(new)

    def __bool__(self) -> bool:
        with self._lock:
            return bool(self._keys)


@dataclass
class AnsweredScan(Scan):
    """A labeled scan with the scans displayed before it (``Pairing(window=...)``): the
    person's learner estimates which of them the label answered."""

    earlier: tuple = ()


def scan_bytes(scan) -> int:
    """The bytes a labeled scan holds: its ranges and those of the scans kept with it."""
    return scan.ranges.nbytes + sum(e.ranges.nbytes for e in getattr(scan, "earlier", ()))


class Pairing:
    """Pairs every label with exactly the scan it answers (by scan id, whichever arrives first),
    at arrival: ``on_scan`` and ``on_label`` are the subscribers' callbacks (any thread); the
    learning loop takes the labeled scans with ``get``.

    Memory is bounded however fast scans arrive and however slowly the loop learns:

    - scans are never queued: a scan is decoded on arrival and either completes a waiting label
      or goes into the pairing buffer (the newest ``scan_buffer`` unlabeled scans, keyed by id).
      Older unlabeled scans are forgotten and counted (``forgotten``): most scans are never
      labeled, so that is not a loss. A label whose scan was already forgotten (it came more
      than ``scan_buffer`` scans late) is counted ``unmatched`` and logged at once.
    - labels whose scan has not arrived wait at most ``match_timeout`` (then dropped, counted
      ``unmatched`` and logged), as before.
    - labeled scans (``ready``) are never dropped while the loop falls behind: their number is
      bounded by the teacher's label rate, and each one is kept (an error is logged when more
      than ``BEHIND`` wait, every few seconds while they do). Only beyond ``max_ready`` (an hour
      of demonstration at 10 Hz, as the journal backlog) the oldest is dropped, counted ``lost``
      and logged as an error (and the learner exits 1). No backpressure: blocking a zenoh
      callback stalls the whole session (scans, queries), and the router would then drop the
      teacher's labels under congestion, silently: keeping them here is the only visible place.

    A person's label answers what they saw ``lag`` scans before the scan the page displayed
    (their reaction time): with ``lag`` > 0 each label is paired with that earlier scan instead
    (``client.behaviour.teaching.answered_scan``: the label's own scan when the earlier one is
    no longer held or the robot was put elsewhere in between, counted ``unshifted``); the
    newest ``scan_buffer`` scans, labeled or not, are kept for it. With ``window`` > 0 instead
    (the lag estimated by the learner), each label keeps its own scan and carries the scans
    displayed 1 .. ``window`` scans before it (``AnsweredScan.earlier``, nearest first; cut
    where ``answered_scan`` would keep the label's own scan). ``lag_of(label)``, when given,
    says each label's ``(lag, window)`` instead (a learner whose rule is not chosen yet,
    ``--teacher auto``, treats a person's labels only so; ``settle`` ends it).
    """

    def __init__(self, scan_buffer: int = 512, match_timeout: float = 2.0,
                 max_ready: int = MAX_BACKLOG, behind: int = BEHIND, on_scan_seen=None,
                 clock=time.monotonic, lag: int = 0, window: int = 0, lag_of=None,
                 laser=None, max_ready_bytes: int = MAX_BACKLOG_BYTES):
        if not (isinstance(lag, int) and lag >= 0):
            raise ValueError(f"lag must be an integer >= 0 scans, got {lag!r}")
        if not (isinstance(window, int) and window >= 0) or (window and lag):
            raise ValueError(f"window must be an integer >= 0 scans (and lag 0 with it), got "
                             f"{window!r}")
        self.lag, self.window = lag, window
        self._lag_of = lag_of
        self.recent: OrderedDict[int, Scan] = OrderedDict()  # every scan (lag > 0 only)
        self.scan_buffer = max(1, int(scan_buffer))
        self.match_timeout = match_timeout
        self.max_ready, self.max_ready_bytes = max_ready, max_ready_bytes
        self.ready_bytes = 0  # the ranges held in ``ready`` (``scan_bytes``)
        self.laser = laser  # a client.laser.Laser: scans and resent labels that do not fit it
        self.behind = behind
        self._seen = on_scan_seen
        self._clock = clock
        self._cond = threading.Condition()
        self.scans: OrderedDict[int, Scan] = OrderedDict()  # unlabeled, newest last
        self.pending: dict[int, tuple[TeacherAction, float]] = {}  # labels awaiting their scan
        self.ready: deque[tuple[Scan, TeacherAction]] = deque()  # labeled, to be learned
        self.last_id = -1
        self.forgot_upto = -1  # the newest scan id forgotten unlabeled
        self.stats = {"scans": 0, "labels": 0, "forgotten": 0, "unmatched": 0,
                      "lost": 0, "max_ready": 0, "resent": 0, "shifted": 0, "unshifted": 0}
        self.decoder = Decoder(log)  # malformed scans and labels: dropped, counted by kind
        self._said_behind = -1e9

    # -- the callbacks (zenoh threads) --
    def on_scan(self, data: bytes) -> None:
        if self._seen is not None:
            self._seen()
        scan = self.decoder.decode(Scan, data)
        if scan is None or (self.laser is not None and not self.laser.fits(scan)):
            return
        with self._cond:
            self.stats["scans"] += 1
            if scan.id <= self.last_id:
                log.info("scan ids restarted (%d after %d): the server restarted; forgetting "
                         "%d unlabeled scans", scan.id, self.last_id, len(self.scans))
                self.scans.clear()
                self.recent.clear()
                self.forgot_upto = -1
            self.last_id = scan.id
            if self.lag or self.window or self._lag_of is not None:
                self.recent[scan.id] = scan
                while len(self.recent) > self.scan_buffer:
                    self.recent.popitem(last=False)
            hit = self.pending.pop(scan.id, None)
            if hit is not None:
                self._ready(scan, hit[0])
                return
            self.scans[scan.id] = scan
            while len(self.scans) > self.scan_buffer:
                old, _ = self.scans.popitem(last=False)
                self.forgot_upto = max(self.forgot_upto, old)
                self.stats["forgotten"] += 1

    def on_label(self, data: bytes) -> None:
        act = self.decoder.decode(TeacherAction, data)
        if act is None:
            return
        with self._cond:
            self.stats["labels"] += 1
            scan = self.scans.pop(act.scan_id, None)
            if scan is not None:
                self._ready(scan, act)
            elif act.scan_id <= self.forgot_upto:
                self.stats["unmatched"] += 1
                n = self.stats["unmatched"]
                if n <= 3 or n % 100 == 0:
                    log.warning("label %r for scan %d came more than %d scans after it: the "
                                "scan was already forgotten; dropped (%d unmatched so far; "
                                "raise --scan-buffer)", act.action, act.scan_id,
                                self.scan_buffer, n)
            else:
                self.pending[act.scan_id] = (act, self._clock())
                if len(self.pending) > 64:
                    self._expire(self._clock())
                if len(self.pending) > MAX_PENDING:  # a flood of labels for scans never sent
                    del self.pending[next(iter(self.pending))]
                    self.stats["unmatched"] += 1

    def on_labeled(self, data: bytes) -> None:
        """A label the teacher resent with its scan (``LabeledScan``: the learner had not
        acknowledged it): ready at once, no pairing."""
        lab = self.decoder.decode(LabeledScan, data)
        if lab is None or (self.laser is not None and not self.laser.fits_ranges(
                lab.ranges, f"label {lab.seq} of teacher session {lab.origin}")):
            return
        act = lab.action_message()
        scan = Scan(ts=lab.ts, id=lab.scan_id, ranges=lab.ranges, pose=(0.0, 0.0, lab.yaw))
        with self._cond:
            self.stats["resent"] += 1
            waiting = self.pending.get(act.scan_id)
            if waiting is not None and (waiting[0].origin, waiting[0].seq) == (act.origin,
                                                                              act.seq):
                del self.pending[act.scan_id]  # the same label, its scan never came
            self._ready(scan, act)

    def settle(self, lag: int, window: int = 0) -> None:
        """Every label from now on is paired with ``lag`` or carries ``window`` earlier scans
        (a learner's rule was chosen: no ``lag_of`` any more); with neither the recent scans
        are no longer kept."""
        with self._cond:
            self.lag, self.window, self._lag_of = int(lag), int(window), None
            if not (self.lag or self.window):
                self.recent.clear()

    def _answered(self, scan: Scan, lag: int) -> Scan:  # under the lock
        """The scan a label given while ``scan`` was displayed answers (``lag``)."""
        from client.behaviour.teaching import answered_scan

        held = self.recent if scan.id in self.recent else {**self.recent, scan.id: scan}
        sid = answered_scan(scan.id, held, lag)
        if sid == scan.id:
            self.stats["unshifted"] += 1
            return scan
        self.stats["shifted"] += 1
        return held[sid]

    def _windowed(self, scan: Scan, window: int) -> AnsweredScan:  # under the lock
        """``scan`` with the scans displayed 1 .. ``window`` before it."""
        from client.behaviour.teaching import answered_scan

        held = self.recent if scan.id in self.recent else {**self.recent, scan.id: scan}
        earlier = []
        for lag in range(1, window + 1):
            sid = answered_scan(scan.id, held, lag)
            if sid == scan.id:
                break
            earlier.append(held[sid])
        self.stats["shifted" if earlier else "unshifted"] += 1
        return AnsweredScan(**{f.name: getattr(scan, f.name) for f in fields(Scan)},
                            earlier=tuple(earlier))

    def _ready(self, scan: Scan, act: TeacherAction) -> None:  # under the lock
        lag, window = (self.lag, self.window) if self._lag_of is None else self._lag_of(act)
        if lag:
            scan = self._answered(scan, lag)
        elif window:
            scan = self._windowed(scan, window)
        self.ready.append((scan, act))
        self.ready_bytes += scan_bytes(scan)
        n = len(self.ready)
        self.stats["max_ready"] = max(self.stats["max_ready"], n)
        if n > self.max_ready or self.ready_bytes > self.max_ready_bytes:
            self.ready_bytes -= scan_bytes(self.ready.popleft()[0])
            self.stats["lost"] += 1
            lost = self.stats["lost"]
            if lost <= 3 or lost % 1000 == 0:
                log.error("the learner is far behind the teacher: dropped the oldest of %d "
                          "labeled scans waiting to be learned (%d lost so far)",
                          self.max_ready, lost)
        elif n > self.behind and self._clock() - self._said_behind >= 5.0:
            self._said_behind = self._clock()
            log.error("the learner falls behind the teacher: %d labeled scans wait to be "
                      "learned (all kept, at most %d; then the oldest are dropped)", n,
                      self.max_ready)
        self._cond.notify()

    # -- the learning loop --
    def get(self, timeout: float) -> tuple[Scan, TeacherAction] | None:
        """The oldest labeled scan, or None after ``timeout`` s without one."""
        with self._cond:
            if not self.ready:
                self._cond.wait(timeout)
            if not self.ready:
                return None
            item = self.ready.popleft()
            self.ready_bytes -= scan_bytes(item[0])
            return item

    def expire(self) -> list[int]:
        """Drop (count, log) the labels that waited longer than ``match_timeout``."""
        with self._cond:
            return self._expire(self._clock())

    def _expire(self, now: float) -> list[int]:  # under the lock
        old = [k for k, (_, t) in self.pending.items() if now - t > self.match_timeout]
        for k in old:
            del self.pending[k]
        if old:
            self.stats["unmatched"] += len(old)
            log.warning("%d labels matched no scan within %.1f s (scan ids %s...): dropped; "
                        "%d so far", len(old), self.match_timeout, old[:3],
                        self.stats["unmatched"])
        return old

    def close(self) -> int:
        """Count the labels still waiting for their scan as unmatched; how many waited."""
        with self._cond:
            n = len(self.pending)
            self.stats["unmatched"] += n
            self.pending.clear()
            return n

    def waiting(self) -> int:
        """Labeled scans waiting to be learned."""
        with self._cond:
            return len(self.ready)

    def discard(self) -> int:
        """Forget the labeled scans waiting to be learned (the caller counts and logs them as
        lost); how many there were."""
        with self._cond:
            n = len(self.ready)
            self.ready.clear()
            self.ready_bytes = 0
            return n


class Acknowledgements:
    """The learner's end of acknowledgements: a label journaled (or refused for good as bad
    input) is acknowledged in the next batch, a ``LearnerAck`` per teacher session (``origin``)
    holding the whole state of that session in ``labels`` (the learner's ``LabelSet``), so a
    later ack makes up for a lost one. A batch is due ``every`` s after the last one or after
    ``batch`` labels (``due``); ``publish`` sends it (or the state of ``origins``: everything a
    restarted learner holds, before its liveliness token). ``put`` publishes the encoded ack.
    With ``withdrawals`` (the learner's ``Withdrawals``) each ack also says which withdrawals
    of the session are held (``withdrawn``)."""

    def __init__(self, put, labels: LabelSet, every: float = ACK_EVERY, batch: int = ACK_BATCH,
                 clock=time.monotonic, withdrawals: Withdrawals | None = None):
        self._put, self.labels, self.withdrawals = put, labels, withdrawals
        self.every, self.batch, self._clock = float(every), int(batch), clock
        self.pending: set[str] = set()  # origins with labels handled since the last ack
        self.count, self.last = 0, 0.0

    def handled(self, act: TeacherAction, journaled: bool) -> None:
        """A label journaled (or refused for good: then recorded as held, so it is not resent
        forever): acknowledged in the next batch."""
        if act.origin is None:
            return
        if not journaled:
            self.labels.add(act.origin, act.seq, kept=False)
        self.pending.add(act.origin)
        self.count += 1

    def withdrawn(self, origin: str) -> None:
        """A withdrawal of ``origin`` journaled (or held already): acknowledged next batch."""
        self.pending.add(origin)
        self.count += 1

    def due(self, now: float | None = None) -> bool:
        now = self._clock() if now is None else now
        return bool(self.pending) and (self.count >= self.batch or now - self.last >= self.every)

    def publish(self, origins=None) -> None:
        """Acknowledge the labels held of each origin handled since the last ack (or of
        ``origins``)."""
        todo = self.pending if origins is None else set(origins)
        for origin in todo:
            upto, seqs = self.labels.ack(origin)
            wd = None if self.withdrawals is None else self.withdrawals.acked(origin)
            try:
                self._put(LearnerAck(origin=origin, upto=upto, seqs=seqs[:LearnerAck.MAX_SEQS],
                                     ts=time.time(), withdrawn=wd,
                                     refused=self.labels.refused.get(origin)).encode())
            except Exception as exc:  # noqa: BLE001 - the session is closing; resent anyway
                log.debug("ack not published: %s", exc)
        self.pending = set()
        self.count, self.last = 0, self._clock()
