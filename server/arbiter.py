"""Command arbitration between commanding sources (pure: no zenoh, no clocks).

The rule (docs/protocol.md, "Who drives"): every command names its ``source``. A source's role
is its name up to the first ``-``, ``:`` or ``.`` (``teacher``, ``teacher-2`` -> ``teacher``).
Priorities: ``teacher`` 2 > ``controller`` 1 > anything else 0. A source *holds* the robot while
its commands keep arriving within ``timeout`` sim seconds of each other (the watchdog). The
driving source is the holding source of highest priority (ties: the most recent command). When
no source holds the robot, it stops. When a teacher stops commanding (timeout) or its liveliness
token disappears (:meth:`Arbiter.release_role`), its hold ends at once and the next source that
holds, e.g. the controller, drives again. A command with ``state`` false (motors off) is a
command to stand still.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = ["PRIORITIES", "Arbiter", "Held", "role_of", "priority_of"]

PRIORITIES: dict[str, int] = {"teacher": 2, "controller": 1}
MAX_SOURCES = 64  # sources held at once; a flood of invented names evicts the least important
_ROLE = re.compile(r"[-:.]")


def role_of(source: str) -> str:
    return _ROLE.split(source, maxsplit=1)[0] if source else ""


def priority_of(source: str) -> int:
    return PRIORITIES.get(role_of(source), 0)


@dataclass
class Held:
    source: str
    vx: float
    va: float
    state: bool
    time: float  # sim time of the last command
    priority: int
    seq: int  # arrival order, breaks ties


class Arbiter:
    """Chooses which source's command drives one robot."""

    def __init__(self, timeout: float = 0.5, max_sources: int = MAX_SOURCES) -> None:
        if not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"command timeout must be a finite number > 0 s, got {timeout!r}")
        self.timeout = float(timeout)
        self.max_sources = int(max_sources)
        self._held: dict[str, Held] = {}
        self._seq = 0

    def offer(self, source: str, vx: float, va: float, state: bool, now: float) -> None:
        """A command arrived from ``source`` at sim time ``now``. At most ``max_sources`` are
        held: a new one beyond that evicts the least important (lowest priority, oldest)."""
        self._seq += 1
        if source not in self._held and len(self._held) >= self.max_sources:
            self.expire(now)
            if len(self._held) >= self.max_sources:
                worst = min(self._held.values(), key=lambda h: (h.priority, h.seq))
                del self._held[worst.source]
        self._held[source] = Held(source, vx, va, state, now, priority_of(source), self._seq)

    def holds(self, source: str) -> bool:
        """Whether ``source`` holds the robot (as of the last expiry)."""
        return source in self._held

    def expire(self, now: float) -> None:
        """Drop sources whose last command is older than the timeout."""
        for s in [s for s, h in self._held.items() if now - h.time > self.timeout]:
            del self._held[s]

    def release(self, source: str) -> None:
        self._held.pop(source, None)

    def release_role(self, role: str) -> None:
        """End the hold of every source with this role (its liveliness token disappeared)."""
        for s in [s for s in self._held if role_of(s) == role]:
            del self._held[s]

    def driver(self, now: float | None = None) -> Held | None:
        """The driving source (after expiring stale ones if ``now`` is given), or None."""
        if now is not None:
            self.expire(now)
        if not self._held:
            return None
        return max(self._held.values(), key=lambda h: (h.priority, h.seq))

    def command(self, now: float) -> tuple[float, float, str]:
        """(vx, va, driver source) to apply now; (0, 0, "") when nobody holds the robot."""
        h = self.driver(now)
        if h is None:
            return 0.0, 0.0, ""
        if not h.state:
            return 0.0, 0.0, h.source
        return h.vx, h.va, h.source

    def clear(self) -> None:
        self._held.clear()
