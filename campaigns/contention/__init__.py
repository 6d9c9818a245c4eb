"""The contention campaign: probes an attacker or a careless operator would try, on loopback,
each checking a promise of docs/reliability.md ("Contention and floods").

    python -m campaigns.contention [--seed 0] [--size ci|full] [--only NAME,...] [--out DIR]

Every probe module here (``lineage``, ``console``, ``snapshot``) defines ``PROBES``: a dict of
name -> function ``(Probe) -> Outcome``. A probe starts the real processes it needs (``rhbl
server``, ``rhbl learner``, ``rhbl console`` ... on 127.0.0.1, a free port, multicast scouting
off), drives them, stops them by PID and says what it measured. ``--size ci`` is the small run
the test suite makes; ``full`` the sizes the promises state (a 10 s flood, 20,000 robot names,
1,000 sessions).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["Outcome", "Probe", "ProbeFunction", "SIZES"]

SIZES = ("ci", "full")


@dataclass
class Probe:
    """What a probe is given: its own seeded generator, a folder of its own, and the size."""

    name: str
    rng: random.Random
    workdir: Path
    size: str = "ci"

    @property
    def full(self) -> bool:
        return self.size == "full"


@dataclass
class Outcome:
    """What a probe saw: ``ok`` when the promise held, ``figures`` (name -> value, printed in
    the report's table) and one line ``said`` in words."""

    ok: bool
    said: str
    figures: dict[str, Any] = field(default_factory=dict)


ProbeFunction = Callable[[Probe], Outcome]
