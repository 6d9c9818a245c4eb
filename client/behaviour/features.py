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

``spec.reader()`` reads scans in place from their payloads with these features, one compiled
call each (``PayloadReader``: the controller's hot path; ``Scan.decode`` for any other layout).

``heading="lr"`` appends the paper's maze feature: 0.66 when the robot is right-directional
(cos(yaw) >= 0, heading towards +x) and 0.33 when left-directional.

``beacon`` appends what the fiducial finder sees of one beacon (Player's ``fiducial``
interface: ``protocol.messages.Fiducial``), three values after the beams and the heading:
``in view`` (1.0, or 0.0 when that beacon is not seen), its ``range`` clamped to and divided by
``beacon_range`` m, and its ``bearing`` as ``(bearing / pi + 1) / 2`` (0.5 straight ahead, more
to the left; ``beacon_bearing`` degrees less than 180: the bearing clipped to +- it and mapped
so, a finer view of a narrower field). "None in view" is a value of its own: ``NO_BEACON`` (0.0, 1.0, 0.5: not seen, as
far as can be, ahead), so a tree tells it apart from any sighting by the first value alone.
``beacon`` is an id (``beacon = 2``: that beacon always) or ``"goal"``: the beacon the caller
names with each scan (``target=``; the current goal's, say; None: none, so none in view)::

    spec = FeatureSpec(beams=(...), beacon="goal")
    x = spec.extract(ranges, yaw, seen=fiducial.items, target=2)

A process reading scans pairs each with its tick's sightings through the client's fiducial log
(``client.player.PlayerClient.fiducials``: ``log.seen(scan.id)``), then ``reader.see(...)``.
"""

from __future__ import annotations

import functools
import importlib
import logging
import math
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from protocol.messages import Scan
from rhbl.tree import KERNELS_ENV

from . import _payload_layout as _layout

__all__ = ["BEACON_GOAL", "DEFAULT_FEATURES", "FeatureSpec", "FeatureError", "FEATURES",
           "HEADING_LEFT", "HEADING_RIGHT", "NO_BEACON", "PayloadReader"]

HEADING_LEFT = 0.33
HEADING_RIGHT = 0.66
_HEADINGS = (None, "lr")
BEACON_GOAL = "goal"  # ``beacon``: the beacon named with each scan (``target``)
NO_BEACON = (0.0, 1.0, 0.5)  # the beacon's three values when it is not in view


log = logging.getLogger(__name__)
_LITTLE = sys.byteorder == "little"  # the payload kernel reads the wire's float32s as its own


@functools.cache
def _payload_kernel():
    """The payload kernel of this process: compiled ahead of time (``_payload_aot``, from this
    checkout's source) or numba's (compiled on first use or loaded from numba's cache; always
    with ``RHBL_KERNELS=jit``, as the tree's)."""
    if os.environ.get(KERNELS_ENV, "") != "jit":
        try:
            aot = importlib.import_module("._payload_aot", __package__)
        except ImportError:
            aot = None
        if aot is not None and aot.source_hash() == _layout.source_hash():
            return aot.read_features
    return importlib.import_module("._payload_kernels", __package__).read_features


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
    beacon: int | str | None = None
    beacon_range: float = 8.0
    beacon_bearing: float = 180.0  # degrees: the bearing is clipped to +- this, mapped on [0, 1]
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
        b = self.beacon
        if b is not None and b != BEACON_GOAL and (isinstance(b, bool) or not isinstance(b, int)
                                                   or b < 1):
            raise FeatureError(f"beacon must be a beacon id (an integer >= 1) or "
                               f"{BEACON_GOAL!r}, got {b!r}")
        if not (self.beacon_range > 0 and math.isfinite(self.beacon_range)):
            raise FeatureError(f"beacon_range must be > 0 m, got {self.beacon_range}")
        if not 0 < self.beacon_bearing <= 180:
            raise FeatureError(f"beacon_bearing must be in (0, 180] degrees, got "
                               f"{self.beacon_bearing}")

    @property
    def dim(self) -> int:
        return len(self.beams) + (1 if self.heading else 0) + (3 if self.beacon else 0)

    def beacon_values(self, seen=None, target: int | None = None) -> tuple[float, float, float]:
        """The three beacon features (``in view``, range, bearing) of the beacon this spec
        follows (its ``beacon`` id, or ``target`` for ``"goal"``) among ``seen`` (items with
        ``id``, ``range``, ``bearing``: ``Fiducial.items``; None: nothing seen):
        ``NO_BEACON`` when it is not among them."""
        want = target if self.beacon == BEACON_GOAL else self.beacon
        if not want or not seen:  # none named (or 0: no beacon is identified as it)
            return NO_BEACON
        for item in seen:
            if item.id == want:
                r = min(max(float(item.range), 0.0), self.beacon_range) / self.beacon_range
                b = float(item.bearing)
                if not (math.isfinite(r) and math.isfinite(b)):
                    return NO_BEACON
                half = math.radians(self.beacon_bearing)
                return (1.0, r, min(max((b / half + 1.0) / 2.0, 0.0), 1.0))
        return NO_BEACON

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

    def extract(self, ranges, yaw: float = 0.0, seen=None, target: int | None = None
                ) -> np.ndarray:
        """The features of one scan (``ranges``, odometry heading ``yaw``); with ``beacon``,
        of what the fiducial finder saw at that scan (``seen``, ``target``:
        :meth:`beacon_values`)."""
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
        if self.beacon:
            v.extend(self.beacon_values(seen, target))
        return np.array(v, dtype=np.float64)

    def reader(self) -> PayloadReader:
        """A ``PayloadReader``: scans read in place from their payloads with these features."""
        return PayloadReader(self)

    def extract_many(self, ranges, yaws=None, seen=None, targets=None) -> np.ndarray:
        """The features of many scans of one beam count at once: ``ranges`` (scans, beams),
        ``yaws`` one per scan (default 0), with ``beacon`` ``seen`` and ``targets`` one per scan
        (default None); row i is ``extract(ranges[i], yaws[i], seen[i], targets[i])``, bit for
        bit (a fleet's scans of a tick, for one batched tree query)."""
        r = np.asarray(ranges)
        if r.ndim != 2 or r.shape[1] < 2:
            raise FeatureError(f"ranges must be scans of one beam count (scans, beams), got "
                               f"shape {r.shape}")
        yaws = [0.0] * len(r) if yaws is None else [float(y) for y in yaws]
        if len(yaws) != len(r):
            raise FeatureError(f"{len(r)} scans but {len(yaws)} headings")
        seen = [None] * len(r) if seen is None else list(seen)
        targets = [None] * len(r) if targets is None else list(targets)
        if len(seen) != len(r) or len(targets) != len(r):
            raise FeatureError(f"{len(r)} scans but {len(seen)} sightings and {len(targets)} "
                               f"targets")
        at = self._reduce_at(r.shape[1])
        if at is None or not len(r):  # a window at the scan's end: one scan at a time
            return np.array([self.extract(row, y, s, t) for row, y, s, t
                             in zip(r, yaws, seen, targets, strict=True)],
                            dtype=np.float64).reshape(len(r), self.dim)
        # as extract: each window's minimum as a double, clamped (NaN or negative: far), scaled
        x = np.minimum.reduceat(r, at, axis=1)[:, ::2].astype(np.float64)
        v = np.where(x >= 0.0, np.minimum(x, self.clamp), self.clamp) / self.scale
        if self.heading == "lr":
            side = [HEADING_RIGHT if math.cos(y) >= 0.0 else HEADING_LEFT for y in yaws]
            v = np.column_stack([v, np.array(side, dtype=np.float64)])
        if self.beacon:
            v = np.column_stack([v, np.array([self.beacon_values(s, t) for s, t
                                              in zip(seen, targets, strict=True)],
                                             dtype=np.float64).reshape(len(r), 3)])
        return v

    def to_dict(self) -> dict:
        return {
            "beams": list(self.beams),
            "clamp": self.clamp,
            "scale": self.scale,
            "heading": self.heading,
            "window": self.window,
            "fov": self.fov,
            # only when used: the dicts of specs without (every snapshot before) are unchanged
            **({"beacon": self.beacon, "beacon_range": self.beacon_range}
               if self.beacon else {}),
            **({"beacon_bearing": self.beacon_bearing}
               if self.beacon and self.beacon_bearing != 180.0 else {}),
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
                beacon=data.get("beacon"),
                beacon_range=float(data.get("beacon_range", 8.0)),
                beacon_bearing=float(data.get("beacon_bearing", 180.0)),
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
    # all round: the whole scan condensed into nine sector minima of 22.5 degrees, from the
    # robot's right through straight ahead to its left (a polar histogram, as in VFH): one spec
    # that sees a wall on either side, the way between two walls and what lies ahead
    "around": FeatureSpec(beams=tuple(22.5 * i for i in range(9)), window=11.25),
}

# The perception of a new tree when none is named (``rhbl learner`` without ``--features``): it
# sees ahead and both sides, so that every shipped behaviour is learnable with it
# (docs/behaviours.md, "The default perception"); the paper's specs stay for its figures.
DEFAULT_FEATURES = "around"


class PayloadReader:
    """Scans read in place from their payloads with the features of ``spec``, one compiled call
    each (the controller's hot path: no map built, no array made, the ranges not copied).

    After ``read(data)`` returned True, until the next ``read``: ``ts``, ``id``, ``x`` (the
    features, ``spec.extract(scan.ranges, scan.pose[2])``: equal values; the beacon's, if
    the spec has them, "none in view" until :meth:`see` sets them), ``ranges`` (a
    read-only view into ``data``), ``pose``, ``min_angle``, ``max_angle``, ``resolution``,
    ``max_range``, ``truth``, ``bearings()`` are those of the scan ``Scan.decode(data)`` gives,
    and ``to_scan()`` is that ``Scan``. ``read`` is False for a payload not laid out exactly as
    ``Scan.encode`` writes it (the fields in its order, every number a float64 but ``v`` and
    ``id``) or with a value that is not finite, valid or not: ``Scan.decode`` then accepts it
    or names what is wrong. One thread at a time (its buffers are reused)."""

    def __init__(self, spec: FeatureSpec) -> None:
        self.spec = spec
        self.x = np.empty(spec.dim)
        self._head = np.empty(_layout.HEAD)
        self._ints = np.empty(_layout.INTS, dtype=np.int64)
        self._data = b""
        self._read = _payload_kernel()
        self._windows(360)
        self.ts, self.id = 0.0, 0
        # numba's kernel compiled (or loaded from its cache) now, not at the first scan
        warm_up = Scan(ts=0.0, id=0, ranges=np.ones(360, dtype=np.float32)).encode()
        try:
            self.read(warm_up)
        except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
            log.warning("cannot cache the scan reader's compiled code (%s): compiled in this "
                        "process", e)
            importlib.import_module("._payload_kernels", __package__).disable_cache()
            self.read(warm_up)

    def _windows(self, count: int) -> None:
        """The kernel's windows (each beam's ``lo, hi``) and scaling, for ``count`` beams."""
        windows = np.array(self.spec._slices(count), dtype=np.int64).ravel()
        self._count = count
        self._args = (windows, self.spec.clamp, self.spec.scale)

    def read(self, data: bytes) -> bool:
        """Read the scan whose payload is ``data`` (bytes, as received); False: not read."""
        if type(data) is not bytes or len(data) > Scan.MAX_SIZE or not _LITTLE:
            return False
        beams = self._read(data, *self._args, self.x, self._head, self._ints)
        if beams and beams != self._count:  # another beam count: its windows, then again
            if abs(beams) < 2:  # a scan the features cannot take (extract names why)
                return False
            self._windows(abs(beams))
            beams = self._read(data, *self._args, self.x, self._head, self._ints)
        if beams < 2:
            return False
        self._data = data
        self.ts, self.id = self._head.item(_layout.TS), self._ints.item(_layout.ID)
        if self.spec.heading == "lr":
            yaw = self._head.item(_layout.YAW)
            self.x[len(self.spec.beams)] = HEADING_RIGHT if math.cos(yaw) >= 0.0 else HEADING_LEFT
        if self.spec.beacon:
            self.x[-3:] = NO_BEACON  # until ``see`` says what the fiducial finder saw
        return True

    def see(self, seen=None, target: int | None = None) -> None:
        """Set the beacon features of the scan read (``spec.beacon_values(seen, target)``;
        ``read`` leaves them at ``NO_BEACON``). Nothing to do for a spec without ``beacon``."""
        if self.spec.beacon:
            self.x[-3:] = self.spec.beacon_values(seen, target)

    @property
    def count(self) -> int:
        return self._ints.item(_layout.BEAMS)

    @property
    def ranges(self) -> np.ndarray:
        return np.frombuffer(self._data, np.float32, self.count, self._ints.item(_layout.OFFSET))

    @property
    def pose(self) -> tuple[float, float, float]:
        x, y, yaw = self._head[_layout.X:_layout.X + 3].tolist()
        return x, y, yaw

    @property
    def truth(self) -> tuple[float, float, float] | None:
        if self._ints.item(_layout.FIELDS) != len(_layout.KEYS):
            return None
        x, y, yaw = self._head[_layout.TRUTH:_layout.TRUTH + 3].tolist()
        return x, y, yaw

    min_angle = property(lambda self: self._head.item(_layout.MIN_ANGLE))
    max_angle = property(lambda self: self._head.item(_layout.MAX_ANGLE))
    resolution = property(lambda self: self._head.item(_layout.RESOLUTION))
    max_range = property(lambda self: self._head.item(_layout.MAX_RANGE))
    bearings = Scan.bearings  # min_angle + i * resolution, as the scan's

    def to_scan(self) -> Scan:
        """The ``Scan`` read (its ranges a copy of its own)."""
        return Scan(ts=self.ts, id=self.id, ranges=self.ranges.copy(), pose=self.pose,
                    min_angle=self.min_angle, max_angle=self.max_angle,
                    resolution=self.resolution, max_range=self.max_range, truth=self.truth)

