"""The simulated fiducial finder (Player's ``fiducial`` interface; Stage's fiducial finder is the
model): which beacons each robot sees, with their id, range and bearing.

:meth:`server.world.World.fiducials` calls :meth:`FiducialFinder.detect` once per tick for all
its robots. A beacon is seen by a sensor at ``o`` facing ``yaw`` when, with ``d`` = beacon
centre - ``o``, range ``|d|`` <= ``max_range``, bearing ``atan2(d) - yaw`` (in
(-pi, pi], counter-clockwise positive: a beacon on the robot's left has a positive bearing)
within ``+-fov/2``, and no wall segment crosses the line from ``o`` to the beacon's centre
before it (a micrometre's margin: a beacon centred on a wall is seen from both its sides; one
mounted on a wall has its centre off it, on the side it faces). Its id is reported when its
range is below ``max_range_id``, else 0 (Stage's "anonymous" fiducial); a range below
``min_range`` is reported as ``min_range``.

In numpy, every (robot, beacon) pair at once: the pairs within range and field of view (the
others cost nothing more) are tested against the walls whose bounding box meets the line's
(the others cannot cross it), all in one intersection, as the laser's cast is
(``server.laser``): with ``w`` = wall start - ``o``, ``e`` = wall vector, ``v`` = ``d``,
``den = v x e``, the ray's position ``t = (w x e) / den`` and the wall's ``u = (w x v) / den``;
a wall hides the beacon when ``0 < t < 1 - 1e-6 / |d|`` and ``0 <= u <= 1`` (a wall parallel
to the line, ``den = 0``, hides nothing), tested as ``t * den`` and ``u * den`` against ``den``
(no division). The bearing is ``arctan2`` of the beacon in the sensor's frame, in (-pi, pi]
without wrapping; the results go out as Python numbers (what the messages are made of). A small problem (one
robot of a room: robots x beacons x walls up to ``FiducialFinder.SMALL``) is computed by the
same tests in a plain Python loop, cheaper there than numpy's fixed cost of a call; the tests
hold both to a plain reference.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["FiducialFinder", "Seen"]


class Seen(NamedTuple):
    """What one sensor sees: the beacons' ``ids`` (0: not identified), ``ranges`` (m) and
    ``bearings`` (rad, robot frame, counter-clockwise), and ``index`` their places in the
    world's list (to draw the seen ones), parallel tuples of Python numbers."""

    ids: tuple[int, ...]
    ranges: tuple[float, ...]
    bearings: tuple[float, ...]
    index: tuple[int, ...]


_MARGIN = 1e-6  # m before the centre: a wall through the centre itself hides nothing
_NONE = Seen((), (), (), ())


class FiducialFinder:
    """The fiducial finders of a world's robots: ``segments`` (S, 4) walls, ``beacons`` (with
    ``id`` and ``pos``), ``spec`` the sensor (``server.world.FiducialSpec``)."""

    # robots x beacons x walls up to which a plain Python loop is used (fewer numpy calls than
    # its fixed cost: one robot of a room, benchmarks/bench_fiducial.py)
    SMALL = 2048

    def __init__(self, segments: np.ndarray, beacons: Sequence, spec,
                 small: int | None = None) -> None:
        self.spec = spec
        self.small = self.SMALL if small is None else int(small)
        self._beacons = [(int(b.id), float(b.pos[0]), float(b.pos[1])) for b in beacons]
        # each wall as its start, vector and bounding box, for the loop
        self._walls = [(x0, y0, x1 - x0, y1 - y0, min(x0, x1), max(x0, x1), min(y0, y1),
                        max(y0, y1)) for x0, y0, x1, y1
                       in np.asarray(segments, dtype=np.float64).reshape(-1, 4).tolist()]
        self.ids = np.asarray([b.id for b in beacons], dtype=np.int64)
        self.pos = np.asarray([b.pos for b in beacons], dtype=np.float64).reshape(-1, 2)
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        self._ax, self._ay = segs[:, 0].copy(), segs[:, 1].copy()
        self._ex, self._ey = segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1]
        self._lo_x = np.minimum(segs[:, 0], segs[:, 2])
        self._hi_x = np.maximum(segs[:, 0], segs[:, 2])
        self._lo_y = np.minimum(segs[:, 1], segs[:, 3])
        self._hi_y = np.maximum(segs[:, 1], segs[:, 3])

    def detect(self, poses: np.ndarray) -> list[Seen]:
        """What the sensors of robots at true ``poses`` (N, 3: x, y, yaw) see, one
        :class:`Seen` per robot, the beacons in the world's order."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        n = len(poses)
        if n == 0 or len(self.ids) == 0:
            return [_NONE] * n
        if n * len(self.ids) * max(1, len(self._walls)) <= self.small:
            return [self._detect_one(*p) for p in poses.tolist()]
        spec = self.spec
        c, s = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])  # (N, 1)
        ox = poses[:, 0:1] + spec.offset * c
        oy = poses[:, 1:2] + spec.offset * s
        dx, dy = self.pos[:, 0] - ox, self.pos[:, 1] - oy  # (N, B): sensor -> beacon centre
        rng = np.hypot(dx, dy)
        # the bearing in the sensor's frame, (-pi, pi] as arctan2 gives it (no wrapping)
        bearing = np.arctan2(dy * c - dx * s, dx * c + dy * s)
        seen = (rng <= spec.max_range) & (np.abs(bearing) <= spec.fov / 2.0)
        robot, beacon = np.nonzero(seen)  # only these pairs meet the walls
        if len(robot) and len(self._ax):
            seen[robot, beacon] = ~self._hidden(ox[robot, 0], oy[robot, 0], dx[robot, beacon],
                                                dy[robot, beacon], rng[robot, beacon])
        robot, beacon = np.nonzero(seen)  # row-major: robot by robot, beacons in order
        r = rng[robot, beacon]
        ids = self.ids[beacon]
        ids[r >= spec.max_range_id] = 0
        found = zip(robot.tolist(), ids.tolist(), np.maximum(r, spec.min_range).tolist(),
                    bearing[robot, beacon].tolist(), beacon.tolist(), strict=True)
        per: list[list] = [[] for _ in range(n)]
        for k, *item in found:
            per[k].append(item)
        return [Seen(*map(tuple, zip(*items, strict=True))) if items else _NONE
                for items in per]

    def _detect_one(self, x: float, y: float, yaw: float) -> Seen:
        """What one sensor sees, in plain Python: the same tests, one pair and wall at a time
        (a wall outside the line's bounding box skipped)."""
        spec = self.spec
        c, s = math.cos(yaw), math.sin(yaw)
        ox, oy = x + spec.offset * c, y + spec.offset * s
        half_fov, items = spec.fov / 2.0, []
        for j, (bid, px, py) in enumerate(self._beacons):
            dx, dy = px - ox, py - oy
            r = math.hypot(dx, dy)
            a = math.atan2(dy * c - dx * s, dx * c + dy * s)
            if r > spec.max_range or abs(a) > half_fov:
                continue
            lo_x, hi_x = (ox, px) if ox < px else (px, ox)
            lo_y, hi_y = (oy, py) if oy < py else (py, oy)
            limit = 1.0 - _MARGIN / max(r, _MARGIN)
            for ax, ay, ex, ey, wlo_x, whi_x, wlo_y, whi_y in self._walls:
                if wlo_x > hi_x or whi_x < lo_x or wlo_y > hi_y or whi_y < lo_y:
                    continue
                den = dx * ey - dy * ex
                if den == 0.0:
                    continue
                wx, wy = ax - ox, ay - oy
                t, u = (wx * ey - wy * ex) / den, (wx * dy - wy * dx) / den
                if 0.0 < t < limit and 0.0 <= u <= 1.0:
                    break  # hidden
            else:
                items.append((bid if r < spec.max_range_id else 0, max(r, spec.min_range), a, j))
        return Seen(*map(tuple, zip(*items, strict=True))) if items else _NONE

    def _hidden(self, ox, oy, dx, dy, rng) -> np.ndarray:
        """For each of K lines from a sensor at ``ox, oy`` along ``dx, dy`` to a beacon's centre
        ``rng`` away (all (K,)), whether a wall crosses it before the centre. Only the walls
        whose bounding box meets the line's are tested (the others cannot cross it), by the
        ``t``, ``u`` test without a division (as ``t * |den|``, ``u * |den|``)."""
        bx, by = ox + dx, oy + dy
        lo_x, hi_x = np.minimum(ox, bx)[:, None], np.maximum(ox, bx)[:, None]
        lo_y, hi_y = np.minimum(oy, by)[:, None], np.maximum(oy, by)[:, None]
        near = ((self._lo_x <= hi_x) & (self._hi_x >= lo_x) & (self._lo_y <= hi_y)
                & (self._hi_y >= lo_y))  # (K, S)
        line, wall = np.nonzero(near)
        hidden = np.zeros(len(ox), dtype=bool)
        if not len(line):
            return hidden
        wx, wy = self._ax[wall] - ox[line], self._ay[wall] - oy[line]
        vx, vy, ex, ey = dx[line], dy[line], self._ex[wall], self._ey[wall]
        den = vx * ey - vy * ex
        sign = np.sign(den)
        tn = (wx * ey - wy * ex) * sign  # t * |den|
        un = (wx * vy - wy * vx) * sign  # u * |den|
        den *= sign  # |den|; 0: parallel, and then tn = 0 is no hit
        limit = 1.0 - _MARGIN / np.maximum(rng[line], _MARGIN)
        hit = (tn > 0.0) & (tn < limit * den) & (un >= 0.0) & (un <= den)
        hidden[line[hit]] = True
        return hidden
