"""The simulated fiducial finder (Player's ``fiducial`` interface; Stage's fiducial finder is the
model): which beacons each robot sees, with their id, range and bearing.

:meth:`server.world.World.fiducials` calls :meth:`FiducialFinder.detect` once per tick for all
its robots. A beacon is seen by a sensor at ``o`` facing ``yaw`` when, with ``d`` = beacon
centre - ``o``, range ``|d|`` <= ``max_range``, bearing ``atan2(d) - yaw`` (wrapped to
(-pi, pi], counter-clockwise positive: a beacon on the robot's left has a positive bearing)
within ``+-fov/2``, and no wall segment crosses the line from ``o`` to the beacon's centre
before it (a micrometre's margin: a beacon centred on a wall is seen from both its sides; one
mounted on a wall has its centre off it, on the side it faces). Its id is reported when its range is below ``max_range_id``, else 0 (Stage's
"anonymous" fiducial); a range below ``min_range`` is reported as ``min_range``.

In numpy, every (robot, beacon) pair at once: the pairs within range and field of view are
tested against every wall in one (pairs x walls) intersection, as the laser's cast is
(``server.laser``): with ``w`` = wall start - ``o``, ``e`` = wall vector, ``v`` = ``d``,
``den = v x e``, the ray's position ``t = (w x e) / den`` and the wall's ``u = (w x v) / den``;
a wall hides the beacon when ``0 < t < 1 - 1e-6 / |d|`` and ``0 <= u <= 1`` (a wall parallel
to the line, ``den = 0``, hides nothing).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["FiducialFinder", "Seen"]


class Seen(NamedTuple):
    """What one sensor sees: parallel arrays of the beacons' ``ids`` (int64; 0: not
    identified), ``ranges`` (m) and ``bearings`` (rad, robot frame, counter-clockwise), and
    ``index`` the beacons' places in the world's list (to draw the seen ones)."""

    ids: np.ndarray
    ranges: np.ndarray
    bearings: np.ndarray
    index: np.ndarray


_MARGIN = 1e-6  # m before the centre: a wall through the centre itself hides nothing
_NONE = Seen(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0, np.intp))


class FiducialFinder:
    """The fiducial finders of a world's robots: ``segments`` (S, 4) walls, ``beacons`` (with
    ``id`` and ``pos``), ``spec`` the sensor (``server.world.FiducialSpec``)."""

    def __init__(self, segments: np.ndarray, beacons: Sequence, spec) -> None:
        self.spec = spec
        self.ids = np.asarray([b.id for b in beacons], dtype=np.int64)
        self.pos = np.asarray([b.pos for b in beacons], dtype=np.float64).reshape(-1, 2)
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        self._a = segs[:, 0:2]
        self._e = segs[:, 2:4] - segs[:, 0:2]

    def detect(self, poses: np.ndarray) -> list[Seen]:
        """What the sensors of robots at true ``poses`` (N, 3: x, y, yaw) see, one
        :class:`Seen` per robot, the beacons in the world's order."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        n = len(poses)
        if n == 0 or len(self.ids) == 0:
            return [_NONE] * n
        spec = self.spec
        yaw = poses[:, 2]
        o = poses[:, :2] + spec.offset * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
        d = self.pos[None, :, :] - o[:, None, :]  # (N, B, 2)
        rng = np.hypot(d[..., 0], d[..., 1])
        bearing = np.arctan2(d[..., 1], d[..., 0]) - yaw[:, None]
        bearing = np.mod(bearing + math.pi, 2.0 * math.pi) - math.pi  # [-pi, pi)
        bearing[bearing == -math.pi] = math.pi  # (-pi, pi], as every angle of the protocol
        seen = (rng <= spec.max_range) & (np.abs(bearing) <= spec.fov / 2.0)
        robot, beacon = np.nonzero(seen)
        if len(robot) and len(self._a):
            seen[robot, beacon] = ~self._hidden(o[robot], d[robot, beacon], rng[robot, beacon])
        out = []
        for k in range(n):
            (idx,) = np.nonzero(seen[k])
            if not len(idx):
                out.append(_NONE)
                continue
            r = rng[k, idx]
            ids = np.where(r < spec.max_range_id, self.ids[idx], 0)
            out.append(Seen(ids, np.maximum(r, spec.min_range), bearing[k, idx], idx))
        return out

    def _hidden(self, o: np.ndarray, v: np.ndarray, rng: np.ndarray) -> np.ndarray:
        """For each of K lines from ``o`` (K, 2) along ``v`` (K, 2) to a beacon's centre
        ``rng`` (K) away, whether a wall crosses it before the centre."""
        a, e = self._a, self._e
        wx = a[None, :, 0] - o[:, 0:1]  # (K, S)
        wy = a[None, :, 1] - o[:, 1:2]
        vx, vy = v[:, 0:1], v[:, 1:2]
        den = vx * e[None, :, 1] - vy * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (wx * e[None, :, 1] - wy * e[None, :, 0]) / den
            u = (wx * vy - wy * vx) / den
        limit = 1.0 - _MARGIN / np.where(rng > _MARGIN, rng, 1.0)
        hit = (den != 0.0) & (t > 0.0) & (t < limit[:, None]) & (u >= 0.0) & (u <= 1.0)
        return hit.any(axis=1)
