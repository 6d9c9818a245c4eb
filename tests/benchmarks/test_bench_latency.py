"""``benchmarks/bench_latency.py`` runs end to end: real processes over a loopback router, the
controller's stages timed where its loop really spends them (its hot path read in place)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]
BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_latency.py"


def test_the_round_trips_and_the_controllers_stages_are_measured():
    r = subprocess.run([sys.executable, str(BENCH), "--n", "40", "--breakdown"],
                       capture_output=True, text=True, timeout=280)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert re.search(r"40 round trips each, one in flight; tree \d+ nodes; lost 0", out), out
    assert re.search(r"ratio p50 \d+\.\d\dx \(target <= 1\.3x\)", out), out
    # every stage was timed: the wrappers hold the names the controller's loop calls
    for stage in ("decode", "answer", "command", "in hand -> out", "decision"):
        assert re.search(rf"^  {re.escape(stage)}\s+\d+\.\d ", out, re.M), (stage, out)


def test_a_peer_that_is_not_a_checkout_is_refused(tmp_path):
    r = subprocess.run([sys.executable, str(BENCH), "--peer", str(tmp_path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "not a checkout of rhbl" in r.stderr, r.stderr
