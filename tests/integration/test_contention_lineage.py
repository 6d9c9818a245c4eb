"""The learner's promises under contention (docs/reliability.md, "Contention and floods"): each
probe of ``campaigns/contention/lineage.py`` at its small size, on real processes (a server,
learners, a zenoh session of the test's), each failing on the code before its fix."""

from __future__ import annotations

import random

import pytest

pytest.importorskip("zenoh")

from campaigns.contention import Probe  # noqa: E402
from campaigns.contention.lineage import PROBES  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]


@pytest.mark.parametrize("name", sorted(PROBES))
def test_lineage_promise_holds(name, tmp_path):
    outcome = PROBES[name](Probe(name, random.Random(0), tmp_path, "ci"))
    assert outcome.ok, f"{name}: {outcome.said} ({outcome.figures})"
