"""``benchmarks/bench_messages.py``: two checkouts' messages timed side by side in one process
(here this checkout against itself), the same bytes from both."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_both_checkouts_are_timed_and_encode_the_same_bytes():
    r = subprocess.run([sys.executable, "benchmarks/bench_messages.py", "--rounds", "1",
                        "--number", "5", "--peer", str(ROOT)], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = [ln for ln in r.stdout.splitlines() if ln.startswith("| ") and "---" not in ln][1:]
    assert [ln.split(" | ")[0][2:] for ln in rows] == [
        "Scan", "State", "TeacherAction", "LabeledScan", "VelCmd", "Decision", "LearnerAck"]
    assert all(ln.endswith("| yes |") for ln in rows), r.stdout


def test_a_peer_that_is_no_checkout_is_refused(tmp_path):
    r = subprocess.run([sys.executable, "benchmarks/bench_messages.py", "--peer", str(tmp_path)],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "not a checkout of rhbl" in r.stderr
