"""The simulated laser: every laser of a tick cast against the walls and the other robots in
one compiled call (numba, compiled ahead of time where the package was built with a compiler).

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
+-pi inside it). The kernels (:mod:`server._laser_kernels`) are compiled ahead of time when the
package is installed (``setup.py``), else once per machine by numba (its cache, next to that file
or in numba's cache folder) and loaded from there by every later process.
"""

from __future__ import annotations

import functools
import importlib
import logging
import math
import os
from typing import Any

import numpy as np

from . import _laser_layout

log = logging.getLogger(__name__)

__all__ = ["Laser", "kernels_origin", "robots_dense"]

# set to "jit" to use numba's kernels even where kernels compiled ahead of time are installed
KERNELS_ENV = "RHBL_KERNELS"


@functools.cache
def _kernels() -> tuple[Any, str]:
    """The cast kernel of this process and where it comes from: ``"ahead-of-time"`` (the
    extension module ``server._laser_aot`` that setup.py compiles: no numba at run time) or
    ``"numba"`` (:mod:`server._laser_kernels`, compiled on first use or loaded from numba's
    cache), when the first ``Laser`` is made."""
    if os.environ.get(KERNELS_ENV, "") != "jit":
        try:
            aot = importlib.import_module("._laser_aot", __package__)
        except ImportError:
            aot = None
        if aot is not None and aot.source_hash() == _laser_layout.source_hash():
            return aot.cast, "ahead-of-time"
        if aot is not None:
            log.info("the laser's kernels compiled ahead of time are older than "
                     "server/_laser_kernels.py: using numba's (make install compiles them again)")
    return importlib.import_module("._laser_kernels", __package__).cast, "numba"


def kernels_origin() -> str:
    """Where this process's laser kernels come from (``"ahead-of-time"`` or ``"numba"``),
    loading them if no laser was made yet."""
    return _kernels()[1]


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
        # load the kernels now, not in the first tick (numba's: compiled by the first process
        # on a machine, about 2 s, or loaded from its cache)
        self._cast = _kernels()[0]
        try:
            self._warm_up()
        except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
            log.warning("cannot cache the laser's compiled code (%s): compiled in this process",
                        e)
            importlib.import_module("._laser_kernels", __package__).disable_cache()
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
        # the arrays as the kernel takes them (the ahead-of-time kernel checks no dtype)
        self._cast(out, np.ascontiguousarray(origins, dtype=np.float64),
                   np.ascontiguousarray(yaws, dtype=np.float64),
                   np.ascontiguousarray(rows, dtype=np.intp),
                   np.ascontiguousarray(centres, dtype=np.float64), self.segs, self.bearings,
                   self.kept, self.dc, self.ds, self.radius, self.start, self.resolution,
                   self.max_range)
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
