"""The laser a robot's labels must come from: a label whose scan does not fit it is refused.

A label is learned from the scan it answers: paired by id with a scan the server published
(``TeacherAction``), or resent by its teacher with the scan's ranges (``LabeledScan``, which
carries no geometry of its own). Anyone on the bus can publish either, so the learner checks
each scan against the laser of the robot before it keeps it (a label carrying 100,000 beams
once grew a learner's journal by 1.35 GB in 8 s).

Which laser: the geometry of the lineage, the beam count of its journal's labels (what every
label the tree holds was learned from: a lineage cannot change lasers under its tree), and,
until the lineage has a label, the first scan seen from the server whose geometry is consistent
(``count == (max_angle - min_angle) / resolution + 1``); the range bound ``max_range`` from the
server's scans. A scan claiming another beam count than that is refused ("beams"); ranges that
are negative or beyond ``max_range`` are refused ("ranges"; the decoder already refuses
non-finite ones); a resent label before any geometry is known is refused ("no_laser": not
acknowledged, its teacher resends it a moment later, when the server's first scan has come).
"""

from __future__ import annotations

import logging
import math

import numpy as np

__all__ = ["Laser", "LaserMismatch"]

log = logging.getLogger(__name__)

_SLACK = 1e-3  # m: ranges this far past max_range still fit (float32 rounding)
_FIELDS = 2048  # bytes a scan or label message holds beside its ranges, at most


class LaserMismatch(ValueError):
    """A scan that does not fit the robot's laser; ``kind`` names what was wrong ("beams",
    "ranges", "geometry", "no_laser")."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


class Laser:
    """A robot's laser as far as it is known: ``beams`` (None: not yet) and ``max_range``
    (None: not yet; then only negative ranges are refused). ``check_scan`` checks a scan the
    server published (and learns the geometry from the first consistent one), ``check_ranges``
    the ranges of a resent label; both raise ``LaserMismatch``; ``fits`` and ``fits_ranges``
    say it instead, counting what they refuse by kind (``refused``, the learner's ``--stats``)
    and logging the first of each kind, then every 1000th. Thread-safe enough for zenoh's
    callbacks: ``beams`` and ``max_range`` are only ever set from None to a value."""

    def __init__(self, beams: int | None = None, max_range: float | None = None):
        if beams is not None and not (isinstance(beams, int) and beams > 0):
            raise ValueError(f"beams must be a positive integer or None, got {beams!r}")
        self.beams = beams
        self.max_range = max_range
        self.refused: dict[str, int] = {}  # by kind of misfit ("beams", "ranges", ...)
        self.by_key: dict[str, int] = {}  # by the message's kind ("scan", "teacher/labeled")

    def too_big(self, size: int, what: str, key: str = "scan", extra: int = 0) -> bool:
        """True (counted "beams", logged) when a message of ``size`` bytes is larger than one
        carrying a scan of this laser (and ``extra`` bytes of other fields: a resent label's
        fiducial items) can be: refused before it is even copied or decoded (a flood of 400 KB
        labels otherwise grows the learner's heap for good)."""
        if self.beams is None or size <= 4 * self.beams + _FIELDS + extra:
            return False
        self.refuse(LaserMismatch("beams", f"{what} of {size} bytes, more than a scan of the "
                                           f"laser's {self.beams} beams holds"), key)
        return True

    def fits(self, scan, key: str = "scan") -> bool:
        """``check_scan``, True or False (counted, logged)."""
        try:
            self.check_scan(scan)
        except LaserMismatch as exc:
            self.refuse(exc, key)
            return False
        return True

    def fits_ranges(self, ranges, what: str, key: str = "teacher/labeled") -> bool:
        """``check_ranges``, True or False (counted, logged)."""
        try:
            self.check_ranges(ranges, what)
        except LaserMismatch as exc:
            self.refuse(exc, key)
            return False
        return True

    def refuse(self, exc: LaserMismatch, key: str = "scan") -> None:
        """Count a refusal of a message of kind ``key`` (as ``protocol.decoding`` names
        kinds); log the first of its kind of misfit, then every 1000th."""
        self.by_key[key] = self.by_key.get(key, 0) + 1
        n = self.refused[exc.kind] = self.refused.get(exc.kind, 0) + 1
        if n == 1 or n % 1000 == 0:
            log.warning("%s: refused (%d %s so far%s)", exc, n, exc.kind,
                        "; the next ones of this kind are counted, logged every 1000th"
                        if n == 1 else "")

    def check_scan(self, scan) -> None:
        """A ``protocol.messages.Scan``: its geometry consistent, its beam count this laser's,
        its ranges within ``[0, max_range]``; the first good one sets what is not known yet."""
        count = len(scan.ranges)
        span = (scan.max_angle - scan.min_angle) / scan.resolution if scan.resolution > 0 else -1
        if not (math.isfinite(span) and span >= 0 and abs(span + 1 - count) < 0.5
                and math.isfinite(scan.max_range) and scan.max_range > 0):
            raise LaserMismatch("geometry", (
                f"scan {scan.id} claims {count} beams from {scan.min_angle:.4f} to "
                f"{scan.max_angle:.4f} rad every {scan.resolution:.6f} rad, max range "
                f"{scan.max_range:g} m: not one laser's geometry"))
        if self.beams is not None and count != self.beams:
            raise LaserMismatch("beams", f"scan {scan.id} has {count} beams, the laser "
                                         f"{self.beams}")
        self._check_values(scan.ranges, scan.max_range, f"scan {scan.id}")
        if self.beams is None:
            self.beams = count
        if self.max_range is None:
            self.max_range = float(scan.max_range)

    def check_ranges(self, ranges, what: str) -> None:
        """The ranges of a label resent with its scan (``what`` names it in the message)."""
        if self.beams is None:
            raise LaserMismatch("no_laser", f"{what}: no scan of the robot seen yet, so its "
                                            "laser is not known")
        if len(ranges) != self.beams:
            raise LaserMismatch("beams", f"{what} has {len(ranges)} beams, the laser "
                                         f"{self.beams}")
        self._check_values(ranges, self.max_range, what)

    @staticmethod
    def _check_values(ranges, max_range: float | None, what: str) -> None:
        r = np.asarray(ranges)
        low, high = (float(r.min()), float(r.max())) if r.size else (0.0, 0.0)
        if not (math.isfinite(low) and math.isfinite(high)) or low < 0 or (
                max_range is not None and high > max_range + _SLACK):
            bound = f"0..{max_range:g} m" if max_range is not None else ">= 0 m"
            raise LaserMismatch("ranges", f"{what} has ranges from {low:g} to {high:g} m, the "
                                          f"laser's are {bound}")
