"""Robots seen by robots: the many-robot part of the simulated laser, for all robots at once.

:meth:`server.world.World.scans` casts every robot's walls first (``World._scan_walls``), then
calls :func:`robots_into` once for the whole fleet. Casting each beam against every other robot
costs ``beams x robots`` per robot, so ``beams x robots**2`` per tick: this was the part of a
server tick that grew with the square of the fleet. Here the work is bounded by what can be seen:

1. all pairs (laser i, robot j) at once from one array of positions: a pair is kept only if j is
   within range, not wholly behind the laser and the laser's origin is outside j's circle (a ray
   starting inside a circle never reports it, as before);
2. each kept pair covers the beams of an angular interval ``bearing(j) +- asin(r / d)`` (one beam
   of margin on each side, the exact test below decides); a pair is dropped when its nearest
   possible hit ``d - r`` lies beyond every range of laser i over that interval (a maximum query
   on a sparse table of blocks of beams), nearest pairs first, so robots behind walls (in other
   rooms) or behind nearer robots cost little;
3. only the (pair, beam) elements left are intersected, with the same per-element arithmetic as a
   full ``beams x robots`` cast (so the result is the same), and folded into the ranges with a
   minimum.

The laser's field of view must not exceed 180 degrees (a circle's angular interval is then never
cut by the wrap at +-pi inside the field of view).
"""

from __future__ import annotations

import numpy as np

__all__ = ["robots_into"]

_BANDS = (1.0, 2.0, 3.5)  # m, distance bands of the nearest-first cast


_BLOCK = 16  # beams per block of the occlusion bound


def _block_max_table(ranges: np.ndarray) -> np.ndarray:
    """Sparse table over blocks of ``_BLOCK`` beams, (levels, rows, blocks):
    ``table[k, row, j]`` is the maximum range of blocks j .. j + 2**k - 1 of ``row`` (j up to
    blocks - 2**k; the rest of a level is unused)."""
    n, count = ranges.shape
    nb = -(-count // _BLOCK)
    padded = np.zeros((n, nb * _BLOCK), dtype=ranges.dtype)
    padded[:, :count] = ranges
    m = padded.reshape(n, nb, _BLOCK)
    half = _BLOCK // 2
    while half:  # the maximum of each block by halves: elementwise, not a short reduction
        m = np.maximum(m[..., :half], m[..., half : 2 * half])
        half //= 2
    table = np.zeros((nb.bit_length(), n, nb), dtype=ranges.dtype)
    table[0] = m[..., 0]
    span = 1
    for k in range(1, len(table)):
        w = nb - 2 * span + 1
        np.maximum(table[k - 1, :, :w], table[k - 1, :, span : span + w], out=table[k, :, :w])
        span *= 2
    return table


def _range_bound(table: np.ndarray, row: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """An upper bound (the maximum over whole blocks) of ``ranges[row, lo..hi]``, lo <= hi."""
    levels, n, nb = table.shape
    blo, bhi = lo // _BLOCK, hi // _BLOCK
    log2 = np.zeros(nb + 1, dtype=np.intp)  # floor(log2(i))
    for i in range(2, nb + 1):
        log2[i] = log2[i // 2] + 1
    k = log2[bhi - blo + 1]
    base = (k * n + row) * nb
    flat = table.ravel()
    return np.maximum(flat.take(base + blo), flat.take(base + bhi + 1 - np.left_shift(1, k)))


def robots_into(
    ranges: np.ndarray,
    origins: np.ndarray,
    yaws: np.ndarray,
    rows: np.ndarray,
    centres: np.ndarray,
    dc: np.ndarray,
    ds: np.ndarray,
    radius: float,
    min_angle: float,
    resolution: float,
    max_range: float,
) -> np.ndarray:
    """Lower ``ranges`` (R, beams), float32 wall ranges of R lasers, where a beam hits a robot.

    ``origins`` (R, 2) and ``yaws`` (R,) are the lasers' poses, ``rows`` (R,) the robot index of
    each laser (a laser never sees its own robot), ``centres`` (N, 2) every robot's position,
    ``dc``/``ds`` (R, beams) the float32 cosines and sines of each beam's world angle. Returns
    the new float32 ranges (R, beams).
    """
    n_lasers, count = ranges.shape
    qx = centres[None, :, 0] - origins[:, 0, None]  # (R, N), float64
    qy = centres[None, :, 1] - origins[:, 1, None]
    qq = qx * qx + qy * qy
    c = qq - radius**2
    fx, fy = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    reach = max_range + radius
    cand = (c > 0.0) & (qq < reach * reach) & (qx * fx + qy * fy > -radius)
    cand[np.arange(n_lasers), rows] = False
    li, rj = np.nonzero(cand)
    if len(li) == 0:
        return ranges
    pqx, pqy, pc = qx[li, rj], qy[li, rj], c[li, rj]
    d = np.sqrt(qq[li, rj])
    bearing = np.arctan2(pqy, pqx) - yaws[li]
    bearing = (bearing + np.pi) % (2.0 * np.pi) - np.pi
    half = np.arcsin(np.minimum(radius / d, 1.0))
    lo = np.floor((bearing - half - min_angle) / resolution).astype(np.intp) - 1
    hi = np.ceil((bearing + half - min_angle) / resolution).astype(np.intp) + 1
    keep = np.flatnonzero((hi >= 0) & (lo <= count - 1))  # inside the field of view
    if len(keep) == 0:
        return ranges
    li, lo, hi = li[keep], np.maximum(lo[keep], 0), np.minimum(hi[keep], count - 1)
    pqx, pqy, pc, d = pqx[keep], pqy[keep], pc[keep], d[keep]
    # nearest first, in bands of distance: a band is culled against the ranges the nearer
    # bands left (walls and robots), so robots hidden behind robots cost little too
    acc = np.full(n_lasers * count, max_range, dtype=np.float64)
    edges = [0.0, *_BANDS, np.inf]
    for near, far in zip(edges[:-1], edges[1:], strict=True):
        band = np.flatnonzero((d >= near) & (d < far))
        if len(band) == 0:
            continue
        # the nearest point of the circle is d - r away: beyond every range over the interval,
        # the pair cannot shorten any beam
        wall_max = _range_bound(_block_max_table(ranges), li[band], lo[band], hi[band])
        band = band[d[band] - radius <= wall_max.astype(np.float64) + 1e-9]
        if len(band) == 0:
            continue
        _cast(acc, count, li[band], lo[band], hi[band], pqx[band], pqy[band], pc[band],
              dc, ds, max_range)
        ranges = np.minimum(ranges, acc.reshape(n_lasers, count)).astype(np.float32)
    return ranges


def _cast(acc, count, li, lo, hi, pqx, pqy, pc, dc, ds, max_range) -> None:
    """Intersect each pair's beams lo..hi with its circle; fold the hits into ``acc``."""
    counts = hi - lo + 1
    # element k of a pair is its beam lo + (k - the pair's first element); per-pair values
    # are repeated (cheaper than a gather), per-beam ones gathered
    flat = np.repeat(li * count + lo - (np.cumsum(counts) - counts), counts)
    flat += np.arange(len(flat))
    b = dc.ravel().take(flat) * np.repeat(pqx, counts)  # float64
    b += ds.ravel().take(flat) * np.repeat(pqy, counts)
    disc = b * b
    disc -= np.repeat(pc, counts)
    with np.errstate(invalid="ignore"):
        t = b - np.sqrt(disc)
    ok = disc >= 0
    ok &= t > 0
    t[~ok] = max_range
    np.minimum.at(acc, flat, t)


def walls(
    origins: np.ndarray,
    yaws: np.ndarray,
    segs: np.ndarray,
    bearings: np.ndarray,
    max_range: float,
    beams: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cast R lasers against the wall segments at once: (ranges, dc, ds), each (R, beams)
    float32 (dc, ds: cosines and sines of the beams' world angles, computed here unless given
    as ``beams``: ``float32(cos(bearings + yaw))`` and the sines, per laser).

    A segment is cast only for lasers that can see it (not wholly behind, within range: the
    culling of a one-laser cast) and only over the beams of its angular interval (one beam of
    margin; the exact intersection test decides). Each (segment, beam) element uses the float32
    arithmetic of a full ``segments x beams`` cast, so the ranges are the same.
    """
    n, count = len(yaws), len(bearings)
    if beams is None:
        ang = bearings[None, :] + yaws[:, None]
        dc = np.cos(ang).astype(np.float32)
        ds = np.sin(ang).astype(np.float32)
    else:
        dc, ds = beams
    ends, ex, ey, li, sj = _visible_segments(origins, yaws, segs, max_range)
    acc = np.full(n * count, max_range, dtype=np.float32)
    if len(li):
        li, sj, lo_i, hi_i = _segment_beams(ends, yaws, li, sj, bearings)
        _cast_segments(acc, count, li, sj, lo_i, hi_i, ends[0], ends[1], ex, ey, dc, ds,
                       max_range)
    return acc.reshape(n, count), dc, ds


def _visible_segments(origins: np.ndarray, yaws: np.ndarray, segs: np.ndarray,
                      max_range: float):
    """The culling of ``walls``: the segments' ends relative to each laser ``(ax, ay, bx, by)``
    (R, S) float64, the segments' vectors ``ex, ey`` (S,) and the (laser, segment) pairs
    ``li, sj`` whose segment is not wholly behind the laser and comes within range."""
    ox, oy = origins[:, 0:1], origins[:, 1:2]
    ax = segs[None, :, 0] - ox  # (R, S) float64
    ay = segs[None, :, 1] - oy
    bx = segs[None, :, 2] - ox
    by = segs[None, :, 3] - oy
    ex = segs[:, 2] - segs[:, 0]
    ey = segs[:, 3] - segs[:, 1]
    ee = ex * ex + ey * ey
    ee = np.where(ee > 0, ee, 1.0)
    fx, fy = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
    t = np.clip(-(ax * ex + ay * ey) / ee, 0.0, 1.0)
    nx = ax + t * ex
    ny = ay + t * ey
    keep = ((ax * fx + ay * fy >= 0) | (bx * fx + by * fy >= 0)) & (
        nx * nx + ny * ny < max_range * max_range
    )
    li, sj = np.nonzero(keep)
    return (ax, ay, bx, by), ex, ey, li, sj


def _segment_beams(ends, yaws: np.ndarray, li: np.ndarray, sj: np.ndarray,
                   bearings: np.ndarray):
    """The beams each (laser, segment) pair covers: its angular interval, one beam of margin on
    each side, clipped to the field of view; an interval passing behind the laser is split in
    two pairs. Returns ``li, sj, lo_i, hi_i`` of the pairs left (lo_i <= hi_i)."""
    ax, ay, bx, by = ends
    count = len(bearings)
    resolution = (bearings[-1] - bearings[0]) / (count - 1)
    yl = yaws[li]
    a0 = np.arctan2(ay[li, sj], ax[li, sj]) - yl
    a1 = np.arctan2(by[li, sj], bx[li, sj]) - yl
    a0 = (a0 + np.pi) % (2.0 * np.pi) - np.pi
    a1 = (a1 + np.pi) % (2.0 * np.pi) - np.pi
    amin, amax = np.minimum(a0, a1), np.maximum(a0, a1)
    wrap = amax - amin > np.pi  # the short way round passes behind the laser: two parts
    start = bearings[0]
    lo = np.where(wrap, amax, amin)
    hi = np.where(wrap, np.pi, amax)
    lo_i = np.floor((lo - start) / resolution).astype(np.intp) - 1
    hi_i = np.ceil((hi - start) / resolution).astype(np.intp) + 1
    w = np.flatnonzero(wrap)
    if len(w):
        lo_i = np.concatenate([lo_i, np.floor((-np.pi - start) / resolution).astype(np.intp)
                               - 1 + np.zeros(len(w), np.intp)])
        hi_i = np.concatenate([hi_i, np.ceil((amin[w] - start) / resolution).astype(np.intp)
                               + 1])
        li = np.concatenate([li, li[w]])
        sj = np.concatenate([sj, sj[w]])
    np.maximum(lo_i, 0, out=lo_i)
    np.minimum(hi_i, count - 1, out=hi_i)
    ok = np.flatnonzero(lo_i <= hi_i)
    return li[ok], sj[ok], lo_i[ok], hi_i[ok]


def _cast_segments(acc, count, li, sj, lo_i, hi_i, ax, ay, ex, ey, dc, ds, max_range) -> None:
    """Intersect each pair's beams lo_i..hi_i with its segment in float32; fold the hits into
    ``acc`` (the reduction: a minimum per beam)."""
    counts = hi_i - lo_i + 1
    # element k of pair p is beam lo_i[p] + (k - first element of p) of laser li[p]; the
    # per-pair values are repeated (cheaper than a gather), the per-beam ones gathered
    flat = np.repeat(li * count + lo_i - (np.cumsum(counts) - counts), counts)
    flat += np.arange(len(flat))
    f4 = np.float32
    qax, qay = ax[li, sj].astype(f4), ay[li, sj].astype(f4)
    qex, qey = ex.astype(f4)[sj], ey.astype(f4)[sj]
    num = qax * qey - qay * qex  # per pair: the same float32 value for all its beams
    pax, pay = np.repeat(qax, counts), np.repeat(qay, counts)
    pex, pey = np.repeat(qex, counts), np.repeat(qey, counts)
    bdc = dc.ravel().take(flat)
    bds = ds.ravel().take(flat)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = pey * bdc
        inv -= np.multiply(pex, bds, out=pey)
        np.divide(1.0, inv, out=inv)
        tr = np.repeat(num, counts)
        tr *= inv
        u = pax * bds
        u -= np.multiply(pay, bdc, out=pex)
        u *= inv
    bad = u < 0.0
    bad |= u > 1.0
    bad |= ~(tr > 0.0)
    tr[bad] = max_range
    np.minimum.at(acc, flat, tr)


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
    ``beams x robots`` work per laser. The reference :func:`robots_into` is tested and
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
