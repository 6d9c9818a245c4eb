"""The learner process under a full disk and hostile input: it keeps running, keeps every
labeled vector it could not journal yet in memory (in order) and writes it once space is back;
a scan its features cannot use is dropped with a log line, not a crash. The test is the server
and the teacher (it publishes scans and labels itself)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh")

from client.journal import Journal, journal_path  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Scan, TeacherAction  # noqa: E402
from protocol.session import make_config  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]
ROOT = Path(__file__).resolve().parents[2]

# runs the learner with journal writes failing (ENOSPC) while the file FULL_FLAG exists
_WRAPPER = """
import errno, os, sys
import client.journal as j
flag = os.environ["FULL_FLAG"]
class _Os:
    def __getattr__(self, name):
        return getattr(os, name)
    def write(self, fd, data):
        if os.path.exists(flag):
            raise OSError(errno.ENOSPC, "No space left on device")
        return os.write(fd, data)
j.os = _Os()
from lab.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _wait(cond, timeout: float, what: str, proc=None, log=None) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return
        if proc is not None and proc.poll() is not None:
            break
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}:\n{log.read_text() if log else ''}")


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
    log = tmp_path / "learner.log"
    rng = np.random.default_rng(0)
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        scan_pub = session.declare_publisher(keys.scan_key("r0"))
        act_pub = session.declare_publisher(keys.teacher_action_key("r0"))
        with open(log, "wb") as f:
            proc = subprocess.Popen(
                [sys.executable, "-c", _WRAPPER, "learner", "--features", "wall", "--out",
                 str(out), "--connect", endpoint, "--snapshot-every", "0.2"],
                cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, start_new_session=True,
                env={**os.environ, "PYTHONUNBUFFERED": "1", "FULL_FLAG": str(flag)})
        try:
            token = keys.alive_key("learner", f"r0-{proc.pid}")
            _wait(lambda: any(r.ok is not None
                              for r in session.liveliness().get(token, timeout=0.5)),
                  30, "the learner's token", proc, log)
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
            _wait(lambda: _records(out) == first, 20, "the first records", proc, log)
            flag.write_text("")  # the disk is full
            bad = teach(1, beams=1)  # a scan the features cannot use: dropped, no crash
            held = teach(20)
            _wait(lambda: "cannot write the journal" in log.read_text(), 20,
                  "the journal error", proc, log)
            time.sleep(0.5)
            assert proc.poll() is None, log.read_text()
            assert _records(out) == first
            flag.unlink()  # space is back
            later = teach(5)
            _wait(lambda: _records(out) == first + held + later, 20, "all the records",
                  proc, log)
            os.kill(proc.pid, signal.SIGINT)
            assert proc.wait(30) == 0, log.read_text()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
    text = log.read_text()
    assert f"scan {bad[0]} dropped" in text, text
    assert "the journal is writable again" in text, text
    assert "Traceback" not in text, text
