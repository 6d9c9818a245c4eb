"""The laser's compiled kernels (numba): every laser of a tick cast in one call
(:mod:`server.laser` describes the cast and holds the ``Laser`` that calls them).

Compiled ahead of time when the package is installed (``setup.py``: the extension module
``server._laser_aot``, which needs no numba, from :func:`aot_exports`), else by numba on first
use and cached (next to this file, else in the user's cache folder or ``NUMBA_CACHE_DIR``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["aot_exports", "cast", "disable_cache"]


def _jit(func):
    """numba-compile ``func`` when first called; cached on disk (next to this file, else in
    the user's cache folder, or in ``NUMBA_CACHE_DIR``) so later processes load it. Without a
    writable cache folder it is compiled in each process. error_model="numpy": a division by
    zero gives inf (a beam parallel to a segment), as in numpy (the ahead-of-time build
    compiles with the same options)."""
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
def cast(out, origins, yaws, rows, centres, segs, bearings, kept, dc, ds, radius, start,
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


_KERNELS = (_beam_index, _cast_segment, _walls, _robots, _directions, cast)


def aot_exports() -> dict:
    """name -> (function, signature) of the kernels ``setup.py`` compiles ahead of time."""
    f32, f64 = "float32[:, ::1]", "float64[:, ::1]"
    return {"cast": (cast, f"void({f32}, {f64}, float64[::1], intp[::1], {f64}, {f64}, "
                           f"float64[::1], float64[::1], {f32}, {f32}, float64, float64, "
                           "float64, float64)")}


def disable_cache() -> None:
    """Compile in this process only (the cache folder cannot take the code)."""
    for kernel in _KERNELS:
        kernel._cache.disable()
