"""Contention probes: a learner's lineage (see campaigns/contention/__init__.py).

Each probe starts a real ``rhbl server`` (world ``room``) and real ``rhbl learner`` processes on
127.0.0.1 (a free port, multicast scouting off), talks to them over a zenoh session of its own,
stops them by PID and reads what they wrote (the journal, ``--stats``, /proc/PID/status):

- ``second-learner``: a second learner on the lineage of a running one, and a restart that
  overlaps the first one's drain; the first keeps learning, the lineage opens afterwards.
- ``oversized-labels``: a flood of labels carrying 100,000 beams, some ranges negative (the
  laser has 360): the journal's growth and the learner's memory.
- ``far-withdrawal``: a withdrawal of labels far beyond what the session gave; the session's
  later labels must still be journaled.
- ``many-sessions``: 1,000 teacher sessions, each label resent after the others: each label
  journaled once.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np

from campaigns.contention import Outcome, Probe, ProbeFunction
from lab.children import Child, free_port, rhbl_argv, rss_kib

__all__ = ["PROBES"]

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "r0"


# ---- the parts ------------------------------------------------------------------------------
class _Bus:
    """A server, a zenoh session on it and the learners started: everything stopped by PID on
    exit."""

    def __init__(self, probe: Probe):
        self.probe = probe
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.children: list[Child] = []
        self.session = None

    def __enter__(self) -> _Bus:
        import zenoh

        from process.session import make_config

        srv = self.start("server", rhbl_argv("server", "--world", "room", "--listen",
                                            self.endpoint))
        if not srv.wait_for_line("listening on", 60.0):
            raise RuntimeError(f"rhbl server did not start:\n{srv.tail()}")
        self.session = zenoh.open(make_config(mode="client", connect=[self.endpoint]))
        return self

    def __exit__(self, *exc) -> None:
        for child in reversed(self.children):
            child.stop()
        if self.session is not None:
            self.session.close()

    def start(self, name: str, argv: list[str], **kw) -> Child:
        child = Child(name, argv, self.probe.workdir, cwd=ROOT, **kw).start()
        self.children.append(child)
        return child

    def publisher(self, key: str):
        """A publisher that blocks rather than drops when the link is congested (a teacher's)."""
        import zenoh

        return self.session.declare_publisher(key,
                                              congestion_control=zenoh.CongestionControl.BLOCK)

    def learner(self, name: str, out: Path, *extra: str) -> Child:
        """A learner of ``out`` (its counters in ``<workdir>/<name>.json``, ``stats_file``)."""
        stats = self.probe.workdir / f"{name}.json"
        child = self.start(name, rhbl_argv(
            "learner", "--features", "wall", "--out", str(out), "--snapshot-every", "1",
            "--connect", self.endpoint, "--stats", str(stats), *extra),
            stop_signal=signal.SIGINT, stop_timeout=60.0)
        child.stats_file = stats
        return child

    def up(self, child: Child, timeout: float = 60.0) -> bool:
        """Until ``child`` (a learner) holds its liveliness token; False when it ended first or
        the time ran out."""
        from client.roles.common import learners_alive

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if child.poll() is not None:
                return False
            if any(k.endswith(f"-{child.pid}") for k in learners_alive(self.session, ROBOT)):
                return True
            time.sleep(0.1)
        return False

    def scan(self, timeout: float = 30.0):
        """One scan of the robot from the server (a real laser's geometry and ranges)."""
        from protocol import keys
        from protocol.messages import Scan

        got: list = []
        ev = threading.Event()

        def on(sample) -> None:
            if not got:
                got.append(Scan.decode(sample.payload.to_bytes()))
                ev.set()

        sub = self.session.declare_subscriber(keys.scan_key(ROBOT), on)
        try:
            if not ev.wait(timeout):
                raise RuntimeError(f"no scan from the server within {timeout:g} s")
        finally:
            sub.undeclare()
        return got[0]


class _Acks:
    """The learner's acknowledgements as they come: origin -> the last ``LearnerAck``."""

    def __init__(self, session):
        from protocol import keys

        self.last: dict = {}
        self.cond = threading.Condition()
        self.sub = session.declare_subscriber(keys.learner_ack_key(ROBOT), self._on)

    def _on(self, sample) -> None:
        from protocol.messages import LearnerAck

        try:
            ack = LearnerAck.decode(sample.payload.to_bytes())
        except Exception:  # noqa: BLE001 - not ours to judge here
            return
        with self.cond:
            self.last[ack.origin] = ack
            self.cond.notify_all()

    def wait(self, pred, timeout: float) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: pred(self.last), timeout)


def _labeled(scan, origin: str, seq: int, ranges=None, action: str = "fwd") -> bytes:
    from protocol.messages import LabeledScan

    return LabeledScan(scan_id=scan.id, action=action, origin=origin, seq=seq,
                       ranges=scan.ranges if ranges is None else ranges,
                       yaw=float(scan.pose[2]), ts=time.time()).encode()


def _journaled(out: Path) -> tuple[Counter, int, str]:
    """(origin, seq) -> how many label records of the journal of ``out`` hold it; withdrawals
    journaled; "" or why the journal cannot be opened."""
    from client.journal import Journal, JournalWithdrawal, journal_path

    labels: Counter = Counter()
    withdrawals = 0
    try:
        journal = Journal.open(journal_path(out), readonly=True)
    except Exception as exc:  # noqa: BLE001 - what the probe reports
        return labels, 0, f"{type(exc).__name__}: {exc}"
    try:
        for rec in journal.records(journal.base):
            if isinstance(rec, JournalWithdrawal):
                withdrawals += 1
            elif rec.origin is not None:
                labels[(rec.origin, rec.seq)] += 1
    finally:
        journal.close()
    return labels, withdrawals, ""


def _stats(child: Child) -> dict:
    try:
        return json.loads(Path(child.stats_file).read_text())
    except (OSError, ValueError):
        return {}


def _opens(bus: _Bus, out: Path, name: str) -> tuple[bool, int | None]:
    """Start a learner on ``out`` again: (it came up, its exit status once stopped)."""
    again = bus.learner(name, out)
    up = bus.up(again)
    return up, again.stop()


class _Sampler(threading.Thread):
    """The peak resident memory of a process (/proc/PID/status VmRSS), sampled every 50 ms."""

    def __init__(self, pid: int):
        super().__init__(daemon=True)
        self.pid, self.peak = pid, 0
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.is_set():
            self.peak = max(self.peak, rss_kib(self.pid))
            self.halt.wait(0.05)

    def stop(self) -> int:
        self.halt.set()
        self.join()
        return self.peak


# ---- the probes -----------------------------------------------------------------------------
def second_learner(probe: Probe) -> Outcome:
    """A second learner on a running one's lineage (issue 36.1), then a restart started while
    the first drains: the second must be refused (one line), the first keep learning, each
    label journaled once and the lineage open afterwards."""
    from client.labels import LabelPublisher

    n = 300 if probe.full else 60
    out = probe.workdir / "tree.rhbl"
    with _Bus(probe) as bus:
        first = bus.learner("first", out)
        if not bus.up(first):
            return Outcome(False, f"the first learner did not come up:\n{first.tail()}")
        scan = bus.scan()
        pubs = LabelPublisher(bus.session, ROBOT, resend_after=0.5)
        held = _Acks(bus.session)  # before the labels: an ack may come before the last is sent
        try:
            for _ in range(n // 2):
                pubs.label(scan, "fwd", "fwd")
                scan = bus.scan()
            second = bus.learner("second", out)
            refused_at = time.monotonic()
            second.wait(20.0)
            second_rc = second.poll()
            refused_s = round(time.monotonic() - refused_at, 1)
            for _ in range(n // 2, n):
                pubs.label(scan, "fwd", "fwd")
                scan = bus.scan()
            acked = held.wait(lambda last: any(a.upto >= n for a in last.values()), 30.0)
            # a restart that overlaps the first one's drain
            first.send_signal(signal.SIGINT)
            restart = bus.learner("restart", out)
            restart_up = bus.up(restart)  # False: it ended (refused, saying so)
            first_rc = first.stop()
            restart_rc = restart.stop()
        finally:
            pubs.close()
        second_rc = second_rc if second_rc is not None else second.stop()
        opens, reopened_rc = _opens(bus, out, "afterwards")
    labels, _w, broken = _journaled(out)
    twice = sum(c - 1 for c in labels.values() if c > 1)
    refused_line = [ln for ln in second.lines if "learner" in ln and "lock" in ln.lower()]
    figures = {"labels": n, "second_exit": second_rc, "refused_after_s": refused_s,
               "restart": "up" if restart_up else f"exit {restart_rc}", "first_exit": first_rc,
               "first_learned": _stats(first).get("learned"), "journaled": len(labels),
               "twice": twice, "lineage_opens": opens and not broken, "all_acked": acked,
               "second_said_lock": bool(refused_line)}
    ok = (second_rc not in (None, 0) and bool(refused_line) and acked and first_rc == 0
          and len(labels) == n and twice == 0 and opens and not broken)
    said = (f"second learner exit {second_rc}, {len(labels)}/{n} labels journaled, {twice} twice;"
            f" lineage {'opens' if opens and not broken else 'cannot be opened: ' + broken}")
    return Outcome(ok, said, figures)


def oversized_labels(probe: Probe) -> Outcome:
    """A flood of labels carrying 100,000 beams, a tenth of them negative (issue 36.2), for
    10 s (ci: 2 s): the journal must grow by under 2 MB, the learner by under 100 MB."""
    from client.journal import journal_path
    from protocol import keys

    seconds = 10.0 if probe.full else 2.0
    out = probe.workdir / "tree.rhbl"
    with _Bus(probe) as bus:
        learner = bus.learner("learner", out)
        if not bus.up(learner):
            return Outcome(False, f"the learner did not come up:\n{learner.tail()}")
        scan = bus.scan()
        jpath = journal_path(out)
        size0 = jpath.stat().st_size if jpath.exists() else 0
        rss0 = rss_kib(learner.pid)
        sampler = _Sampler(learner.pid)
        sampler.start()
        pub = bus.publisher(keys.teacher_labeled_key(ROBOT))
        big = probe.rng.random() * 8.0 * np.ones(100_000, np.float32)
        big[::10] = -1.0
        sent, seq, end = 0, 0, time.monotonic() + seconds
        while time.monotonic() < end:
            pub.put(_labeled(scan, f"flood-{seq % 1000}", seq // 1000, ranges=big))
            seq += 1
            sent += 1
        pub.undeclare()
        settled = time.monotonic() + 3.0  # what arrived is handled; the memory it kept stays
        while time.monotonic() < settled and learner.poll() is None:
            time.sleep(0.1)
        rss_after = rss_kib(learner.pid)
        peak = sampler.stop()
        size1 = jpath.stat().st_size if jpath.exists() else 0
        alive = learner.poll() is None
        t0 = time.monotonic()
        rc = learner.stop()
        stop_s = round(time.monotonic() - t0, 1)
        t0 = time.monotonic()
        opens, _ = _opens(bus, out, "restart")
        restart_s = round(time.monotonic() - t0, 1)
    stats = _stats(learner)
    grew_mb = (size1 - size0) / 1e6
    rss_mb = (max(peak, rss_after) - rss0) / 1024
    figures = {"sent": sent, "journal_grew_mb": round(grew_mb, 2),
               "rss_before_mb": round(rss0 / 1024), "rss_peak_mb": round(peak / 1024),
               "rss_after_mb": round(rss_after / 1024), "learned": stats.get("learned"),
               "refused": stats.get("refused"), "stop_s": stop_s, "restart_s": restart_s}
    ok = alive and grew_mb < 2.0 and rss_mb < 100 and opens and rc == 0
    said = (f"{sent} labels of 100,000 beams in {seconds:g} s: journal +{grew_mb:.2f} MB, "
            f"learner +{rss_mb:.0f} MB (peak {peak / 1024:.0f} MB), exit {rc}")
    return Outcome(ok, said, figures)


def far_withdrawal(probe: Probe) -> Outcome:
    """A withdrawal with ``first`` = 10^9 from a session that gave labels 0-9 (issue 36.4):
    it must be refused, and the session's later labels 10-19 journaled."""
    from protocol import keys
    from protocol.messages import Withdrawal

    out = probe.workdir / "tree.rhbl"
    origin = "far-session"
    far = 10**9 if probe.full else 10**6
    with _Bus(probe) as bus:
        learner = bus.learner("learner", out)
        if not bus.up(learner):
            return Outcome(False, f"the learner did not come up:\n{learner.tail()}")
        acks = _Acks(bus.session)
        scan = bus.scan()
        labeled = bus.publisher(keys.teacher_labeled_key(ROBOT))
        withdraw = bus.publisher(keys.teacher_withdraw_key(ROBOT))
        for seq in range(10):
            labeled.put(_labeled(scan, origin, seq))
        first_acked = acks.wait(lambda a: origin in a and a[origin].upto >= 10, 20.0)
        for _ in range(3):  # resent, as a teacher resends what is not acknowledged
            withdraw.put(Withdrawal(origin=origin, id=0, first=far, upto=far + 5000,
                                    ts=time.time(), reason="probe").encode())
            time.sleep(0.2)
        for seq in range(10, 20):
            labeled.put(_labeled(scan, origin, seq))
        acks.wait(lambda a: origin in a and a[origin].upto >= 20, 10.0)
        upto = acks.last[origin].upto if origin in acks.last else None
        rc = learner.stop()
    labels, withdrawals, broken = _journaled(out)
    mine = sorted(s for o, s in labels if o == origin)
    lost = sorted(set(range(20)) - set(mine))
    stats = _stats(learner)
    figures = {"first": far, "journaled": len(mine), "lost": len(lost), "acked_upto": upto,
               "withdrawals_journaled": withdrawals, "refused": stats.get("refused"),
               "exit": rc}
    ok = first_acked and not lost and withdrawals == 0 and upto == 20 and not broken
    said = (f"withdrawal of {far}..{far + 4999}: {len(mine)}/20 labels journaled, "
            f"acknowledged up to {upto}, {withdrawals} withdrawals journaled")
    return Outcome(ok, said, figures)


def many_sessions(probe: Probe) -> Outcome:
    """1,000 teacher sessions (ci: 300), each label resent once every session gave its own
    (issue 36.5): each label journaled once."""
    from protocol import keys

    sessions = 1000 if probe.full else 300
    per = 5 if probe.full else 2
    out = probe.workdir / "tree.rhbl"
    with _Bus(probe) as bus:
        learner = bus.learner("learner", out)
        if not bus.up(learner):
            return Outcome(False, f"the learner did not come up:\n{learner.tail()}")
        acks = _Acks(bus.session)
        scan = bus.scan()
        pub = bus.publisher(keys.teacher_labeled_key(ROBOT))
        names = [f"s{i:04d}-{probe.rng.randrange(1 << 30):08x}" for i in range(sessions)]
        for name in names:
            for seq in range(per):
                pub.put(_labeled(scan, name, seq))
        acked = acks.wait(lambda a: sum(1 for x in a.values() if x.upto >= per) >= sessions,
                          120.0)
        with acks.cond:
            acks.last.clear()
        for name in names:  # resent (their acknowledgements were lost, say)
            for seq in range(per):
                pub.put(_labeled(scan, name, seq))
        # the resends are handled: every session acknowledged again after them
        reacked = acks.wait(lambda a: len(a) >= sessions, 60.0)
        rc = learner.stop()
    labels, _w, broken = _journaled(out)
    want = sessions * per
    twice = sum(c - 1 for c in labels.values() if c > 1)
    missing = want - len(labels)
    stats = _stats(learner)
    figures = {"sessions": sessions, "labels": want, "journaled": sum(labels.values()),
               "twice": twice, "missing": missing, "duplicates": stats.get("duplicates"),
               "reacknowledged": reacked,
               "exit": rc}
    ok = acked and twice == 0 and missing == 0 and not broken and rc == 0
    said = (f"{sessions} sessions x {per} labels, each resent: {twice} journaled twice, "
            f"{missing} missing")
    return Outcome(ok, said, figures)


PROBES: dict[str, ProbeFunction] = {
    "second-learner": second_learner,
    "oversized-labels": oversized_labels,
    "far-withdrawal": far_withdrawal,
    "many-sessions": many_sessions,
}
