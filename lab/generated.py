"""Randomised teaching worlds (domain randomisation): rooms, tiered mazes, cluttered rooms, rooms
with beacons, winding corridors, dead ends and rooms joined by doorways drawn at random from a
seed, for corrective rounds and practice in worlds nobody drew, so that what a tree is taught
does not hang on the few shapes of its teaching worlds.

    spec = generate("rooms", rng, side="right")   # a server.world.WorldSpec, in memory
    specs = generated("rooms", 4, seed)           # a training run's: the same for the same seed
    rhbl generate rooms --count 8 --seed 1000 --out my-worlds/   # as world files, to evaluate on

A behaviour asks for them in its file (``[recipe] round_generated = 6`` and ``generator =
"rooms"``); ``lab.train`` runs its corrective rounds in each, from the world's own start poses,
after its other teaching worlds. The kinds, each a family of shapes with the sizes drawn
uniformly from the ranges below (no range was chosen on a held-out world):

* ``rooms``: a rectangle of 8-14 x 6-10 m whose sides carry up to two features each, an alcove
  (1.2-2.2 m wide, 0.6-2.0 m deep), a protrusion (0.8-2.0 m wide, 0.3-1.2 m deep) or a
  sawtooth, and whose corners may be cut diagonally (0.5-1.5 m); one room in two has an
  island, leaving a corridor of 1.4-2.6 m round it. Start poses 0.7 m from a wall, the wall on
  the side the behaviour follows.
* ``mazes``: 3-5 tiers of 1.7-2.6 m by 7-11 m, openings of 1.0-1.5 m at alternating ends, the
  first at either end; the goal at the far end of the last tier.
* ``clutter``: a room of 8-13 x 6-10 m with 3-6 boxes (0.4-2.4 m sides, some turned) and 2-4
  pillars (0.3-0.6 m), at least 1.2 m from each other and from the walls.
* ``beacons``: a room of 9-14 x 6-9 m with 1-3 partitions (0.4 m thick, 35-60% of the room's
  depth, from the top or the bottom wall, 2.5 m apart), up to two blocks (0.6-1.4 m sides)
  against a side wall or in the open, and the beacons 1, 2 and 3 (red, green, blue) at least
  0.9 m from every wall and 3 m from each other: for behaviours with goals (docs/goals.md).
* ``corridors``: a winding corridor in a loop, its centre line an ellipse of 4.5-7.5 x 3-5 m
  bulging and dipping with one or two waves (2-4 periods round it, 4-18% of its radius; drawn
  again where a bend is too tight for the width), 1.0-2.4 m wide (two widths drawn, the width
  changing smoothly between them along it: the teaching world's 1.2-2.0 m, widened).
* ``dead-ends``: a square hall of 3.5-5.5 m with two to four blind corridors off the middles
  of its walls, 1.0-2.2 m wide and 3-5.5 m long; the start poses in them facing their ends; the
  goal the middle of the hall.
* ``doorways``: three to five rooms of 3.2-4.8 m in a row 3.8-5.5 m deep, joined by doorways
  of 1.2-1.8 m at the top, the middle or the bottom of each wall; the start poses in the first
  room within 1.2 m of a wall; the goal by the far wall of the last.

The ranges of the last three widen those of their behaviour's teaching world; the scripted
experts succeed from most, not all, of their start poses (a practice episode the expert fails
is left out; ``rhbl refine`` says so).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from process import arguments, files
from server.world import WorldSpec, parse_world

__all__ = ["KINDS", "add_arguments", "draw", "generate", "generated", "main", "to_toml"]

KINDS = ("rooms", "mazes", "clutter", "beacons", "corridors", "dead-ends", "doorways")
CLEAR = 0.7  # m from a wall to a start pose


def _u(rng, lo, hi) -> float:
    return float(rng.uniform(lo, hi))


def _side_features(rng, length: float, inward_room: float) -> list[tuple[float, float, str, float]]:
    """Features along one side: (start, width, kind, depth), sorted, 1.2 m from its ends and
    1.5 m from each other."""
    out: list[tuple[float, float, str, float]] = []
    for _ in range(int(rng.integers(0, 3))):
        kind = str(rng.choice(["alcove", "protrusion", "teeth"]))
        if kind == "alcove":
            w, d = _u(rng, 1.2, 2.2), _u(rng, 0.6, 2.0)
        elif kind == "protrusion":
            w, d = _u(rng, 0.8, 2.0), min(_u(rng, 0.3, 1.2), inward_room)
        else:
            w, d = 2.0 * int(rng.integers(1, 3)) * _u(rng, 0.4, 0.6), _u(rng, 0.3, 0.6)
        lo, hi = 1.2, length - 1.2 - w
        if hi <= lo:
            continue
        s = _u(rng, lo, hi)
        if all(s + w + 1.5 <= a or a + b + 1.5 <= s for a, b, _, _ in out):
            out.append((s, w, kind, d))
    return sorted(out)


def _room(rng, side: str) -> dict:
    w, h = _u(rng, 8.0, 14.0), _u(rng, 6.0, 10.0)
    island = rng.random() < 0.5
    gap = _u(rng, 1.4, 2.6)
    inward = (gap - 1.0) if island else min(w, h) / 4
    corners = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
    cuts = [(_u(rng, 0.5, 1.5) if rng.random() < 0.4 else 0.0) for _ in corners]
    pts: list[tuple[float, float]] = []
    starts = []
    for k in range(4):  # counter-clockwise: the wall is on a robot's right going this way
        a, b = np.array(corners[k]), np.array(corners[(k + 1) % 4])
        length = float(np.linalg.norm(b - a))
        d = (b - a) / length
        n = np.array([-d[1], d[0]])  # inward
        c0, c1 = cuts[k], cuts[(k + 1) % 4]
        pts.append(tuple(a + d * c0))
        feats = [f for f in _side_features(rng, length, inward) if f[0] > c0 + 0.3
                 and f[0] + f[1] < length - c1 - 0.3]
        for s, fw, kind, depth in feats:
            if kind == "teeth":
                teeth = max(1, round(fw / (2 * 0.5)))
                step = fw / (2 * teeth)
                for t in range(2 * teeth + 1):
                    off = depth if t % 2 else 0.0
                    pts.append(tuple(a + d * (s + t * step) + n * off))
                continue
            sign = -1.0 if kind == "alcove" else 1.0
            pts += [tuple(a + d * s), tuple(a + d * s + n * sign * depth),
                    tuple(a + d * (s + fw) + n * sign * depth), tuple(a + d * (s + fw))]
        # a start on the longest stretch of this side free of features, 0.7 m off the wall
        edges = [c0 + 0.3] + [x for s, fw, _, _ in feats for x in (s, s + fw)] + [length - c1 - 0.3]
        spans = [(edges[i], edges[i + 1]) for i in range(0, len(edges), 2)]
        lo, hi = max(spans, key=lambda p: p[1] - p[0])
        if hi - lo >= 1.0:
            p = a + d * (lo + 0.5 * (hi - lo)) + n * CLEAR
            yaw = math.atan2(d[1], d[0]) if side == "right" else math.atan2(-d[1], -d[0])
            starts.append([round(float(p[0]), 3), round(float(p[1]), 3), round(yaw, 4)])
        if c1 > 0:
            pts.append(tuple(b - d * c1))
    walls = [{"closed": True, "points": [[round(x, 3), round(y, 3)] for x, y in _dedup(pts)]}]
    if island:
        x0, y0, x1, y1 = gap, gap, w - gap, h - gap
        if x1 - x0 >= 1.0 and y1 - y0 >= 1.0:
            walls.append({"closed": True, "points": [[round(x, 3), round(y, 3)] for x, y in
                                                     ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]})
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls}


def _dedup(pts):
    out = []
    for p in pts:
        if not out or math.dist(out[-1], p) > 1e-6:
            out.append(p)
    if len(out) > 1 and math.dist(out[0], out[-1]) <= 1e-6:
        out.pop()
    return out


def _maze(rng, side: str) -> dict:
    tiers = int(rng.integers(3, 6))
    th, w, gap = _u(rng, 1.7, 2.6), _u(rng, 7.0, 11.0), _u(rng, 1.0, 1.5)
    first_right = bool(rng.random() < 0.5)
    walls = [{"closed": True, "points": [[0, 0], [round(w, 3), 0], [round(w, 3), round(tiers * th, 3)],
                                         [0, round(tiers * th, 3)]]}]
    for k in range(1, tiers):
        right = first_right if k % 2 == 1 else not first_right
        y = round(k * th, 3)
        walls.append({"points": [[0, y], [round(w - gap, 3), y]] if right
                      else [[round(gap, 3), y], [round(w, 3), y]]})
    last_right = first_right if (tiers - 1) % 2 == 1 else not first_right  # last opening's end
    # the last tier is entered at that end: the goal at the other
    gx = 1.0 if last_right else w - 1.0
    y0 = th / 2
    starts = [[1.5, round(y0 - 0.3, 3), 0.0], [1.5, round(y0 + 0.3, 3), 0.0],
              [2.5, round(y0, 3), 0.3], [2.5, round(y0, 3), -0.3]]
    return {"robot": {"pose": [1.0, round(y0, 3), 0.0], "starts": starts}, "walls": walls,
            "goal": {"center": [round(gx, 3), round((tiers - 0.5) * th, 3)], "radius": 0.75}}


def _clutter(rng, side: str) -> dict:
    w, h = _u(rng, 8.0, 13.0), _u(rng, 6.0, 10.0)
    walls = [{"closed": True, "points": [[0, 0], [round(w, 3), 0], [round(w, 3), round(h, 3)],
                                         [0, round(h, 3)]]}]
    shapes: list[tuple[float, float, float]] = []  # centre and radius of what is placed
    want = int(rng.integers(3, 7)) + int(rng.integers(2, 5))
    for _ in range(200):
        if len(shapes) >= want:
            break
        pillar = len(shapes) >= want - 2
        if pillar:
            r = _u(rng, 0.15, 0.3)
            a = b = r
        else:
            a, b = _u(rng, 0.2, 1.2), _u(rng, 0.2, 1.2)
            r = math.hypot(a, b)
        cx, cy = _u(rng, 1.2 + r, w - 1.2 - r), _u(rng, 1.2 + r, h - 1.2 - r)
        if any(math.hypot(cx - x, cy - y) < r + q + 1.2 for x, y, q in shapes):
            continue
        shapes.append((cx, cy, r))
        if pillar:
            pts = [[cx + r * math.cos(t * math.tau / 8), cy + r * math.sin(t * math.tau / 8)]
                   for t in range(8)]
        else:
            t = _u(rng, 0, math.pi) if rng.random() < 0.3 else 0.0
            c, s = math.cos(t), math.sin(t)
            pts = [[cx + c * x - s * y, cy + s * x + c * y]
                   for x, y in ((-a, -b), (a, -b), (a, b), (-a, b))]
        walls.append({"closed": True, "points": [[round(x, 3), round(y, 3)] for x, y in pts]})
    starts = []
    for _ in range(400):
        if len(starts) >= 5:
            break
        x, y = _u(rng, 0.8, w - 0.8), _u(rng, 0.8, h - 0.8)
        if all(math.hypot(x - sx, y - sy) > q + 0.8 for sx, sy, q in shapes):
            starts.append([round(x, 3), round(y, 3), round(_u(rng, -math.pi, math.pi), 4)])
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls}


def _to_rect(x: float, y: float, rect: tuple[float, float, float, float]) -> float:
    """Distance from (x, y) to the rectangle (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = rect
    return math.hypot(max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1))


def _to_segments(points: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """The distance from each of ``points`` (N, 2) to the nearest of ``segs`` (S, 4)."""
    a, b = segs[None, :, :2], segs[None, :, 2:]
    ab, ap = b - a, points[:, None, :] - a
    t = np.clip(np.sum(ap * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-12), 0.0, 1.0)
    return np.min(np.linalg.norm(ap - t[..., None] * ab, axis=2), axis=1)


def _clearance(x: float, y: float, rects: list[tuple[float, float, float, float]], w: float,
               h: float) -> float:
    """Distance from (x, y) to the nearest of the room's walls and the rectangles standing in
    it."""
    return min([x, y, w - x, h - y] + [_to_rect(x, y, r) for r in rects])


def _beacons(rng, side: str) -> dict:
    """A room with partitions from its walls, blocks on them and boxes in the open, and the
    beacons 1, 2 and 3 standing on the floor (the goals' worlds: docs/goals.md)."""
    w, h = _u(rng, 9.0, 14.0), _u(rng, 6.0, 9.0)
    rects: list[tuple[float, float, float, float]] = []
    xs: list[float] = []
    for _ in range(int(rng.integers(1, 4))):  # partitions from the top or the bottom wall
        x = _u(rng, 2.5, w - 2.5)
        if any(abs(x - q) < 2.5 for q in xs):
            continue
        xs.append(x)
        length = _u(rng, 0.35, 0.6) * h
        rects.append((x - 0.2, h - length, x + 0.2, h) if rng.random() < 0.5
                     else (x - 0.2, 0.0, x + 0.2, length))
    for _ in range(int(rng.integers(0, 3))):  # blocks on the walls, boxes in the open
        a, b = _u(rng, 0.3, 0.7), _u(rng, 0.3, 0.7)
        cx, cy = _u(rng, a, w - a), _u(rng, b, h - b)
        if rng.random() < 0.5:  # against the nearest side wall
            cx = a if cx < w / 2 else w - a
        if all(_to_rect(cx, cy, r) > max(a, b) + 1.3 for r in rects):
            rects.append((cx - a, cy - b, cx + a, cy + b))

    def spots(count: int, clear: float, apart: float) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for _ in range(600):
            if len(out) >= count:
                break
            x, y = _u(rng, clear, w - clear), _u(rng, clear, h - clear)
            if (_clearance(x, y, rects, w, h) >= clear
                    and all(math.hypot(x - p, y - q) >= apart for p, q in out)):
                out.append((x, y))
        return out

    beacons = spots(3, 0.9, 3.0)
    if len(beacons) < 3:
        raise ValueError("no room for three beacons 3 m apart")
    starts = [[round(x, 3), round(y, 3), round(_u(rng, -math.pi, math.pi), 4)]
              for x, y in spots(5, 0.8, 1.0)
              if all(math.hypot(x - p, y - q) > 1.2 for p, q in beacons)]
    walls = [{"closed": True, "points": [[0, 0], [round(w, 3), 0], [round(w, 3), round(h, 3)],
                                         [0, round(h, 3)]]}]
    walls += [{"closed": True, "points": [[round(x, 3), round(y, 3)] for x, y in
                                          ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]}
              for x0, y0, x1, y1 in rects]
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls,
            "beacons": [{"id": i + 1, "pos": [round(x, 3), round(y, 3)],
                         "colour": ("red", "green", "blue")[i], "size": 0.3}
                        for i, (x, y) in enumerate(beacons)]}


def _corridor(rng, side: str) -> dict:
    """A winding corridor in a loop: its centre line an ellipse of 4.5-7.5 x 3-5 m whose radius
    bulges and dips with one or two waves (2-4 periods round it), its width between two values
    drawn from 1.0-2.4 m, changing smoothly along it. Start poses on the centre line or up to
    0.2 of the width off it (0.5 m from the walls at least), heading along it either way."""
    a, b = _u(rng, 4.5, 7.5), _u(rng, 3.0, 5.0)
    waves = [(int(k), _u(rng, 0.04, 0.18), _u(rng, 0.0, math.tau))
             for k in rng.choice([2, 3, 4], size=int(rng.integers(1, 3)), replace=False)]
    w0 = _u(rng, 1.0, 1.8)
    w1 = _u(rng, w0, min(w0 + 0.8, 2.4))
    m, psi = int(rng.integers(1, 4)), _u(rng, 0.0, math.tau)
    t = np.linspace(0.0, math.tau, 96, endpoint=False)
    r = 1.0 + sum(e * np.cos(k * t + f) for k, e, f in waves)
    c = np.stack([a * r * np.cos(t), b * r * np.sin(t)], axis=1)
    d1 = (np.roll(c, -1, axis=0) - np.roll(c, 1, axis=0)) / 2  # the tangent, counter-clockwise
    d = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    out = np.stack([d[:, 1], -d[:, 0]], axis=1)  # the outward normal
    width = w0 + (w1 - w0) * 0.5 * (1.0 + np.sin(m * t + psi))
    outer, inner = c + out * (width / 2)[:, None], c - out * (width / 2)[:, None]
    d2 = np.roll(c, -1, axis=0) - 2 * c + np.roll(c, 1, axis=0)  # the centre line's curvature
    bend = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    if np.any(bend * (width / 2 + 0.4) > 1.0):  # the wall inside a bend: a radius under 0.4 m
        raise ValueError("a bend tighter than the corridor's width")
    segs = np.concatenate([np.concatenate([p, np.roll(p, -1, axis=0)], axis=1)
                           for p in (outer, inner)])
    if np.any(_to_segments(c, segs) < 0.95 * width / 2):  # the walls come close elsewhere
        raise ValueError("the corridor's walls come closer than its width")
    lo = np.minimum(outer.min(axis=0), inner.min(axis=0)) - 0.5
    outer, inner, c = outer - lo, inner - lo, c - lo
    walls = [{"closed": True, "points": [[round(float(x), 3), round(float(y), 3)] for x, y in p]}
             for p in (outer, inner)]
    starts = []
    for i in rng.choice(len(t), size=5, replace=False):
        off = (_u(rng, -1.0, 1.0) * max(0.0, min(0.2 * width[i], width[i] / 2 - 0.5))
               if rng.random() < 0.5 else 0.0)
        p = c[i] + out[i] * off
        yaw = math.atan2(d[i, 1], d[i, 0]) + (math.pi if rng.random() < 0.5 else 0.0)
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        starts.append([round(float(p[0]), 3), round(float(p[1]), 3), round(yaw, 4)])
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls}


def _dead_end(rng, side: str) -> dict:
    """A square hall of 3.5-5.5 m with two to four blind corridors, each off the middle of its
    own wall, 1.0-2.2 m wide and 3-5.5 m long; every start pose inside a corridor facing its
    blind end (1.5 m from it or more, a little off its line and slanted); the goal the middle of
    the hall, straight out of every corridor's mouth."""
    hall = _u(rng, 3.5, 5.5)
    half = hall / 2
    sides = sorted(int(k) for k in rng.choice(4, size=int(rng.integers(2, 5)), replace=False))
    pts: list[tuple[float, float]] = []
    starts = []
    for k in range(4):  # the hall's walls counter-clockwise from the bottom; (x, y) about its middle
        ang = -math.pi / 2 + k * math.pi / 2  # the direction out through this wall
        u, v = np.array([math.cos(ang), math.sin(ang)]), np.array([-math.sin(ang), math.cos(ang)])
        corner = u * half - v * half
        pts.append(tuple(corner))
        if k in sides:
            w, length = _u(rng, 1.0, min(2.2, hall - 1.0)), _u(rng, 3.0, 5.5)
            pts += [tuple(u * half - v * w / 2), tuple(u * (half + length) - v * w / 2),
                    tuple(u * (half + length) + v * w / 2), tuple(u * half + v * w / 2)]
            for _ in range(2):
                ahead = _u(rng, 1.5, length - 0.3)  # from the blind end
                lateral = _u(rng, -1.0, 1.0) * min(0.15, w / 2 - 0.5)
                p = u * (half + length - ahead) + v * lateral
                yaw = ang + _u(rng, -1.0, 1.0) * min(0.25, 0.2 * w)
                yaw = math.atan2(math.sin(yaw), math.cos(yaw))
                starts.append([round(float(p[0]) + 10.0, 3), round(float(p[1]) + 10.0, 3),
                               round(yaw, 4)])
    walls = [{"closed": True, "points": [[round(x + 10.0, 3), round(y + 10.0, 3)]
                                         for x, y in _dedup(pts)]}]
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls,
            "goal": {"center": [10.0, 10.0], "radius": 0.75}}


def _doorways(rng, side: str) -> dict:
    """Three to five rooms in a row, each 3.2-4.8 m long, the row 3.8-5.5 m deep, joined by
    doorways of 1.2-1.8 m at the top, the middle or the bottom of each wall between them; every
    wall joined to the outer one, so that keeping the wall on the robot's right leads through
    every doorway in turn. Start poses in the first room within 1.2 m of a wall, facing every
    way; the goal 0.7 m from the far wall of the last room."""
    rooms, h = int(rng.integers(3, 6)), _u(rng, 3.8, 5.5)
    xs = np.cumsum([_u(rng, 3.2, 4.8) for _ in range(rooms)])
    length = float(xs[-1])
    walls = [{"closed": True, "points": [[0, 0], [round(length, 3), 0],
                                         [round(length, 3), round(h, 3)], [0, round(h, 3)]]}]
    for x in xs[:-1]:
        gap = _u(rng, 1.2, 1.8)
        where = str(rng.choice(["top", "middle", "bottom"]))
        y0 = {"bottom": 0.0, "middle": (h - gap) / 2, "top": h - gap}[where]
        x = round(float(x), 3)
        if y0 > 0:
            walls.append({"points": [[x, 0], [x, round(y0, 3)]]})
        if y0 + gap < h:
            walls.append({"points": [[x, round(y0 + gap, 3)], [x, round(h, 3)]]})
    first = float(xs[0])
    starts = []
    for _ in range(400):
        if len(starts) >= 5:
            break
        x, y = _u(rng, 0.6, first - 0.6), _u(rng, 0.6, h - 0.6)
        if (min(x, first - x, y, h - y) <= 1.2
                and all(math.hypot(x - p, y - q) > 0.8 for p, q, _ in starts)):
            starts.append([round(x, 3), round(y, 3), round(_u(rng, -math.pi, math.pi), 4)])
    return {"robot": {"pose": starts[0], "starts": starts[1:]}, "walls": walls,
            "goal": {"center": [round(length - 0.7, 3), round(h / 2, 3)], "radius": 0.75}}


_MAKERS = {"rooms": _room, "mazes": _maze, "clutter": _clutter, "beacons": _beacons,
           "corridors": _corridor, "dead-ends": _dead_end, "doorways": _doorways}


def draw(kind: str, rng: np.random.Generator, side: str = "right",
         name: str = "generated") -> tuple[dict, WorldSpec]:
    """One randomised world of ``kind`` (``KINDS``) drawn with ``rng``, as the mapping a world
    file holds and as the world; start poses with the wall on the robot's ``side`` (rooms).
    Drawn again (up to 20 times) when a draw does not make a valid world."""
    if kind not in _MAKERS:
        raise ValueError(f"generator must be one of {', '.join(KINDS)}, got {kind!r}")
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    last: Exception | None = None
    for _ in range(20):
        try:
            data = {"name": name, **_MAKERS[kind](rng, side)}
            return data, parse_world(data, source=name)
        except (ValueError, IndexError) as exc:  # no start pose, or one too near a wall
            last = exc
    raise ValueError(f"no valid {kind} world in 20 draws: {last}")


def generate(kind: str, rng: np.random.Generator, side: str = "right",
             name: str = "generated") -> WorldSpec:
    """One randomised world (``draw``'s world)."""
    return draw(kind, rng, side, name)[1]


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, 0x5EED])


def generated(kind: str, count: int, seed: int, side: str = "right") -> list[WorldSpec]:
    """``count`` randomised worlds of ``kind`` for the training run of ``seed`` (the same worlds
    for the same seed, here and in ``rhbl generate``), named ``<kind>-<seed>-<i>``."""
    rng = _rng(seed)
    return [generate(kind, rng, side, name=f"{kind}-{seed}-{i}") for i in range(count)]


def to_toml(data: dict) -> str:
    """A drawn world (``draw``'s mapping) as a world file (docs/protocol.md section 10)."""
    def vec(v) -> str:
        return "[" + ", ".join(vec(x) if isinstance(x, list | tuple) else f"{x:g}"
                               for x in v) + "]"

    robot = data["robot"]
    out = ["# drawn by rhbl generate (lab.generated), not by hand",
           f'name = "{data["name"]}"', "", "[robot]", f"pose = {vec(robot['pose'])}",
           f"starts = {vec(robot['starts'])}"]
    for w in data["walls"]:
        out += ["", "[[walls]]"] + (["closed = true"] if w.get("closed") else []) + [
            f"points = {vec(w['points'])}"]
    for bc in data.get("beacons", ()):
        out += ["", "[[beacons]]", f"id = {bc['id']}", f"pos = {vec(bc['pos'])}",
                f'colour = "{bc["colour"]}"', f"size = {bc['size']:g}"]
    if data.get("goal"):
        g = data["goal"]
        out += ["", "[goal]", f"center = {vec(g['center'])}", f"radius = {g['radius']:g}"]
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------ the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("kind", choices=list(KINDS),
                        help="rooms (walls to follow), mazes (tiered, with a goal), clutter "
                             "(boxes and pillars to wander among), beacons (a room with "
                             "partitions and the beacons 1-3, for goals), corridors (winding "
                             "loops), dead-ends (a hall with blind corridors, a goal) or "
                             "doorways (rooms in a row, a goal in the last)")
    parser.add_argument("--count", type=arguments.positive_int, default=8)
    parser.add_argument("--seed", type=arguments.seed, default=0,
                        help="the same seed draws the same worlds (a training run of seed S "
                             "with round_generated = N is taught in the first N of seed S)")
    parser.add_argument("--side", choices=["right", "left"], default="right",
                        help="rooms: the start poses have the wall on the robot's right or left")
    parser.add_argument("--out", required=True, type=arguments.output_folder,
                        help="the folder to write KIND-SEED-I.toml into (made if missing; an "
                             "existing file of that name is not replaced)")


def main(args) -> int:
    out = Path(args.out)
    rng = _rng(args.seed)
    drawn = [draw(args.kind, rng, args.side, f"{args.kind}-{args.seed}-{i}")[0]
             for i in range(args.count)]
    for data in drawn:
        path = out / f"{data['name']}.toml"
        try:
            fd = files.open_output(path, overwrite=False, what="--out")
        except FileExistsError:
            raise ValueError(f"--out: {path} exists (not replaced): give another folder or "
                             "--seed") from None
        with open(fd, "w", encoding="utf-8") as f:
            f.write(to_toml(data))
        print(f"wrote {path}")
    return 0
