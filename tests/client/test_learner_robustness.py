"""The learner process under a full disk, hostile input and a flood of scans: it keeps running,
keeps every labeled vector it could not journal yet in memory (in order) and writes it once space
is back; a scan its features cannot use is dropped with a log line, not a crash; a learner far
behind a flood of scans stays in bounded memory and still learns every label. The test is the
server and the teacher (it publishes scans and labels itself)."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import eventually, wait_token  # noqa: E402

from campaigns import full_disk  # noqa: E402
from client.journal import Journal, journal_path  # noqa: E402
from lab.children import Child  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import LabeledScan, Scan, TeacherAction  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]
ROOT = Path(__file__).resolve().parents[2]



def _records(out: Path) -> list[int]:
    if not journal_path(out).exists():
        return []
    with Journal.open(journal_path(out), readonly=True) as jr:
        return [r.scan_id for r in jr.records()]


def test_disk_full_keeps_labels_in_memory_and_journals_them_later(free_port, tmp_path):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    out = tmp_path / "t.rhbl"
    flag = tmp_path / "full"
    rng = np.random.default_rng(0)
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        scan_pub = session.declare_publisher(keys.scan_key("r0"))
        act_pub = session.declare_publisher(keys.teacher_action_key("r0"))
        # the learner with journal writes failing (ENOSPC) while the file FULL_FLAG exists
        proc = Child("learner", [*full_disk.ARGV, "learner", "--features", "wall",
                                 "--out", str(out), "--connect", endpoint, "--snapshot-every",
                                 "0.2"], tmp_path, cwd=ROOT,
                     env={**os.environ, "FULL_FLAG": str(flag)}).start()
        try:
            token = keys.alive_key("learner", f"r0-{proc.pid}")
            wait_token(session, token, alive=[proc])
            sid = 0

            def teach(n: int, beams: int = 360) -> list[int]:
                nonlocal sid
                ids = []
                for _ in range(n):
                    sid += 1
                    ranges = rng.uniform(0.3, 3.0, beams).astype(np.float32)
                    scan_pub.put(Scan(ts=0.1 * sid, id=sid, ranges=ranges).encode())
                    act_pub.put(TeacherAction(scan_id=sid, action="fwd").encode())
                    ids.append(sid)
                    time.sleep(0.01)
                return ids

            first = teach(5)
            eventually(lambda: _records(out), 20, "the first records", alive=[proc],
                       until=lambda got: got == first)
            flag.write_text("")  # the disk is full
            bad = teach(1, beams=1)  # a scan not of this laser: refused, no crash
            held = teach(20)
            assert proc.wait_for_line("cannot write the journal", 20), (
                f"timed out waiting for the journal error:\n{proc.output()}")
            # it keeps trying (every second) and keeps running
            assert proc.wait_for_line("cannot write the journal", 20, since=proc.mark()), (
                f"timed out waiting for the second attempt:\n{proc.output()}")
            assert proc.poll() is None, proc.output()
            assert _records(out) == first
            flag.unlink()  # space is back
            later = teach(5)
            eventually(lambda: _records(out), 20, "all the records", alive=[proc],
                       until=lambda got: got == first + held + later)
            proc.send_signal(signal.SIGINT)
            assert proc.wait(30) == 0, proc.output()
        finally:
            proc.kill()  # nothing if it ended
    text = proc.output()
    assert f"scan {bad[0]} claims 1 beams" in text and "refused" in text, text
    assert "the journal is writable again" in text, text
    assert "Traceback" not in text, text


# runs the learner with every learning step slowed down (a learner that falls behind)
_SLOW = """
import sys, time
import client.lineage as L
_learn = L.Lineage.learn
def slow(self, *args, **kwargs):
    time.sleep(0.02)
    return _learn(self, *args, **kwargs)
L.Lineage.learn = slow
from lab.cli import main
sys.exit(main(sys.argv[1:]))
"""


ORIGIN = "f1" * 8  # the flood's teacher session


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc")
def test_a_flood_of_scans_keeps_a_slow_learner_bounded_and_every_label_learned(free_port,
                                                                               tmp_path):
    """30000 scans as fast as zenoh carries them (blocking congestion control: none is lost on
    the way), one in 100 labeled, into a learner that needs 20 ms per labeled scan. Its memory
    stays flat (the old unbounded event queue grew by ~50 MB here) and every label is learned:
    at ~1000 times a robot's scan rate, a loaded machine can deliver a label after its scan has
    left the pairing buffer (the label's callback once fell ~10,600 scans behind the scans'),
    and then, as a teacher does for every label not acknowledged, the test resends it with its
    scan (``teacher/labeled``)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    out = tmp_path / "t.rhbl"
    rng = np.random.default_rng(0)
    ranges = [rng.uniform(0.3, 3.0, 360).astype(np.float32) for _ in range(8)]
    n, every = 30_000, 100
    block = zenoh.CongestionControl.BLOCK
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        scan_pub = session.declare_publisher(keys.scan_key("r0"), congestion_control=block)
        act_pub = session.declare_publisher(keys.teacher_action_key("r0"),
                                            congestion_control=block)
        resend_pub = session.declare_publisher(keys.teacher_labeled_key("r0"),
                                               congestion_control=block)
        proc = Child(
            "learner",
            # the flood runs ~1000x a server's 10 Hz: the default 512-scan pairing buffer
            # is 50 s of a real robot but only ~50 ms here, less than one scheduling hiccup
            # of a loaded CI machine between a scan's and its label's callbacks; 4096 scans
            # (~6 MB, full before the 5000th scan, where the memory check starts) keeps the
            # same tolerance in time (2048 fell short once on three loaded test workers) and
            # memory still bounded
            [sys.executable, "-c", _SLOW, "learner", "--features", "wall", "--out",
             str(out), "--connect", endpoint, "--scan-buffer", "4096"],
            tmp_path, cwd=ROOT).start()
        try:
            token = keys.alive_key("learner", f"r0-{proc.pid}")
            wait_token(session, token, alive=[proc])
            scan_pub.put(Scan(ts=0.0, id=0, ranges=ranges[0]).encode())  # the server is up
            act_pub.put(TeacherAction(scan_id=0, action="fwd").encode())  # and learning is
            eventually(lambda: _records(out), 30, "the first label learned", alive=[proc],
                       until=lambda got: got == [0])
            before = _rss_mb(proc.pid)
            rss = []  # every 1000 scans
            for sid in range(1, n + 1):
                scan_pub.put(Scan(ts=0.01 * sid, id=sid, ranges=ranges[sid % 8]).encode())
                if sid % every == 0:
                    act_pub.put(TeacherAction(scan_id=sid, action="fwd", origin=ORIGIN,
                                              seq=sid).encode())
                if sid % 1000 == 0:
                    rss.append(_rss_mb(proc.pid))
            labeled = [0, *range(every, n + 1, every)]

            def learned() -> list[int]:  # every label, those the learner missed resent
                got = _records(out)
                for sid in sorted(set(labeled[1:]) - set(got)):
                    resend_pub.put(LabeledScan(scan_id=sid, action="fwd", origin=ORIGIN, seq=sid,
                                               ranges=ranges[sid % 8], yaw=0.0,
                                               ts=0.01 * sid).encode())
                return sorted(got)

            eventually(learned, 60, "every label learned", alive=[proc], every=2.0,
                       until=lambda got: got == labeled)
            after = _rss_mb(proc.pid)
            # flat, not growing with the flood: the buffers fill in the first few thousand
            # scans, then the middle of the flood and its end hold the same (a queue growing
            # with the backlog climbs all along: ~50 MB over this flood). Medians, because
            # zenoh's own receive buffers swell for a moment whenever the learner's callback
            # falls behind (spikes of ~10 MB seen on an idle machine, more under load)
            middle, end = float(np.median(rss[5:15])), float(np.median(rss[-10:]))
            assert end - middle < 8 and after - before < 20, (before, middle, end, after, rss)
            proc.send_signal(signal.SIGINT)
            assert proc.wait(30) == 0, proc.output()
        finally:
            proc.kill()  # nothing if it ended
    text = proc.output()
    assert " 0 lost)" in text, text  # unmatched labels were resent and learned (above)
    assert f"{n + 1} scans received" in text, text
    assert "Traceback" not in text, text
