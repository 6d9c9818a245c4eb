"""Label delivery over a real bus, end to end, for what a person at the console does: labels
given before any learner is up are kept and delivered once one is; a withdrawal reaches the
learner, which journals it, rebuilds its tree without those labels and keeps them out after a
SIGKILL and a restart. A real server, a real learner process and a ``LabelPublisher`` (the
console's and the teacher's) on real zenoh sessions; waits on counters and liveliness, never on
fixed sleeps."""

from __future__ import annotations

import json
import signal
import threading
from pathlib import Path

import pytest
from waiting import eventually, patience

zenoh = pytest.importorskip("zenoh")

from client.journal import Journal, JournalWithdrawal, journal_path  # noqa: E402
from client.labels import LabelPublisher  # noqa: E402
from client.player import PlayerClient  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import TreeNotice  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

ROOT = Path(__file__).resolve().parents[2]


def _scan(scans):
    """The next scan of the server (a deadline: a server that stopped publishing fails the
    test instead of hanging it)."""
    return eventually(scans.try_recv, 20, "a scan from the server", every=0.01)


class _Notices:
    def __init__(self, session):
        self.last: TreeNotice | None = None
        self.cond = threading.Condition()
        self.sub = session.declare_subscriber(keys.learner_notice_key("r0"), self._on)

    def _on(self, sample):
        with self.cond:
            self.last = TreeNotice.decode(sample.payload.to_bytes())
            self.cond.notify_all()

    def wait(self, pred, timeout: float, what: str) -> TreeNotice:
        with self.cond:
            assert self.cond.wait_for(lambda: self.last is not None and pred(self.last),
                                      patience(timeout)), f"{what}: last notice {self.last}"
            return self.last


def _learner(srv, out: Path, tmp: Path, n: int, *extra: str) -> Child:
    stats = tmp / f"learner-{n}.json"
    p = Child(f"learner-{n}", rhbl_argv("learner", "--features", "wall", "--out", str(out),
                                        "--snapshot-every", "0.3", "--connect", srv.endpoint,
                                        "--stats", str(stats), *extra), tmp, cwd=ROOT,
              stop_signal=signal.SIGINT, stop_timeout=30.0, escalate=False).start()
    p.stats_file = stats
    return p


def test_labels_before_any_learner_are_kept_and_a_withdrawal_survives_a_restart(
        start_server, tmp_path):
    srv = start_server("room")
    out = tmp_path / "tree.rhbl"
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        notices = _Notices(session)
        client = PlayerClient(session=session, source="teacher")
        scans = client.scans(depth=64)
        pubs = LabelPublisher(session, "r0", resend_after=0.5)
        try:
            # 31 labels while no learner is up (the console's bug: 0 of them arrived)
            for _ in range(31):
                pubs.label(_scan(scans), "fwd", "fwd")
            assert len(pubs.outbox) == 31 and not pubs.learners
            learner = _learner(srv, out, tmp_path, 1)
            eventually(lambda: len(pubs.outbox), 30, "the learner acknowledges all 31 (unacknowledged)",
                       until=lambda n: n == 0, alive=[learner])
            for k in range(29):  # then 29 more with it up: seqs 31..59
                pubs.label(_scan(scans), "rot-left" if k % 2 else "fwd-left", None)
            eventually(lambda: len(pubs.outbox), 30, "all 60 acknowledged (unacknowledged)",
                       until=lambda n: n == 0, alive=[learner])
            notices.wait(lambda n: n.vectors == 60, 20, "a notice of 60 vectors")
            pubs.withdraw(40, 55, "undo 1.5 s")
            eventually(lambda: pubs.outbox.unacknowledged_withdrawals == 0, 20,
                   "the withdrawal acknowledged")
            notices.wait(lambda n: n.vectors == 45, 20, "the rebuilt tree: 45 vectors")
            learner.send_signal(signal.SIGKILL)
            assert learner.wait(10) is not None
            again = _learner(srv, out, tmp_path, 2)
            notices.last = None
            pubs.label(_scan(scans), "fwd", "fwd")  # seq 60, to a learner that restarted
            eventually(lambda: len(pubs.outbox), 30, "the restarted learner acknowledges",
                       until=lambda n: n == 0, alive=[again])
            notices.wait(lambda n: n.vectors == 46, 20, "45 + 1 vectors after the restart")
            assert again.stop() == 0, again.output()
        finally:
            pubs.close()
            client.close()
            notices.sub.undeclare()
    stats = json.loads(again.stats_file.read_text())
    assert stats["standing"] == 46 and stats["withdrawn_labels"] == 15
    with Journal.open(journal_path(out), readonly=True) as j:
        recs = list(j.records())
        standing = sorted(r.seq for r in j.standing())  # in the order they arrived
    assert [type(r) for r in recs].count(JournalWithdrawal) == 1
    assert standing == [*range(40), *range(55, 61)]
    assert all(r.origin == pubs.outbox.origin for r in recs)


def test_a_persons_learner_keeps_withdrawn_labels_out_after_a_restart(start_server, tmp_path):
    """``--teacher person`` rebuilds its tree from the whole journal: the tombstones in it keep
    the withdrawn labels out, live and after a SIGKILL and a restart."""
    srv = start_server("room")
    out = tmp_path / "tree.rhbl"
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        notices = _Notices(session)
        client = PlayerClient(session=session, source="teacher")
        scans = client.scans(depth=64)
        pubs = LabelPublisher(session, "r0", resend_after=0.5)
        learner = _learner(srv, out, tmp_path, 1, "--teacher", "person")
        try:
            eventually(lambda: bool(pubs.learners), 30, "the learner is up (its token)",
                       alive=[learner])
            for k in range(40):
                pubs.label(_scan(scans), "fwd" if k < 30 else "rot-left", "fwd")
            eventually(lambda: len(pubs.outbox), 30, "all 40 acknowledged (unacknowledged)",
                       until=lambda n: n == 0, alive=[learner])
            notices.wait(lambda n: n.vectors == 40, 20, "a notice of 40 vectors")
            pubs.withdraw(30, 40, "undo 1 s")
            eventually(lambda: pubs.outbox.unacknowledged_withdrawals == 0, 20, "acknowledged")
            notices.wait(lambda n: n.vectors == 30, 20, "the rebuilt tree: 30 vectors")
            learner.send_signal(signal.SIGKILL)
            assert learner.wait(10) is not None
            notices.last = None
            again = _learner(srv, out, tmp_path, 2, "--teacher", "person")
            pubs.label(_scan(scans), "fwd", "fwd")
            eventually(lambda: len(pubs.outbox), 30, "the restarted learner acknowledges",
                       until=lambda n: n == 0, alive=[again])
            notices.wait(lambda n: n.vectors == 31, 20, "30 + 1 vectors after the restart")
            assert again.stop() == 0, again.output()
        finally:
            learner.kill()
            pubs.close()
            client.close()
            notices.sub.undeclare()
    with Journal.open(journal_path(out), readonly=True) as j:
        standing = [r.label for r in j.standing()]
    assert standing == ["fwd"] * 31
