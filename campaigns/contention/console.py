"""Contention probes: console (see campaigns/contention/__init__.py)."""

from __future__ import annotations

from campaigns.contention import ProbeFunction

__all__ = ["PROBES"]

PROBES: dict[str, ProbeFunction] = {}
