"""A scan's features straight from its bytes, compiled (numba): the controller's hot path
(:class:`client.behaviour.features.PayloadReader` calls it and says what it gives).

One call reads a scan's msgpack map when it is laid out exactly as ``Scan.encode`` writes it
(the fields in that order, every number a float64 but ``v`` and ``id``, ``ranges`` a bin of
float32s, ``pose`` and ``truth`` arrays of three floats) with every value finite, and takes the
tree's features from its ranges (each window's minimum, clamped, scaled). Anything else, valid
or not, is left to the reference decoder (``Scan.decode``), which accepts or names it: this is a
faster way to the same values, never a second definition of what a scan is.

Compiled ahead of time when the package is installed (``setup.py``: the extension module
``client.behaviour._payload_aot``, which needs no numba, from :func:`aot_exports`), else by
numba on first use and cached.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._payload_layout import (
    BEAMS,
    FIELDS,
    ID,
    MAX_ANGLE,
    MAX_BEAMS,
    MAX_RANGE,
    MIN_ANGLE,
    OFFSET,
    RESOLUTION,
    TEMPLATE,
    TRUTH,
    TS,
    VERSION,
    X,
)

__all__ = ["aot_exports", "disable_cache", "read_features"]


def _jit(func):
    """numba-compile ``func`` when first called, cached on disk (as the tree's kernels)."""
    try:
        return njit(cache=True, nogil=True)(func)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        return njit(nogil=True)(func)


@_jit
def _key(data, p, k):
    """The position after key number ``k`` of the template at ``data[p]``, or -1."""
    keys = TEMPLATE
    q = 0
    for _ in range(k):  # skip the keys before it
        q += 1 + (keys[q] & 0x1F)
    n = 1 + (keys[q] & 0x1F)
    if p + n > len(data):
        return -1
    for i in range(n):
        if data[p + i] != keys[q + i]:
            return -1
    return p + n


@_jit
def _be(data, p, n):
    """``n`` bytes at ``data[p]`` as a big-endian unsigned integer (n <= 7)."""
    v = 0
    for i in range(n):
        v = (v << 8) | np.int64(data[p + i])
    return v


@_jit
def _double(data, p, bits):
    """The msgpack float64 (0xcb) at ``data[p]`` into ``bits`` (a uint64 scratch whose float64
    view the caller reads); False when it is not one or not finite."""
    if p + 9 > len(data) or data[p] != 0xCB:
        return False
    v = np.uint64(0)
    for i in range(8):
        v = (v << np.uint64(8)) | np.uint64(data[p + 1 + i])
    if (v & np.uint64(0x7FF0000000000000)) == np.uint64(0x7FF0000000000000):
        return False  # infinity or NaN
    bits[0] = v
    return True


@_jit
def read_features(data, windows, clamp, scale, x, head, ints):
    """The beams of the scan ``data`` (its payload, bytes) when it is laid out as
    ``Scan.encode`` writes it with every value finite, else 0 (minus the beams when a window
    does not fit them: windows made for another beam count). On success ``x[k]`` is beam window
    ``windows[2k]:windows[2k + 1]``'s minimum (as a float64), clamped to ``clamp`` (a negative
    one taken as no reading: ``clamp``) and divided by ``scale``, for every window; ``head``
    holds ts, min_angle, max_angle, resolution, max_range, the pose and the truth, ``ints`` the
    id, the offset of the ranges in ``data``, the beam count and the map's field count (10: a
    truth). Little-endian machines only (the caller's)."""
    n = len(data)
    if n < 1 or (data[0] != 0x89 and data[0] != 0x8A):  # a fixmap of 9 fields, or 10 (truth)
        return 0
    fields = np.int64(data[0] & 0x0F)
    bits = np.empty(1, dtype=np.uint64)
    value = bits.view(np.float64)
    p = _key(data, 1, 0)
    if p < 0 or p >= n or np.int64(data[p]) != VERSION:  # v, a positive fixint
        return 0
    p += 1
    for k in range(1, 7):  # ts, id, min_angle, max_angle, resolution, max_range
        p = _key(data, p, k)
        if p < 0:
            return 0
        if k == 2:  # id: an unsigned integer, as msgpack packs it
            if p >= n:
                return 0
            tag = data[p]
            if tag < 0x80:
                ints[ID], p = np.int64(tag), p + 1
            elif tag == 0xCC or tag == 0xCD or tag == 0xCE:
                width = 1 << (tag - 0xCC)
                if p + 1 + width > n:
                    return 0
                ints[ID], p = _be(data, p + 1, width), p + 1 + width
            elif tag == 0xCF:  # uint64: below 2**63 only (else the reference decides)
                if p + 9 > n or data[p + 1] >= 0x80:
                    return 0
                ints[ID], p = (_be(data, p + 1, 4) << 32) | _be(data, p + 5, 4), p + 9
            else:
                return 0
            continue
        if not _double(data, p, bits):
            return 0
        head[(TS, TS, TS, MIN_ANGLE, MAX_ANGLE, RESOLUTION, MAX_RANGE)[k]] = value[0]
        p += 9
    p = _key(data, p, 7)  # ranges: a bin of little-endian float32s
    if p < 0 or p >= n:
        return 0
    tag = data[p]
    if tag == 0xC4 or tag == 0xC5 or tag == 0xC6:
        width = 1 << (tag - 0xC4)
        if p + 1 + width > n:
            return 0
        size, start = _be(data, p + 1, width), p + 1 + width
    else:
        return 0
    if size % 4 or size == 0 or size > 4 * MAX_BEAMS or start + size > n:
        return 0
    beams = size // 4
    p = start + size
    for k in range(8, 8 + fields - 8):  # pose, then truth when there is one
        p = _key(data, p, k)
        if p < 0 or p >= n or data[p] != 0x93:
            return 0
        p += 1
        for j in range(3):
            if not _double(data, p, bits):
                return 0
            head[(X if k == 8 else TRUTH) + j] = value[0]
            p += 9
    if p != n:  # more after the map: the reference refuses it
        return 0
    # every range finite (an exponent of all ones is infinity or NaN), read as float32 words
    words = np.empty(beams, dtype=np.uint32)
    for i in range(beams):
        q = start + 4 * i
        w = (np.uint32(data[q]) | (np.uint32(data[q + 1]) << np.uint32(8))
             | (np.uint32(data[q + 2]) << np.uint32(16)) | (np.uint32(data[q + 3]) << np.uint32(24)))
        if (w & np.uint32(0x7F800000)) == np.uint32(0x7F800000):
            return 0
        words[i] = w
    ranges = words.view(np.float32)
    for k in range(windows.shape[0] // 2):
        lo, hi = windows[2 * k], windows[2 * k + 1]
        if lo < 0 or hi > beams or lo >= hi:  # windows for another beam count
            return -beams
        m = ranges[lo]
        for i in range(lo + 1, hi):
            if ranges[i] < m:
                m = ranges[i]
        r = np.float64(m)
        x[k] = (r if r <= clamp else clamp) / scale if r >= 0.0 else clamp / scale
    ints[OFFSET], ints[BEAMS], ints[FIELDS] = start, beams, fields
    return beams


def disable_cache() -> None:
    """Compile in this process, without numba's cache (a cache folder that cannot hold it)."""
    for kernel in (_key, _be, _double, read_features):
        kernel._cache.disable()


def aot_exports() -> dict:
    """name -> (function, signature) of the kernel ``setup.py`` compiles ahead of time (the
    payload as a ``bytes`` object: no array made for it)."""
    from numba import types

    i64, f64 = types.int64[::1], types.float64[::1]
    payload = types.Bytes(types.uint8, 1, "C", readonly=True)
    return {"read_features": (read_features, types.int64(payload, i64, types.float64,
                                                         types.float64, f64, f64, i64))}
