"""Simulator speed: ``python benchmarks/bench_sim.py [--world room] [--seconds 300]``.

1. In-process (no zenoh): one robot with the 360-beam laser scanned at 10 Hz, driven by a small
   wall-avoiding reflex, as a real-time factor (sim seconds per wall second). Stage's published
   figure for one simple robot is about 1000x real time.
2. The zenoh server node (``server.node.ServerNode``, a router session on loopback, no clients,
   every robot commanded each tick): the cost of one 10 Hz tick (step + scan + encode + publish
   for every robot), and the largest number of robots it keeps at real time, checked by running
   that many at 10 Hz for a few seconds and counting missed ticks.
3. ``--fleet N``: N robots at 10 Hz real time for ``--fleet-seconds``, every robot driven by one
   controller process serving them all (a wall-avoiding reflex answering each scan with its id,
   over the same zenoh router as the server): ticks missed, worst tick, and sense-to-act
   latency (a robot's scan put by the server -> its answer reaching the server's session, by
   the timestamp zenoh's router gives it) percentiles; where the time goes: the server's tick
   CPU (median), the server process's CPU (zenoh's threads and the command handler included)
   and the controller process's. A world too small for N robots is tiled (``--tiles``: copies side by side,
   1 m apart; a robot sees only its own room's robots, the walls hide the rest).
   ``--fleet-tree one|batch``: the controller drives every robot with a tree (trained for 120 s
   of the room, as ``bench_latency.py``'s) instead of the reflex; it takes every scan waiting,
   the latest of each robot, and answers them one by one (``TreePolicy.act``) or in one
   batched query (``TreePolicy.act_many``).

The laser of all robots is cast together, in one compiled call per tick (``World.scans``,
``server.laser``): the robots-seen-by-robots part no longer grows with the square of the fleet.
``--compare`` times that cast against one laser at a time, each against every other robot in
numpy (``server.laser.robots_dense``), in the same run.
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
from lab.children import free_port  # noqa: E402
from server.world import LASER, ROBOT, Wall, World, load_world  # noqa: E402

_PERIOD = 0.1  # s, 10 Hz


def tiled(spec, tiles: int, gap: float = 1.0):
    """``spec`` copied ``tiles`` times on a near-square grid, ``gap`` m apart."""
    import dataclasses

    if tiles <= 1:
        return spec
    x0, y0, x1, y1 = spec.bounds()
    px, py = x1 - x0 + gap, y1 - y0 + gap
    cols = math.ceil(math.sqrt(tiles))
    walls = []
    for k in range(tiles):
        a, b = k % cols, k // cols
        walls += [Wall(points=tuple((x + a * px, y + b * py) for x, y in w.points),
                       closed=w.closed) for w in spec.walls]
    return dataclasses.replace(spec, name=f"{spec.name}x{tiles}", walls=tuple(walls))


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
    """Best of ``repeats`` runs of ``seconds`` sim seconds, then one more run timing the scan
    and the step of every tick apart (the same ticks: the robot drives, turns and stops as in
    the timed runs)."""
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
    w = World(spec, robots=1, seed=0)
    clock = time.perf_counter
    scan_s = step_s = 0.0
    for _ in range(steps):
        t0 = clock()
        r = w.scan(0)
        t1 = clock()
        w.set_command(0, *reflex(r))
        t2 = clock()
        w.step(0.1)
        t3 = clock()
        scan_s += t1 - t0
        step_s += t3 - t2
    return {
        "rtf": seconds / best,
        "tick_us": best / steps * 1e6,
        "scan_us": scan_s / steps * 1e6,
        "step_us": step_s / steps * 1e6,
        "segments": len(spec.segments()),
    }


def free_poses(spec, n: int, spacing: float = 0.7) -> list[tuple[float, float, float]]:
    """Up to ``n`` poses on a grid, clear of walls (for many-robot runs)."""
    from server.worldfile import point_segment_distance

    xmin, ymin, xmax, ymax = spec.bounds()
    segs = spec.segments()
    probe = World(spec)
    out = []
    for y in np.arange(ymin + 0.5, ymax - 0.3, spacing):
        for x in np.arange(xmin + 0.5, xmax - 0.3, spacing):
            if point_segment_distance(np.array([x, y]), segs).min() < ROBOT.radius + 0.15:
                continue
            probe.reset(poses=[(float(x), float(y), 0.0)])
            r = probe.scan(0)  # inside the walls: something within range in most directions
            if (r < LASER.max_range).mean() < 0.5:
                continue
            out.append((float(x), float(y), 0.0))
            if len(out) == n:
                return out
    return out


def _node(spec, n: int, tiles: int = 1):
    import zenoh

    from process.session import make_config
    from server.node import ServerNode

    session = zenoh.open(make_config(mode="router", listen=[f"tcp/127.0.0.1:{free_port()}"]))
    w = World(tiled(spec, tiles), robots=n)
    w.reset(poses=fleet_poses(spec, tiles, n) if tiles > 1 else free_poses(spec, n))
    node = ServerNode(session, w, rate=10.0, speedup=1.0, watchdog=0.5)
    return session, node


def _command_all(node, k: int) -> None:
    for r in node._robots:
        r.arbiter.offer("bench", 0.3, 0.4 * math.sin(0.05 * k + r.index), True, node.world.time)


def tick_cost(spec, n: int, ticks: int = 50, tiles: int = 1,
              clock=time.perf_counter) -> float:
    session, node = _node(spec, n, tiles)
    try:
        t = clock()
        for k in range(ticks):
            _command_all(node, k)
            node.tick()
        return (clock() - t) / ticks
    finally:
        node.close()
        session.close()


def real_time_run(spec, n: int, seconds: float = 3.0, tiles: int = 1) -> tuple[float, float]:
    """Run n robots at 10 Hz real time; return (achieved Hz, worst tick seconds)."""
    session, node = _node(spec, n, tiles)
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


def fleet_poses(spec, tiles: int, n: int) -> list[tuple[float, float, float]]:
    """``n`` free poses spread round-robin over the rooms of ``tiled(spec, tiles)``."""
    one = free_poses(spec, 10_000)
    if n > len(one) * max(tiles, 1):
        raise SystemExit(f"{n} robots do not fit in {tiles} copies of {spec.name!r} "
                         f"({len(one)} free poses each): raise --tiles")
    x0, y0, x1, y1 = spec.bounds()
    px, py = x1 - x0 + 1.0, y1 - y0 + 1.0
    cols = math.ceil(math.sqrt(max(tiles, 1)))
    out = []
    for k in range(n):
        t, j = k % max(tiles, 1), k // max(tiles, 1)
        x, y, a = one[j]
        out.append((x + (t % cols) * px, y + (t // cols) * py, a))
    return out


def serve_controller(endpoint: str, tree: str | None = None, batch: bool = False) -> int:
    """Child process: one controller for every robot, answering each scan with its id (with
    ``tree``: the tree's actions, ``serve_tree``)."""
    if tree is not None:
        return serve_tree(endpoint, tree, batch)
    from protocol import keys
    from protocol.messages import Scan, VelCmd

    def start(s, done, publisher):
        def on_scan(sample) -> None:
            robot = keys.parse(sample.key_expr).robot
            scan = Scan.decode(sample.payload.to_bytes())
            vx, va = reflex(np.asarray(scan.ranges))
            if done.is_set():  # stopping: the session may close under a late callback
                return
            publisher(robot).put(VelCmd(vx=vx, va=va, source="controller",
                                        scan_id=scan.id).encode())

        return s.declare_subscriber(keys.scan_key(keys.EVERY), on_scan).undeclare

    return _serve(endpoint, start)


def serve_tree(endpoint: str, tree: str, batch: bool) -> int:
    """Child process: one controller for every robot driving it with ``tree``: every scan
    waiting taken, the latest of each robot answered, one by one or (``batch``) together."""
    import threading

    import zenoh

    from client.roles.controller import load_tree
    from protocol import keys
    from protocol.messages import Scan, VelCmdPacker

    policy = load_tree(tree)
    packer = VelCmdPacker("controller")

    def start(s, done, publisher):
        sub = s.declare_subscriber(keys.scan_key(keys.EVERY), zenoh.handlers.FifoChannel(4096))

        def serve() -> None:
            recv, take = sub.handler.recv, sub.handler.try_recv
            while not done.is_set():
                latest = {}
                try:
                    sample = recv()
                except zenoh.ZError:  # the session closed: stopping
                    return
                while sample is not None:  # every scan waiting: the latest of each robot
                    latest[keys.parse(sample.key_expr).robot] = sample
                    sample = take()
                robots = list(latest)
                scans = [Scan.decode(latest[r].payload.to_bytes()) for r in robots]
                if batch:
                    names = policy.act_many(np.stack([sc.ranges for sc in scans]),
                                            [sc.pose[2] for sc in scans])
                else:
                    names = [policy.act(sc.ranges, sc.pose) for sc in scans]
                for robot, sc, name in zip(robots, scans, names, strict=True):
                    vx, va = policy.actions[name]
                    publisher(robot).put(packer.pack(vx, va, True, sc.id, sc.ts))

        threading.Thread(target=serve, daemon=True).start()
        return None

    return _serve(endpoint, start)


def _serve(endpoint: str, start) -> int:
    """A controller child's frame: a zenoh session on ``endpoint``; ``start(session, done,
    publisher)`` sets up the answering (``publisher(robot)``: that robot's command publisher)
    and returns what stops it, or None; "ready", then on SIGTERM the CPU seconds spent
    serving, both on stdout for the parent (``fleet_run``)."""
    import os
    import signal
    import threading

    import zenoh

    from process.session import make_config
    from protocol import keys

    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    with zenoh.open(make_config(mode="client", connect=[endpoint])) as s:
        pubs: dict[str, object] = {}

        def publisher(robot: str):
            pub = pubs.get(robot)
            if pub is None:
                pub = pubs[robot] = s.declare_publisher(
                    keys.cmd_vel_key(robot, source="controller"), express=True)
            return pub

        stop = start(s, done, publisher)
        t0 = os.times()
        print("ready", flush=True)
        done.wait()
        if stop is not None:
            stop()
        t1 = os.times()  # CPU seconds while serving, for the parent's figures
        print(f"cpu {t1.user + t1.system - t0.user - t0.system:.3f}", flush=True)
    return 0


class _TimedPub:
    """A scan publisher that notes when each robot's scan went out."""

    def __init__(self, pub, name: str, sent: dict) -> None:
        self.pub, self.name, self.sent = pub, name, sent

    def put(self, payload: bytes) -> None:
        self.pub.put(payload)
        self.sent[self.name] = time.time()  # the clock of zenoh's timestamps


def train_room_tree(path: Path) -> None:
    """A small tree of the room (120 s of the recipe, seed 0) at ``path``: what the latency
    benchmarks' controllers drive."""
    from lab.harness import make_learner, resolve_world
    from lab.recipe import RECIPES
    from lab.train import train

    spec = resolve_world("room")
    learner = make_learner("wall-following")
    train(spec, learner, RECIPES["wall-following"].replace(seconds=120.0), seed=0)
    learner.save(path)


def fleet_run(spec, n: int, tiles: int, seconds: float, tree: str | None = None) -> dict:
    """n robots at 10 Hz real time, driven by one controller process: missed ticks and
    sense-to-act latency (a robot's scan out -> its answer in at the server). ``tree``:
    ``one`` or ``batch``, the controller drives with a tree (``serve_tree``)."""
    import subprocess
    import tempfile

    argv = [sys.executable, __file__]
    if tree is not None:
        path = Path(tempfile.mkdtemp(prefix="rhbl-bench-")) / "tree.rhbl"
        train_room_tree(path)
        argv += ["--tree", str(path), *(["--batch"] if tree == "batch" else [])]
    session, node, endpoint = _fleet_node(spec, n, tiles)
    probe = _Latency(node)
    child = subprocess.Popen([*argv, "--serve-controller", endpoint], stdout=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        if child.stdout.readline().strip() != "ready":
            raise SystemExit("the controller process did not start")
        ready = time.monotonic()
        t = _tick_at_10hz(node, probe, seconds)
        ms = np.asarray(probe.lat) * 1e3 if probe.lat else np.asarray([math.nan])
        result = {
            "robots": n, "tiles": tiles, "ticks": t["ticks"], "missed": t["missed"],
            "worst_ms": t["worst_ms"], "answered": probe.answered / max(t["ticks"] * n, 1),
            "p50": float(np.percentile(ms, 50)), "p90": float(np.percentile(ms, 90)),
            "p99": float(np.percentile(ms, 99)),
            "hz": t["hz"], "tick_cpu_ms": t["tick_cpu_ms"], "server_cpu": t["server_cpu"],
        }
    finally:
        out = _stop_controller(child)
        node.close()
        session.close()
    # the controller's CPU seconds from its "ready" to its end (the warm-up ticks included)
    cpu = [float(line.split()[1]) for line in out.splitlines() if line.startswith("cpu ")]
    result["controller_cpu"] = cpu[0] / (time.monotonic() - ready) if cpu else math.nan
    return result


def _fleet_node(spec, n: int, tiles: int):
    """A router session listening on a free loopback port, a server node for n robots on it,
    and the port's endpoint."""
    import zenoh

    from process.session import make_config
    from server.node import ServerNode

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(make_config(mode="router", listen=[endpoint]))
    w = World(tiled(spec, tiles), robots=n)
    w.reset(poses=fleet_poses(spec, tiles, n))
    return session, ServerNode(session, w, rate=10.0, speedup=1.0, watchdog=0.5), endpoint


class _Latency:
    """Sense-to-act latency at the server: a robot's scan out (``_TimedPub``) -> the answer to
    that scan in, for every robot of ``node``; ``lat`` (seconds), ``answered`` (count)."""

    def __init__(self, node) -> None:
        self.sent: dict[str, float] = {}  # robot -> when its last scan went out
        self.scan_of: dict[str, int] = {}
        self.lat: list[float] = []
        self.answered = 0
        for r in node._robots:
            r.pubs["scan"] = _TimedPub(r.pubs["scan"], r.name, self.sent)
        # a command's arrival is the timestamp the server's session (the router) gave it on the
        # way in, read in the node's own handler (the node takes commands at its tick; a second
        # subscriber decoding every command again would add its work to the server measured)
        node_on_cmd = node._on_cmd

        def on_cmd(r, sample) -> None:
            stamp = sample.timestamp
            t = stamp.get_time().timestamp() if stamp is not None else time.time()
            node_on_cmd(r, sample)
            if r.answers.get("controller") == self.scan_of.get(r.name) and r.name in self.sent:
                self.lat.append(t - self.sent[r.name])
                self.answered += 1

        node._on_cmd = on_cmd

    def ticked(self, node) -> None:
        """Note each robot's scan of this tick (the one its answer must carry)."""
        for r in node._robots:
            self.scan_of[r.name] = r.scan_id

    def restart(self) -> None:
        self.lat.clear()
        self.answered = 0


def _tick_at_10hz(node, probe: _Latency, seconds: float, warm: int = 10) -> dict:
    """Tick ``node`` at 10 Hz real time for ``seconds`` after ``warm`` ticks (connections,
    first publishers; ``probe`` restarts then): ticks counted, missed, the worst, the achieved
    rate, the tick's median thread CPU and the process's CPU share."""
    import os

    tick_cpu: list[float] = []
    ticks = missed = 0
    worst = 0.0
    t0 = time.monotonic()
    next_t = t0
    while time.monotonic() - t0 < seconds + warm * _PERIOD:
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        start = next_t
        next_t += _PERIOD
        a, c = time.perf_counter(), time.thread_time()
        node.tick()
        took = time.perf_counter() - a
        tick_cpu.append(time.thread_time() - c)
        probe.ticked(node)
        ticks += 1
        if ticks == warm:
            probe.restart()
            counted_from = ticks
            tick_cpu.clear()
            cpu0, wall0 = os.times(), time.monotonic()
        if ticks > warm:
            worst = max(worst, took)
            if time.monotonic() - start > _PERIOD:
                missed += 1
            if next_t < time.monotonic() - _PERIOD:  # behind by a whole tick: skip it
                next_t = time.monotonic()
    counted = ticks - counted_from
    cpu1, wall1 = os.times(), time.monotonic()
    return {"ticks": counted, "missed": missed, "worst_ms": worst * 1e3,
            "hz": counted / (time.monotonic() - t0 - warm * _PERIOD),
            "tick_cpu_ms": float(np.median(tick_cpu)) * 1e3,
            "server_cpu": (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (wall1 - wall0)}


def _stop_controller(child) -> str:
    """Stop the controller process (SIGTERM, SIGKILL after 10 s); its output."""
    import os
    import signal
    import subprocess

    os.kill(child.pid, signal.SIGTERM)
    try:
        out, _ = child.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        os.kill(child.pid, signal.SIGKILL)
        out, _ = child.communicate()
    return out


def compare_scans(spec, n: int, tiles: int, repeats: int = 5) -> tuple[float, float]:
    """Best-of ``repeats`` CPU seconds to cast all n lasers: one robot at a time, its walls then
    every other robot in numpy (``server.laser.robots_dense``, the simulator's robot cast before
    ``World.scans``) vs all together (``World.scans``), side by side in one run. Checks both
    give the same ranges."""
    from server import laser

    w = World(tiled(spec, tiles), robots=n)
    w.reset(poses=fleet_poses(spec, tiles, n))

    def one_by_one() -> np.ndarray:
        centres = np.asarray([w.pose(i)[:2] for i in range(n)])
        out = np.empty((n, LASER.count), dtype=np.float32)
        for i in range(n):
            x, y, yaw = w.pose(i)
            r, dc, ds = w._scan_walls(x, y, yaw)
            out[i] = laser.robots_dense(r, (x, y), dc, ds, np.delete(centres, i, axis=0),
                                        ROBOT.radius, LASER.max_range)
        return out

    if not np.array_equal(one_by_one(), w.scans()):
        raise SystemExit("the batched laser differs from the one-robot-at-a-time cast")
    one = batch = math.inf
    clock = time.thread_time  # CPU seconds of this thread: steadier than wall time on a busy box
    for _ in range(repeats):
        t = clock()
        w.scans()
        batch = min(batch, clock() - t)
        t = clock()
        one_by_one()
        one = min(one, clock() - t)
    return one, batch


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    if args.serve_controller:
        return serve_controller(args.serve_controller, args.tree, args.batch)
    spec = load_world(server.world_path(args.world))
    capacity = len(free_poses(spec, 10_000))

    def tiles_for(n: int) -> int:
        return args.tiles if args.tiles else max(1, math.ceil(n / capacity))

    # one measurement only, when asked for
    for only, report in (("compare", _report_compare), ("tick_cpu", _report_tick_cpu),
                         ("real_time", _report_real_time), ("fleet", _report_fleet)):
        if getattr(args, only):
            report(args, spec, tiles_for)
            return 0
    _report_in_process(args)
    if args.no_server:
        return 0
    _report_server(args, tiles_for)
    return 0


def _parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--world", default="room")
    p.add_argument("--seconds", type=float, default=300.0, help="sim seconds in-process")
    p.add_argument("--no-server", action="store_true", help="skip the zenoh server figures")
    p.add_argument("--compare", default=None, metavar="N,N,...",
                   help="only time the batched laser against one robot at a time for these "
                        "fleet sizes (e.g. 1,10,40,100,300)")
    p.add_argument("--tick-cpu", default=None, metavar="N,N,...",
                   help="only the server node's CPU seconds per tick (process time, zenoh's "
                        "threads included; best of 3 runs of 20 ticks) for these fleet sizes")
    p.add_argument("--real-time", type=int, default=None, metavar="N",
                   help="only run N robots at 10 Hz for --fleet-seconds, commanded in-process "
                        "(no clients): achieved rate, worst tick, ticks over the period")
    p.add_argument("--fleet", type=int, default=None, metavar="N",
                   help="only run N robots at 10 Hz with one controller process serving all")
    p.add_argument("--tiles", type=int, default=None,
                   help="copies of the world side by side (default: as few as fit the fleet)")
    p.add_argument("--fleet-seconds", type=float, default=20.0, help="real seconds (20)")
    p.add_argument("--fleet-tree", choices=("one", "batch"), default=None,
                   help="with --fleet: drive every robot with a tree, each scan answered one by "
                        "one or a batch of them in one query (default: a reflex)")
    p.add_argument("--serve-controller", metavar="ENDPOINT", help=argparse.SUPPRESS)
    p.add_argument("--tree", help=argparse.SUPPRESS)
    p.add_argument("--batch", action="store_true", help=argparse.SUPPRESS)
    return p.parse_args(argv)


def _report_compare(args, spec, tiles_for) -> None:
    for n in (int(x) for x in args.compare.split(",")):
        one, batch = compare_scans(spec, n, tiles_for(n))
        print(f"{n:4d} robots ({tiles_for(n)} x {args.world!r}): all lasers, CPU per tick: "
              f"one robot at a time {one * 1e3:8.2f} ms, together {batch * 1e3:7.2f} ms "
              f"({one / batch:.1f}x)", flush=True)


def _report_tick_cpu(args, spec, tiles_for) -> None:
    for n in (int(x) for x in args.tick_cpu.split(",")):
        c = min(tick_cost(spec, n, ticks=20, tiles=tiles_for(n), clock=time.process_time)
                for _ in range(3))
        print(f"{n:4d} robots ({tiles_for(n)} x {args.world!r}): server tick CPU "
              f"{c * 1e3:8.2f} ms ({c / n * 1e3:.3f} ms per robot; real time needs "
              f"< 100 ms)", flush=True)


def _report_real_time(args, spec, tiles_for) -> None:
    n = args.real_time
    hz, worst = real_time_run(spec, n, seconds=args.fleet_seconds, tiles=tiles_for(n))
    print(f"server node, {n} robots in {tiles_for(n)} x {args.world!r}, commanded "
          f"in-process, {args.fleet_seconds:g} s at 10 Hz: achieved {hz:.2f} Hz, worst tick "
          f"{worst * 1e3:.1f} ms")


def _report_fleet(args, spec, tiles_for) -> None:
    r = fleet_run(spec, args.fleet, tiles_for(args.fleet), args.fleet_seconds, args.fleet_tree)
    how = ("a reflex" if args.fleet_tree is None else
           f"a tree, {'one query per scan' if args.fleet_tree == 'one' else 'batched queries'}")
    print(f"fleet: {r['robots']} robots in {r['tiles']} x {args.world!r} at 10 Hz, one "
          f"controller process for all ({how}), {r['ticks']} ticks ({r['hz']:.2f} Hz): "
          f"{r['missed']} ticks missed, worst tick {r['worst_ms']:.1f} ms; "
          f"{r['answered'] * 100:.1f}% of scans answered in time; sense-to-act "
          f"p50 {r['p50']:.1f} ms, p90 {r['p90']:.1f} ms, p99 {r['p99']:.1f} ms; "
          f"server tick CPU p50 {r['tick_cpu_ms']:.1f} ms, server process "
          f"{r['server_cpu'] * 100:.0f}% of a core (zenoh and command callbacks included), "
          f"controller process {r['controller_cpu'] * 100:.0f}%")


def _report_in_process(args) -> None:
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


def _report_server(args, tiles_for) -> None:
    """The server node's tick cost for 1, 10, 40 robots and the largest fleet it keeps at
    real time (estimated from the cost's slope, then checked, 20% fewer each time it fails)."""
    spec = load_world(server.world_path(args.world))
    per = {n: tick_cost(spec, n) for n in (1, 10, 40)}
    for n, c in per.items():
        print(f"server node, {n:3d} robots: one tick (step+scan+encode+publish) {c * 1e3:.2f} ms")
    slope = (per[40] - per[10]) / 30
    estimate = int(0.08 / max(slope, 1e-6))  # keep a 20% margin of the 100 ms period
    n = max(1, min(estimate, 2000))
    while n > 1:
        hz, worst = real_time_run(spec, n, tiles=tiles_for(n))
        if hz >= 9.9 and worst < 0.1:
            break
        n = int(n * 0.8)
    print(
        f"server node at real time (10 Hz): {n} robots in {tiles_for(n)} x world "
        f"{args.world!r} (achieved {hz:.2f} Hz, worst tick {worst * 1e3:.1f} ms)"
    )


if __name__ == "__main__":
    sys.exit(main())
