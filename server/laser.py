"""The simulated laser: every laser of a tick cast against the walls and the other robots in
one compiled call (numba).

:meth:`server.world.World.scans` (and ``scan``) calls :meth:`Laser.cast` once per tick for all
its lasers. A tick's cost is the arithmetic of what each laser can see,
not a number of interpreter calls (with numpy, a one-robot cast was about 45 numpy calls of
0.5-3 us each, and their overhead was most of a tick):

1. walls: a segment is cast only for a laser that can see it: not wholly behind the laser and
   within range (the segment's point nearest the laser), and only over the beams of its angular
   interval (one beam of margin on each side; the exact test decides). Each (segment, beam)
   element is the float32 intersection of the full ``segments x beams`` cast: with
   ``a`` = segment start - origin, ``e`` = segment vector, ``d`` = the beam's direction,
   ``inv = 1 / (e_y d_x - e_x d_y)``, range ``(a_x e_y - a_y e_x) inv`` and position along the
   segment ``(a_x d_y - a_y d_x) inv``; a hit has position in [0, 1] and range > 0.
2. robots: a robot j is cast for laser i if it is within range, not wholly behind and the
   laser's origin is outside its circle (a ray starting inside a circle never reports it), a
   laser never sees its own robot; only over the beams of ``bearing(j) +- asin(r / d)`` (one
   beam of margin), in float64: ``b = d . q``, ``t = b - sqrt(b^2 - (|q|^2 - r^2))``.

The culling only skips work whose result cannot be a hit, so the ranges equal those of the full
dense cast (:func:`robots_dense` is the plain cast of one laser against every other robot, kept
as the reference the tests and ``benchmarks/bench_sim.py --compare`` use). The laser's field of
view must not exceed 180 degrees (a robot's angular interval is then never cut by the wrap at
+-pi inside it). The kernels are compiled once per machine (numba's cache, next to this file or
in numba's cache folder) and loaded from there by every later process.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

__all__ = ["Laser", "robots_dense"]


def _jit(func):
    """numba-compile ``func`` when first called; cached on disk (next to this file, else in
    the user's cache folder, or in ``NUMBA_CACHE_DIR``) so later processes load it. Without a
    writable cache folder it is compiled in each process. error_model="numpy": a division by
    zero gives inf (a beam parallel to a segment), as in numpy."""
    try:
        return njit(cache=True, nogil=True, error_model="numpy")(func)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        return njit(nogil=True, error_model="numpy")(func)


_F32 = np.float32
_TWO_PI = 2.0 * math.pi


@_jit
def _beam_index(angle, start, resolution, up):
    """The beam just below (``up`` False: floor, minus a margin of one) or just above (ceil,
    plus one) ``angle``, a bearing in the laser's frame."""
    x = (angle - start) / resolution
    return math.ceil(x) + 1 if up else math.floor(x) - 1


@_jit
def _cast_segment(out, lo, hi, ax, ay, ex, ey, dc, ds):
    """Lower ``out[lo..hi]`` where those beams hit the segment (float32 arithmetic)."""
    lo = max(lo, 0)
    hi = min(hi, out.shape[0] - 1)
    ax32, ay32, ex32, ey32 = _F32(ax), _F32(ay), _F32(ex), _F32(ey)
    num = ax32 * ey32 - ay32 * ex32
    one = _F32(1.0)
    for b in range(lo, hi + 1):
        inv = one / (ey32 * dc[b] - ex32 * ds[b])
        tr = num * inv
        u = (ax32 * ds[b] - ay32 * dc[b]) * inv
        if u >= 0.0 and u <= 1.0 and tr > 0.0 and tr < out[b]:
            out[b] = tr


@_jit
def _walls(out, ox, oy, yaw, segs, dc, ds, start, resolution, max_range):
    """Fill ``out`` (float32, beams) with the ranges from (ox, oy) facing ``yaw`` to the walls
    ``segs`` (S, 4: x0, y0, x1, y1); ``dc``/``ds``: float32 cosines and sines of the beams'
    world angles."""
    out[:] = _F32(max_range)
    fx, fy = math.cos(yaw), math.sin(yaw)
    for j in range(segs.shape[0]):
        ax, ay = segs[j, 0] - ox, segs[j, 1] - oy
        bx, by = segs[j, 2] - ox, segs[j, 3] - oy
        if ax * fx + ay * fy < 0.0 and bx * fx + by * fy < 0.0:
            continue  # wholly behind the laser
        ex, ey = segs[j, 2] - segs[j, 0], segs[j, 3] - segs[j, 1]
        ee = ex * ex + ey * ey
        t = (ax * ex + ay * ey) / -(ee if ee > 0.0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        nx, ny = ex * t + ax, ey * t + ay  # the segment's point nearest the laser
        if not nx * nx + ny * ny < max_range * max_range:
            continue
        a0 = (math.atan2(ay, ax) - yaw + math.pi) % _TWO_PI - math.pi
        a1 = (math.atan2(by, bx) - yaw + math.pi) % _TWO_PI - math.pi
        amin, amax = min(a0, a1), max(a0, a1)
        if amax - amin > math.pi:  # the short way round passes behind the laser: two parts
            _cast_segment(out, _beam_index(amax, start, resolution, False),
                          _beam_index(math.pi, start, resolution, True), ax, ay, ex, ey, dc, ds)
            _cast_segment(out, _beam_index(-math.pi, start, resolution, False),
                          _beam_index(amin, start, resolution, True), ax, ay, ex, ey, dc, ds)
        else:
            _cast_segment(out, _beam_index(amin, start, resolution, False),
                          _beam_index(amax, start, resolution, True), ax, ay, ex, ey, dc, ds)


@_jit
def _robots(out, ox, oy, yaw, own, centres, dc, ds, radius, start, resolution, max_range):
    """Lower ``out`` where the beams from (ox, oy) facing ``yaw`` hit a robot (``centres``
    (N, 2); robot ``own`` is the laser's own, never seen)."""
    count = out.shape[0]
    fx, fy = math.cos(yaw), math.sin(yaw)
    reach = max_range + radius
    for j in range(centres.shape[0]):
        if j == own:
            continue
        qx, qy = centres[j, 0] - ox, centres[j, 1] - oy
        qq = qx * qx + qy * qy
        c = qq - radius * radius
        if not (c > 0.0 and qq < reach * reach and qx * fx + qy * fy > -radius):
            continue
        bearing = (math.atan2(qy, qx) - yaw + math.pi) % _TWO_PI - math.pi
        half = math.asin(min(radius / math.sqrt(qq), 1.0))
        lo = max(_beam_index(bearing - half, start, resolution, False), 0)
        hi = min(_beam_index(bearing + half, start, resolution, True), count - 1)
        for b in range(lo, hi + 1):
            bb = np.float64(dc[b]) * qx + np.float64(ds[b]) * qy
            disc = bb * bb - c
            if disc >= 0.0:
                t = bb - math.sqrt(disc)
                if t > 0.0 and t < out[b]:
                    out[b] = _F32(t)


@_jit
def _directions(dc, ds, bearings, yaw):
    """The float32 cosines and sines of the beams' world angles at heading ``yaw``."""
    for b in range(bearings.shape[0]):
        a = bearings[b] + yaw
        dc[b] = _F32(math.cos(a))
        ds[b] = _F32(math.sin(a))


@_jit
def _cast(out, origins, yaws, rows, centres, segs, bearings, kept, dc, ds, radius, start,
          resolution, max_range):
    n = out.shape[0]
    if origins.shape[0] != n or yaws.shape[0] != n or rows.shape[0] != n:
        raise ValueError("cast: origins, yaws, rows and out need one row per laser")
    if origins.shape[1] != 2 or out.shape[1] != bearings.shape[0]:
        raise ValueError("cast: origins are (x, y) and out has one column per beam")
    for i in range(n):
        if rows[i] < 0 or rows[i] >= kept.shape[0]:
            raise ValueError("cast: a laser's robot row is outside 0 .. robots - 1")
    for i in range(n):
        ox, oy, yaw, row = origins[i, 0], origins[i, 1], yaws[i], rows[i]
        if kept[row] != yaw:  # NaN (none kept) is never equal
            _directions(dc[row], ds[row], bearings, yaw)
            kept[row] = yaw
        _walls(out[i], ox, oy, yaw, segs, dc[row], ds[row], start, resolution, max_range)
        if centres.shape[0] > 1:
            _robots(out[i], ox, oy, yaw, row, centres, dc[row], ds[row], radius, start,
                    resolution, max_range)


_KERNELS = (_beam_index, _cast_segment, _walls, _robots, _directions, _cast)


class Laser:
    """The lasers of one world's ``robots`` robots: the wall segments ``segs`` (S, 4: x0, y0,
    x1, y1), the beams' ``bearings`` in the robot frame (at least 2, evenly spaced, spanning at
    most 180 degrees), ``max_range``, the robots' ``radius``; and per robot the float32 cosines
    and sines of its beams' world angles at its last heading (recomputed only when the heading
    changes: a robot driving straight or standing reuses them).

    The ranges equal the dense cast's (every segment against every beam) for a laser farther
    than about a micrometre from every wall and a heading in [-pi, pi] (``World`` wraps it): at
    a wall, the dense cast finds hits of 1e-7 m on beams outside the segment's angular interval,
    which this cast skips. Not re-entrant: one ``Laser`` is cast from one thread at a time (the
    kept directions are updated in place; the server casts under its lock)."""

    def __init__(self, segs: np.ndarray, bearings: np.ndarray, max_range: float,
                 radius: float, robots: int = 1) -> None:
        self.segs = np.ascontiguousarray(segs, dtype=np.float64).reshape(-1, 4)
        self.bearings = np.ascontiguousarray(bearings, dtype=np.float64)
        count = len(self.bearings)
        steps = np.diff(self.bearings)
        if count < 2 or not np.all(steps > 0) or not np.allclose(steps, steps[0]) or \
                self.bearings[-1] - self.bearings[0] > math.pi + 1e-9:
            raise ValueError("a laser's bearings are at least 2, evenly spaced and span at most "
                             "180 degrees")
        self.start = float(self.bearings[0])
        self.resolution = float(self.bearings[-1] - self.bearings[0]) / max(count - 1, 1)
        self.max_range = float(max_range)
        self.radius = float(radius)
        self.kept = np.full(robots, np.nan)  # the heading of each robot's directions
        self.dc = np.zeros((robots, count), dtype=np.float32)
        self.ds = np.zeros((robots, count), dtype=np.float32)
        # compile (first process on a machine, about 2 s) or load the kernels now, not in the
        # first tick
        try:
            self._warm_up()
        except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
            log.warning("cannot cache the laser's compiled code (%s): compiled in this process",
                        e)
            for kernel in _KERNELS:
                kernel._cache.disable()
            self._warm_up()

    def _warm_up(self) -> None:
        self.cast(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=np.intp), np.zeros((0, 2)))

    def cast(self, origins: np.ndarray, yaws: np.ndarray, rows: np.ndarray,
             centres: np.ndarray) -> np.ndarray:
        """Ranges (R, beams) float32 of R lasers against the walls and the robots: the lasers
        at ``origins`` (R, 2) facing ``yaws`` (R,) belong to robots ``rows`` (R, intp; a laser
        never sees its own robot); ``centres`` (N, 2) are every robot's positions (fewer than
        two: walls only)."""
        out = np.empty((len(rows), len(self.bearings)), dtype=np.float32)
        _cast(out, origins, yaws, rows, centres, self.segs, self.bearings, self.kept, self.dc,
              self.ds, self.radius, self.start, self.resolution, self.max_range)
        return out

    def directions(self, row: int) -> tuple[np.ndarray, np.ndarray]:
        """Robot ``row``'s beam directions at its last cast heading (float32 cosines, sines;
        copies)."""
        return self.dc[row].copy(), self.ds[row].copy()


def robots_dense(
    ranges: np.ndarray,
    origin: tuple[float, float],
    dc: np.ndarray,
    ds: np.ndarray,
    others: np.ndarray,
    radius: float,
    max_range: float,
) -> np.ndarray:
    """The plain cast of one laser against every other robot (``others`` (M, 2) centres):
    ``beams x robots`` work per laser, in numpy. The reference :meth:`Laser.cast` is tested and
    benchmarked against (it was the simulator's cast before the fleet was cast together)."""
    if len(others) == 0:
        return ranges
    q = np.asarray(others, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    b = np.multiply.outer(dc, q[:, 0]) + np.multiply.outer(ds, q[:, 1])
    disc = b * b - (np.einsum("ij,ij->i", q, q) - radius**2)
    with np.errstate(invalid="ignore"):
        t = b - np.sqrt(disc)
    ok = (disc >= 0) & (t > 0)
    t = np.where(ok, t, max_range)
    return np.minimum(ranges, t.min(axis=1)).astype(np.float32)
