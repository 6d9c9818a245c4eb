"""The fault campaign (``python -m lab.faults``) at CI size: learner SIGKILLs during a
demonstration lose no label, and a restarted server is driven again by the teacher."""

from __future__ import annotations

import random

import pytest

from lab import faults

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


def test_learner_kills_lose_no_label(tmp_path):
    r = faults.learner_kill(tmp_path, random.Random(1), kills=2, speedup=2.0)
    assert r["ok"] and r["labels published"] > 50
    assert r["lost"] == 0 and r["duplicates in journal"] == 0, r


def test_a_restarted_server_is_driven_again(tmp_path):
    r = faults.server_restart(tmp_path, random.Random(2), restarts=1)
    assert r["ok"], r
    assert r["max s"] < 30
