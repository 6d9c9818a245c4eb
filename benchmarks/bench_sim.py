"""Simulator speed: ``python benchmarks/bench_sim.py [--world room] [--seconds 300]``.

1. In-process (no zenoh): one robot with the 360-beam laser scanned at 10 Hz, driven by a small
   wall-avoiding reflex, as a real-time factor (sim seconds per wall second). Stage's published
   figure for one simple robot is about 1000x real time.
2. The zenoh server node (``server.node.ServerNode``, a router session on loopback, no clients,
   every robot commanded each tick): the cost of one 10 Hz tick (step + scan + encode + publish
   for every robot), and the largest number of robots it keeps at real time, checked by running
   that many at 10 Hz for a few seconds and counting missed ticks.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import server  # noqa: E402
from lab.processes import free_port  # noqa: E402
from server.world import LASER, ROBOT, World, load_world  # noqa: E402


def reflex(ranges: np.ndarray) -> tuple[float, float]:
    front = float(ranges[150:210].min())
    right = float(ranges[0:60].min())
    if front < 0.7:
        return 0.0, 0.8
    if right < 0.5:
        return 0.3, 0.4
    if right > 1.0:
        return 0.3, -0.4
    return 0.45, 0.0


def bench_in_process(world: str, seconds: float, repeats: int = 3) -> dict:
    spec = load_world(server.world_path(world))
    steps = int(round(seconds * 10))
    best = math.inf
    for _ in range(repeats):
        w = World(spec, robots=1, seed=0)
        t = time.perf_counter()
        for _ in range(steps):
            w.set_command(0, *reflex(w.scan(0)))
            w.step(0.1)
        best = min(best, time.perf_counter() - t)
    w = World(spec)
    n = 2000
    t = time.perf_counter()
    for _ in range(n):
        w.scan(0)
    scan_us = (time.perf_counter() - t) / n * 1e6
    w.set_command(0, 0.3, 0.2)
    t = time.perf_counter()
    for _ in range(n):
        w.step(0.1)
    step_us = (time.perf_counter() - t) / n * 1e6
    return {
        "rtf": seconds / best,
        "tick_us": best / steps * 1e6,
        "scan_us": scan_us,
        "step_us": step_us,
        "segments": len(spec.segments()),
    }


def free_poses(spec, n: int, spacing: float = 0.7) -> list[tuple[float, float, float]]:
    """Up to ``n`` poses on a grid, clear of walls (for many-robot runs)."""
    from server.world import _point_segment_distance

    xmin, ymin, xmax, ymax = spec.bounds()
    segs = spec.segments()
    probe = World(spec)
    out = []
    for y in np.arange(ymin + 0.5, ymax - 0.3, spacing):
        for x in np.arange(xmin + 0.5, xmax - 0.3, spacing):
            if _point_segment_distance(np.array([x, y]), segs).min() < ROBOT.radius + 0.15:
                continue
            probe.reset(poses=[(float(x), float(y), 0.0)])
            r = probe.scan(0)  # inside the walls: something within range in most directions
            if (r < LASER.max_range).mean() < 0.5:
                continue
            out.append((float(x), float(y), 0.0))
            if len(out) == n:
                return out
    return out


def _node(spec, n: int):
    import zenoh

    from protocol.session import make_config
    from server.node import ServerNode

    session = zenoh.open(make_config(mode="router", listen=[f"tcp/127.0.0.1:{free_port()}"]))
    w = World(spec, robots=n)
    w.reset(poses=free_poses(spec, n))
    node = ServerNode(session, w, rate=10.0, speedup=1.0, watchdog=0.5)
    return session, node


def _command_all(node, k: int) -> None:
    for r in node._robots:
        r.arbiter.offer("bench", 0.3, 0.4 * math.sin(0.05 * k + r.index), True, node.world.time)


def tick_cost(spec, n: int, ticks: int = 50) -> float:
    session, node = _node(spec, n)
    try:
        t = time.perf_counter()
        for k in range(ticks):
            _command_all(node, k)
            node.tick()
        return (time.perf_counter() - t) / ticks
    finally:
        node.close()
        session.close()


def real_time_run(spec, n: int, seconds: float = 3.0) -> tuple[float, float]:
    """Run n robots at 10 Hz real time; return (achieved Hz, worst tick seconds)."""
    session, node = _node(spec, n)
    try:
        period = 0.1
        t0 = time.monotonic()
        next_t = t0
        worst = 0.0
        ticks = 0
        while time.monotonic() - t0 < seconds:
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            next_t += period
            a = time.perf_counter()
            _command_all(node, ticks)
            node.tick()
            worst = max(worst, time.perf_counter() - a)
            ticks += 1
        return ticks / (time.monotonic() - t0), worst
    finally:
        node.close()
        session.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--world", default="room")
    p.add_argument("--seconds", type=float, default=300.0, help="sim seconds in-process")
    p.add_argument("--no-server", action="store_true", help="skip the zenoh server figures")
    args = p.parse_args(argv)

    r = bench_in_process(args.world, args.seconds)
    print(
        f"in-process, world {args.world!r} ({r['segments']} wall segments), 1 robot, "
        f"360-beam laser at 10 Hz, {args.seconds:g} s sim:"
    )
    print(
        f"  real-time factor {r['rtf']:.0f}x  (one 0.1 s tick {r['tick_us']:.0f} us: "
        f"step {r['step_us']:.0f} us, scan {r['scan_us']:.0f} us)"
    )
    print("  Stage's published figure for one simple robot: about 1000x")
    if args.no_server:
        return 0
    spec = load_world(server.world_path(args.world))
    per = {n: tick_cost(spec, n) for n in (1, 10, 40)}
    for n, c in per.items():
        print(f"server node, {n:3d} robots: one tick (step+scan+encode+publish) {c * 1e3:.2f} ms")
    slope = (per[40] - per[10]) / 30
    estimate = int(0.08 / max(slope, 1e-6))  # keep a 20% margin of the 100 ms period
    n = max(1, min(estimate, len(free_poses(spec, 10_000))))
    while n > 1:
        hz, worst = real_time_run(spec, n)
        if hz >= 9.9 and worst < 0.1:
            break
        n = int(n * 0.8)
    print(
        f"server node at real time (10 Hz): {n} robots in world {args.world!r} "
        f"(achieved {hz:.2f} Hz, worst tick {worst * 1e3:.1f} ms)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
