"""Another laser's scan in the beam layout a tree's features were taught on.

A :class:`~client.behaviour.features.FeatureSpec` names beams in degrees from the right edge of
a scan of ``spec.fov`` degrees centred on straight ahead, and the trees taught here read the
simulator's laser: 360 beams over 180 degrees. A real robot's laser has its own beam count,
span and range (a 640-beam, 240-degree laser, say). :class:`LaserResampler` maps its scans onto
the taught layout, so the same spec and the same tree read them::

    fit = LaserResampler(spec, min_angle=-2.094, resolution=0.00656, count=640, max_range=10.0)
    ranges = fit.resample(scan_ranges)      # 360 float32 ranges, beam 0 at -fov/2
    x = fit.features(scan_ranges, yaw)      # == spec.extract(ranges, yaw)

Each taught beam reads the nearest obstacle the other laser saw within its own angular
footprint (half a taught beam either side; the other laser's nearest beam when none falls in
it). A taught beam outside the other laser's field of view reads ``max_range`` (nothing seen),
which is allowed only where no feature looks: if a feature's beam or window is not covered,
the constructor raises :class:`CoverageError` naming the beams and the laser's span.

Ranges come in rhbl's convention (``protocol.ros2.convert.scan_from_laserscan`` brings a ROS 2
``LaserScan`` there): beams counter-clockwise from ``min_angle``, no echo = ``max_range``.
"""

from __future__ import annotations

import math

import numpy as np

from client.behaviour.features import FeatureError, FeatureSpec

__all__ = ["TAUGHT_BEAMS", "CoverageError", "LaserResampler"]

TAUGHT_BEAMS = 360  # the simulator's laser (protocol.md, section 2): what the trees read
_EPS = 1e-9  # rad


class CoverageError(FeatureError):
    """A laser's field of view does not cover a beam the features need."""


class LaserResampler:
    """Maps scans of one laser layout (``count`` beams, bearing(i) = ``min_angle`` + i *
    ``resolution``, radians, counter-clockwise, ``max_range`` metres) to ``beams`` beams over
    ``spec.fov`` degrees, the layout ``spec`` reads."""

    def __init__(self, spec: FeatureSpec, *, min_angle: float, resolution: float, count: int,
                 max_range: float, beams: int = TAUGHT_BEAMS):
        values = (min_angle, resolution, max_range)
        if not all(math.isfinite(float(v)) for v in values) or resolution < 0 or max_range <= 0:
            raise FeatureError(f"a laser layout needs finite min_angle, resolution >= 0 and "
                               f"max_range > 0, got {values}")
        if int(count) < 1 or (count > 1 and resolution == 0) or int(beams) < 2:
            raise FeatureError(f"a laser layout needs count >= 1 beams (resolution > 0 when "
                               f"more than one) and beams >= 2, got {count}, {beams}")
        self.spec = spec
        self.layout = (float(min_angle), float(resolution), int(count), float(max_range))
        self.beams = int(beams)
        half_fov = math.radians(spec.fov) / 2.0
        self._targets = -half_fov + np.arange(self.beams) * (2.0 * half_fov / (self.beams - 1))
        self._gather, seen = self._footprints()
        self._check_coverage(seen)

    @classmethod
    def for_scan(cls, spec: FeatureSpec, scan, beams: int = TAUGHT_BEAMS) -> LaserResampler:
        """For the layout of ``scan`` (anything with ``min_angle``, ``resolution``, ``count``
        and ``max_range``, e.g. a ``protocol.messages.Scan``)."""
        return cls(spec, min_angle=scan.min_angle, resolution=scan.resolution,
                   count=scan.count, max_range=scan.max_range, beams=beams)

    def fits(self, scan) -> bool:
        """Whether ``scan`` has this resampler's layout (rebuild one when the laser changes)."""
        return self.layout == (float(scan.min_angle), float(scan.resolution), int(scan.count),
                               float(scan.max_range))

    def _check_coverage(self, seen: np.ndarray) -> None:
        """Every taught beam a feature reads (its beam and window, out to the rounding of
        ``spec.extract``) must be seen by this laser."""
        spec, t = self.spec, self._targets
        half_step = (t[1] - t[0]) / 2.0
        missing = []
        for b in spec.beams:
            a = math.radians(max(b - spec.window, 0.0) - spec.fov / 2.0) - half_step
            z = math.radians(min(b + spec.window, spec.fov) - spec.fov / 2.0) + half_step
            if not seen[(t >= a - _EPS) & (t <= z + _EPS)].all():
                window = f" +/- {spec.window:g}" if spec.window else ""
                missing.append(f"beam {b:g}{window} deg from the right "
                               f"({math.degrees(max(a, t[0])):.1f}.."
                               f"{math.degrees(min(z, t[-1])):.1f} deg)")
        if missing:
            a0, inc, n, _ = self.layout
            raise CoverageError(
                f"the tree's features cannot be had from this laser: they need "
                f"{'; '.join(missing)}, but its {n} beams cover only "
                f"{math.degrees(a0 - inc / 2):.1f}..{math.degrees(a0 + inc * (n - 0.5)):.1f} deg "
                f"(0 = straight ahead, counter-clockwise)")

    def _footprints(self) -> tuple[np.ndarray, np.ndarray]:
        """For each taught beam, the laser's beams in its footprint (padded with ``n``: an
        index past the end, which reads ``max_range``), and whether the laser sees it at all."""
        a0, inc, n, _ = self.layout
        src = a0 + np.arange(n) * inc
        half = (self._targets[1] - self._targets[0]) / 2.0
        lo = np.searchsorted(src, self._targets - half - _EPS, side="left")
        hi = np.searchsorted(src, self._targets + half - _EPS, side="left")
        nearest = np.clip(np.rint((self._targets - a0) / inc) if inc > 0 else 0, 0, n - 1)
        nearest = nearest.astype(np.intp)
        seen = np.abs(self._targets - src[nearest]) <= inc / 2.0 + _EPS
        empty = hi <= lo
        lo = np.where(empty, nearest, lo)
        hi = np.where(empty, np.where(seen, nearest + 1, nearest), hi)
        width = max(1, int((hi - lo).max()))
        gather = lo[:, None] + np.arange(width)[None, :]
        return np.where(gather < hi[:, None], gather, n), hi > lo

    def resample(self, ranges) -> np.ndarray:
        """``beams`` float32 ranges in the taught layout from this laser's ``count`` ranges
        (NaN or infinite values read as no echo, ``max_range``)."""
        r = np.asarray(ranges, dtype=np.float32).reshape(-1)
        a0, inc, n, max_range = self.layout
        if r.size != n:
            raise FeatureError(f"expected a scan of {n} beams (this laser's layout), "
                               f"got {r.size}")
        ext = np.empty(n + 1, dtype=np.float32)
        ext[:n] = np.where(np.isfinite(r), r, np.float32(max_range))
        ext[n] = max_range
        return ext[self._gather].min(axis=1)

    def features(self, ranges, yaw: float = 0.0) -> np.ndarray:
        """``spec.extract`` of the resampled scan: the tree's input vector."""
        return self.spec.extract(self.resample(ranges), yaw)
