"""Decode or drop: the one way a receiver turns a payload into a message without ever raising.

    decoder = Decoder(log)                        # one per receiving object, any thread
    scan = decoder.decode(Scan, payload)          # the message, or None: counted, logged
    decoder.counts                                # {"scan": 3, ...}: drops by what was dropped
    decoder.drop("cmd_source", "its source does not match its key")   # any other refusal

A malformed message is dropped, counted under what it is (``cls.WHAT``, or ``what``) and logged
at a bounded rate (the first ``first`` of each kind, then every ``every``-th), so hostile
traffic cannot flood the log; the counts are data (a process reports them with ``--stats``).
``counts`` may be a dict the caller owns (a server's counters); ``total`` names a key of it that
counts every drop.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

__all__ = ["Decoder"]


class Decoder:
    def __init__(self, logger: logging.Logger, level: int = logging.WARNING,
                 counts: dict[str, int] | None = None, total: str | None = None,
                 verb: str = "dropped a malformed", first: int = 10, every: int = 100):
        self.log, self.level, self.verb = logger, level, verb
        self.counts: dict[str, int] = {} if counts is None else counts
        self.total_key = total
        self.first, self.every = int(first), int(every)
        self._lock = threading.Lock()

    def decode(self, cls, data: Any, what: str | None = None, where: str = "", **kw):
        """``cls.decode(data, **kw)``, or None when it raises (counted and logged: ``where``,
        a key say, is said before the reason)."""
        try:
            return cls.decode(data, **kw)
        except Exception as exc:  # noqa: BLE001 - DecodeError, and anything a bad payload raises
            self.drop(what or cls.WHAT, f"{where}: {exc}" if where else str(exc))
            return None

    def drop(self, what: str, reason: str) -> int:
        """Count a refused message of kind ``what`` and log it (at a bounded rate); how many of
        that kind so far."""
        with self._lock:
            n = self.counts[what] = self.counts.get(what, 0) + 1
            if self.total_key is not None:
                self.counts[self.total_key] = self.counts.get(self.total_key, 0) + 1
        if n <= self.first or n % self.every == 0:
            self.log.log(self.level, "%s %s (%d so far): %s", self.verb, what, n, reason)
        return n

    @property
    def total(self) -> int:
        """Every drop counted here (all kinds)."""
        with self._lock:
            if self.total_key is not None:
                return self.counts.get(self.total_key, 0)
            return sum(self.counts.values())
