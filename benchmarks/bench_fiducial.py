"""Fiducial finder speed: ``python benchmarks/bench_fiducial.py [--world beacons-room]
[--robots 1 10 100 300] [--repeat 200]``.

The cost of one tick's fiducial detection for every robot (``World.fiducials``: every
(robot, beacon) pair within range and field of view tested against every wall in one numpy
intersection, ``server.fiducial``) beside the laser cast of the same tick (``World.scans``,
compiled) and a plain Python loop over robots, beacons and walls (the reference the tests
hold it to), robots at random free poses of the world (copies of it side by side, walls and
beacons, 20 robots a copy, for a fleet: every robot is tested against every beacon and wall). Also the cost of encoding one robot's ``Fiducial`` message. Figures in
microseconds per tick (median of ``--repeat``), ratios side by side.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import server  # noqa: E402
from protocol.messages import Fiducial, FiducialItem  # noqa: E402
from server.world import FIDUCIAL, Wall, World, load_world  # noqa: E402


def naive(spec, poses) -> list[list[int]]:
    """The beacons each robot sees, by a plain Python loop (no numpy)."""
    segs = spec.segments().tolist()
    out = []
    for x, y, yaw in poses:
        seen = []
        for b in spec.beacons:
            dx, dy = b.pos[0] - x, b.pos[1] - y
            r = math.hypot(dx, dy)
            a = math.remainder(math.atan2(dy, dx) - yaw, math.tau)
            if r > FIDUCIAL.max_range or abs(a) > FIDUCIAL.fov / 2:
                continue
            hidden = False
            for x0, y0, x1, y1 in segs:
                ex, ey = x1 - x0, y1 - y0
                den = dx * ey - dy * ex
                if den == 0:
                    continue
                wx, wy = x0 - x, y0 - y
                t, u = (wx * ey - wy * ex) / den, (wx * dy - wy * dx) / den
                if 0 < t < 1 - 1e-6 / r and 0 <= u <= 1:
                    hidden = True
                    break
            if not hidden:
                seen.append(b.id)
        out.append(seen)
    return out


def median_us(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * float(np.median(times))


def tiled(spec, tiles: int, gap: float = 1.0):
    """``spec`` copied ``tiles`` times on a near-square grid ``gap`` m apart, walls and beacons
    (the copies' beacon ids numbered on)."""
    if tiles <= 1:
        return spec
    x0, y0, x1, y1 = spec.bounds()
    px, py = x1 - x0 + gap, y1 - y0 + gap
    cols = math.ceil(math.sqrt(tiles))
    walls, beacons, top = [], [], max(b.id for b in spec.beacons)
    for k in range(tiles):
        a, b = k % cols, k // cols
        walls += [Wall(points=tuple((x + a * px, y + b * py) for x, y in w.points),
                       closed=w.closed) for w in spec.walls]
        beacons += [dataclasses.replace(c, id=c.id + k * top,
                                        pos=(c.pos[0] + a * px, c.pos[1] + b * py))
                    for c in spec.beacons]
    return dataclasses.replace(spec, name=f"{spec.name}x{tiles}", walls=tuple(walls),
                               beacons=tuple(beacons))


def fleet_world(spec, n: int, rng) -> World:
    """A world of ``n`` robots at random free poses (no two overlapping), the world tiled so
    that each copy holds at most 20."""
    spec = tiled(spec, math.ceil(n / 20))
    world = World(spec, robots=n)
    poses: list[tuple[float, float, float]] = []
    x0, y0, x1, y1 = spec.bounds()
    tries = 0
    while len(poses) < n:
        tries += 1
        if tries > 200_000:
            raise SystemExit(f"{spec.name}: no room for {n} robots; give fewer --robots")
        p = (rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-math.pi, math.pi))
        if spec.clearance(p[0], p[1]) < 0.3:
            continue
        if any(math.hypot(p[0] - q[0], p[1] - q[1]) < 0.55 for q in poses):
            continue
        poses.append(p)
    world.reset(poses=poses)
    return world


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--world", default="beacons-room")
    ap.add_argument("--robots", type=int, nargs="+", default=[1, 10, 100, 300])
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args(argv)
    spec = load_world(server.world_path(args.world))
    if not spec.beacons:
        raise SystemExit(f"{args.world}: a world without beacons")
    rng = np.random.default_rng(0)
    print(f"world {spec.name}: {len(spec.beacons)} beacons, {len(spec.segments())} wall "
          f"segments (tiled, 20 robots a copy, for a fleet); median of {args.repeat} ticks")
    print(f"{'robots':>7} {'fiducials us':>13} {'laser us':>10} {'python loop us':>15} "
          f"{'fid/laser':>10} {'loop/fid':>9}")
    for n in args.robots:
        world = fleet_world(spec, n, rng)
        poses = [world.pose(i) for i in range(n)]
        got = [sorted(int(i) for i in s.ids) for s in world.fiducials()]
        want = [sorted(s) for s in naive(world.spec, poses)]
        assert got == want, "the numpy detection and the loop disagree"
        fid = median_us(world.fiducials, args.repeat)
        laser = median_us(world.scans, args.repeat)
        loop = median_us(lambda w=world.spec, poses=poses: naive(w, poses),
                         max(10, args.repeat // 10))
        print(f"{n:>7} {fid:>13.1f} {laser:>10.1f} {loop:>15.1f} {fid / laser:>10.2f} "
              f"{loop / fid:>9.1f}")
    msg = Fiducial(ts=1.0, seq=1, items=tuple(FiducialItem(b.id, 3.0, 0.5) for b in spec.beacons),
                   pose=(1.0, 2.0, 0.5), truth=(1.0, 2.0, 0.5))
    enc = median_us(msg.encode, args.repeat * 10)
    print(f"encoding one Fiducial of {len(msg.items)} items: {enc:.1f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
