"""The contention campaign as a command (``python -m campaigns.contention``): its probes listed,
an unknown one refused, a broken promise is exit 1; and the snapshot probes at their small size
(the lineage's and the console's run in test_contention_lineage.py and
test_console_contention.py)."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("zenoh")

from campaigns.contention import Outcome, Probe  # noqa: E402
from campaigns.contention import __main__ as campaign  # noqa: E402
from campaigns.contention.snapshot import PROBES as SNAPSHOT  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]


def _run(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "campaigns.contention", *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def test_the_campaign_lists_every_probe_and_refuses_an_unknown_one():
    r = _run("--list")
    listed = r.stdout.split()
    assert r.returncode == 0 and listed == list(campaign.probes()), r.stderr
    assert {"second-learner", "oversized-labels", "far-withdrawal", "many-sessions",
            "console-robot-names", "console-pages", "console-tokens", "cli-hostile-snapshot",
            "follow-hostile-snapshot"} <= set(listed)
    r = _run("--only", "second-learner,no-such-probe")
    assert r.returncode == 2 and "no-such-probe" in r.stderr, r.stderr


def test_a_broken_promise_or_a_broken_probe_is_a_failed_run(tmp_path, monkeypatch, capsys):
    table = {"holds": lambda p: Outcome(True, "fine"),
             "breaks": lambda p: Outcome(False, "lost 3 labels", {"lost": 3}),
             "crashes": lambda p: 1 / 0}
    monkeypatch.setattr(campaign, "probes", lambda: table)
    assert campaign.main(["--size", "ci", "--out", str(tmp_path), "--only", "holds"]) == 0
    assert campaign.main(["--size", "ci", "--out", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "| breaks | **no** | lost 3 labels | lost 3" in out
    assert "| crashes | **no** | the probe itself failed: ZeroDivisionError" in out


@pytest.mark.parametrize("name", sorted(SNAPSHOT))
def test_snapshot_promise_holds(name, tmp_path):
    outcome = SNAPSHOT[name](Probe(name, random.Random(0), tmp_path, "ci"))
    assert outcome.ok, f"{name}: {outcome.said} ({outcome.figures})"
