"""Feature specification: which laser beams feed the tree, clamping, scaling, heading.

    spec = FEATURES["wall"]
    x = spec.extract(ranges, yaw)      # np.ndarray float64, every value in [0, 1]
    spec.dim                           # number of features
    FeatureSpec.from_dict(spec.to_dict()) == spec    (stored in every snapshot's metadata)

``ranges`` is the 360-beam scan (float32, ranges[0] at -90 deg = the robot's right, beams
counter-clockwise over ``fov`` degrees). Beams are given in degrees measured from the right edge of
the scan (0 = right, 90 = straight ahead, 180 = left), so a spec does not depend on the beam count.
Each beam value is the minimum over +/- ``window`` degrees around it (``window=0`` is the paper's
single ping), clamped to ``clamp`` metres and divided by ``scale`` (paper: 2.0 and 2.0).

``heading="lr"`` appends the paper's maze feature: 0.66 when the robot is right-directional
(cos(yaw) >= 0, heading towards +x) and 0.33 when left-directional.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FeatureSpec", "FeatureError", "FEATURES", "HEADING_LEFT", "HEADING_RIGHT"]

HEADING_LEFT = 0.33
HEADING_RIGHT = 0.66
_HEADINGS = (None, "lr")


class FeatureError(ValueError):
    """A malformed feature specification or scan."""


@dataclass(frozen=True)
class FeatureSpec:
    beams: tuple[float, ...]
    clamp: float = 2.0
    scale: float = 2.0
    heading: str | None = None
    window: float = 0.0
    fov: float = 180.0
    _cache: dict = field(default_factory=dict, compare=False, repr=False, hash=False)

    def __post_init__(self):
        beams = tuple(float(b) for b in self.beams)
        object.__setattr__(self, "beams", beams)
        if not beams:
            raise FeatureError("a feature spec needs at least one beam")
        for b in beams:
            if not 0.0 <= b <= self.fov:
                raise FeatureError(f"beam {b} deg outside the scan's 0..{self.fov} deg")
        if not (self.clamp > 0 and self.scale > 0):
            raise FeatureError(f"clamp and scale must be > 0, got {self.clamp}, {self.scale}")
        if self.clamp > self.scale:
            raise FeatureError(f"clamp {self.clamp} > scale {self.scale}: features would exceed 1")
        if self.heading not in _HEADINGS:
            raise FeatureError(f"heading must be one of {_HEADINGS}, got {self.heading!r}")
        if self.window < 0:
            raise FeatureError(f"window must be >= 0, got {self.window}")

    @property
    def dim(self) -> int:
        return len(self.beams) + (1 if self.heading else 0)

    def _slices(self, count: int) -> list[tuple[int, int]]:
        key = count
        sl = self._cache.get(key)
        if sl is None:
            per = (count - 1) / self.fov
            sl = []
            for b in self.beams:
                lo = max(0, int(math.floor((b - self.window) * per + 0.5)))
                hi = min(count - 1, int(math.floor((b + self.window) * per + 0.5)))
                sl.append((lo, hi + 1))
            self._cache[key] = sl
        return sl

    def beam_indices(self, count: int = 360) -> list[int]:
        """Index of each beam's centre in a scan of ``count`` beams."""
        per = (count - 1) / self.fov
        return [int(math.floor(b * per + 0.5)) for b in self.beams]

    def _reduce_at(self, count: int) -> np.ndarray | None:
        """The indices ``np.minimum.reduceat`` takes to give each beam's window minimum at its
        even positions (``lo, hi`` of each window in turn; the last window's ``hi`` is dropped
        when it is the scan's end, the reduction then runs to it); None when another window
        ends at the scan's end (:meth:`extract` then takes the windows one by one)."""
        key = ("reduceat", count)
        if key not in self._cache:
            pairs = [i for window in self._slices(count) for i in window]
            if pairs[-1] == count:
                pairs.pop()
            self._cache[key] = (np.array(pairs, dtype=np.intp) if max(pairs) < count
                                else None)
        return self._cache[key]

    def extract(self, ranges, yaw: float = 0.0) -> np.ndarray:
        r = ranges if type(ranges) is np.ndarray else np.asarray(ranges)
        if r.ndim != 1 or r.size < 2:
            raise FeatureError(f"ranges must be a 1-D scan, got shape {r.shape}")
        at = self._reduce_at(r.size)
        if at is not None:  # every window's minimum in one call (as the loop below gives)
            mins = np.minimum.reduceat(r, at)[::2].tolist()
        else:
            mins = [float(r[lo:hi].min()) for lo, hi in self._slices(r.size)]
        # a few beams: Python's floats (doubles, as numpy's float64) cost less than arrays
        clamp, scale = self.clamp, self.scale
        v = [(x if x <= clamp else clamp) / scale if x >= 0.0 else clamp / scale
             for x in mins]  # NaN or negative: treat as no reading (far)
        if self.heading == "lr":
            v.append(HEADING_RIGHT if math.cos(yaw) >= 0.0 else HEADING_LEFT)
        return np.array(v, dtype=np.float64)

    def to_dict(self) -> dict:
        return {
            "beams": list(self.beams),
            "clamp": self.clamp,
            "scale": self.scale,
            "heading": self.heading,
            "window": self.window,
            "fov": self.fov,
        }

    @classmethod
    def from_dict(cls, data: Mapping) -> FeatureSpec:
        try:
            return cls(
                beams=tuple(data["beams"]),
                clamp=float(data.get("clamp", 2.0)),
                scale=float(data.get("scale", 2.0)),
                heading=data.get("heading"),
                window=float(data.get("window", 0.0)),
                fov=float(data.get("fov", 180.0)),
            )
        except (KeyError, TypeError) as exc:
            raise FeatureError(f"a feature spec dict needs 'beams', got {data!r}") from exc


# "wall": five beams concentrated on the followed (right) side, see docs/experiments.md.
# "maze": five symmetric beams plus the paper's left/right-directional heading value.
# "maze-right": the maze recipe's default (docs/experiments.md): five beams 0-120 deg from the
# right edge, each the minimum over +/- 10 deg, no heading. The maze teacher is a right-hand
# wall follower, so its labels do not depend on the heading; the heading value tied each tier's
# travel direction to the training maze's layout and failed on mazes whose openings alternate
# the other way.
FEATURES: dict[str, FeatureSpec] = {
    "wall": FeatureSpec(beams=(0.0, 22.5, 45.0, 67.5, 90.0), window=11.25),
    "wall-ping": FeatureSpec(beams=(0.0, 22.5, 45.0, 67.5, 90.0)),
    "maze": FeatureSpec(beams=(0.0, 45.0, 90.0, 135.0, 180.0), heading="lr"),
    "maze-right": FeatureSpec(beams=(0.0, 30.0, 60.0, 90.0, 120.0), window=10.0),
}
