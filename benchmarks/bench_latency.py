"""Sense-to-act latency across processes, beside the raw zenoh round trip measured in the same run.

Topology as in the demo: this process plays the server (a zenoh session in router mode listening
on loopback); the others connect to it as clients.

- raw: a scan-sized payload published here, echoed back by a child process (``--echo``) that
  does nothing else: the transport's round trip with two Python callbacks.
- sense-to-act: a real ``Scan`` (a 360-beam scan of the room world) published on the robot's scan
  key, answered by a real ``rhbl controller`` process (a tree trained in-process for 120 s of the
  room) with a ``VelCmd`` carrying that scan's id: decode, features, ``predict_one``, encode,
  publish, through the same router.

One message in flight at a time, the kinds interleaved. Prints p50/p99 and the ratio (target:
sense-to-act p50 within 1.3x of the raw round trip). ``--peer DIR`` also runs the controller of
another checkout of rhbl (DIR, e.g. ``git archive`` of an older commit unpacked; this
interpreter, the same tree, robot ``r1``) and interleaves its round trips with the others: the
two versions side by side under the same load. ``--breakdown`` runs this checkout's controller
with a clock around each stage of its loop (the scan's bytes taken from the ring channel and
decoded, features and tree, the command encoded and put, the decision for viewers) and prints
each stage's median beside the round trips.

``--fleet N,N,...`` instead times, in this process, the controller's own work for a tick of a
fleet of N robots (their scans in tiled copies of the room): each scan's features and tree query
one by one (``TreePolicy.act``, as ``rhbl controller`` answers a scan) against all of them at
once (``TreePolicy.act_many``: the features together, one batched tree query), best of 5, the
actions checked to be the same.

    python benchmarks/bench_latency.py [--n 1000] [--breakdown] [--peer DIR]
    python benchmarks/bench_latency.py --fleet 1,10,100,400
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lab.children import Child, free_port, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import Scan, VelCmd  # noqa: E402

PING, PONG = "bench/ping", "bench/pong"
ROBOT, PEER = "r0", "r1"  # this checkout's controller drives r0, the --peer's r1


def echo(endpoint: str) -> int:
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(0)))
    with zenoh.open(make_config(mode="client", connect=[endpoint])) as s:
        pub = s.declare_publisher(PONG, express=True)
        sub = s.declare_subscriber(PING, zenoh.handlers.RingChannel(1))
        try:
            while True:
                sample = sub.handler.recv()
                pub.put(sample.payload.to_bytes())
        except SystemExit:
            pass
    return 0


# the controller's stages --breakdown times: (label, what is wrapped)
STAGES = (("decode", "the scan's bytes read in place with the tree's features (one call)"),
          ("answer", "the tree's predict_one, the guard"),
          ("command", "the VelCmd encoded and put"),
          ("in hand -> out", "from the scan's bytes in hand to the command put"),
          ("decision", "the decision for viewers, after the command"))


def timed_controller(out: str, argv: list[str]) -> int:
    """Child process (--breakdown): ``rhbl controller ARGV`` with a clock around each stage of
    its loop; the durations (seconds) are written to ``out`` (JSON) when it ends."""
    import atexit
    import json

    import client.player as player
    import client.roles.controller as controller
    from lab.cli import main as rhbl_main

    times: dict[str, list[float]] = {name: [] for name, _ in STAGES}
    clock = time.perf_counter
    mark = [0.0]

    recv_payload, receive = player.ScanChannel.recv_payload, controller.ControllerProcess.receive

    def timed_recv_payload(self):
        data = recv_payload(self)
        mark[0] = clock()
        return data

    def timed_receive(self):
        scan = receive(self)
        times["decode"].append(clock() - mark[0])
        return scan

    def timed(cls, name: str, stage: str, end_to_end: bool = False) -> None:
        inner = getattr(cls, name)

        def wrapper(self, *a):
            t = clock()
            result = inner(self, *a)
            now = clock()
            times[stage].append(now - t)
            if end_to_end:
                times["in hand -> out"].append(now - mark[0])
            return result

        setattr(cls, name, wrapper)

    player.ScanChannel.recv_payload = timed_recv_payload
    controller.ControllerProcess.receive = timed_receive
    timed(controller.ControllerProcess, "answer", "answer")
    timed(player.PlayerClient, "answer", "command", end_to_end=True)
    timed(controller.ControllerProcess, "publish_decision", "decision")
    atexit.register(lambda: Path(out).write_text(json.dumps(times)))
    return rhbl_main(argv)


def _pct(a) -> tuple[float, float]:
    a = np.asarray(a) * 1e6
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="round trips of each kind")
    ap.add_argument("--breakdown", action="store_true",
                    help="also time each stage of the controller's loop")
    ap.add_argument("--peer", metavar="DIR", type=Path,
                    help="also the controller of another checkout of rhbl (its top folder), "
                         "interleaved with this one's")
    ap.add_argument("--fleet", metavar="N,N,...",
                    help="only the in-process figure: a tick of N robots' scans answered one "
                         "by one against one batched query")
    ap.add_argument("--echo", metavar="ENDPOINT", help=argparse.SUPPRESS)
    ap.add_argument("--timed-controller", metavar="OUT", help=argparse.SUPPRESS)
    args, rest = ap.parse_known_args()
    if args.echo:
        return echo(args.echo)
    if args.timed_controller:
        return timed_controller(args.timed_controller, rest)
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    if args.peer is not None and not (args.peer / "lab" / "cli.py").is_file():
        ap.error(f"--peer {args.peer}: not a checkout of rhbl (no lab/cli.py in it)")

    from lab.harness import resolve_world
    from server.world import World

    fleet = None
    if args.fleet:
        try:
            fleet = [int(x) for x in args.fleet.split(",")]
        except ValueError:
            ap.error(f"--fleet {args.fleet}: expected robot counts like 1,10,100")
        if min(fleet) < 1:
            ap.error(f"--fleet {args.fleet}: robot counts must be >= 1")
    tmp = Path(tempfile.mkdtemp(prefix="rhbl-bench-"))
    tree = tmp / "tree.rhbl"
    from bench_sim import train_room_tree

    train_room_tree(tree)
    if fleet:
        return fleet_ticks(tree, fleet)
    probe = _Probe(World(resolve_world("room")).scan(0))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argv = ["controller", "--tree", str(tree), "--connect", endpoint, "--log-level", "WARNING"]
    stages = tmp / "stages.json"
    children = [
        Child("echo", [sys.executable, __file__, "--echo", endpoint]),
        Child("controller", [sys.executable, __file__, "--timed-controller", str(stages), *argv]
              if args.breakdown else rhbl_argv(*argv), cwd=ROOT),
    ]
    robots = [ROBOT]
    if args.peer is not None:  # its own code: ``-m`` imports from the folder it runs in
        children.append(Child("peer", rhbl_argv(*argv, "--robot", PEER), cwd=args.peer))
        robots.append(PEER)
    raw, s2a, lost = _measure(endpoint, children, probe, robots, args.n)
    _report(raw, s2a, lost, probe.size, args.n, tree, args.peer)
    if args.breakdown:
        _report_stages(stages)
    return 0


def fleet_ticks(tree: Path, sizes: list[int]) -> int:
    """The controller's work for one tick of each fleet size: one by one against batched."""
    import math

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_sim import fleet_poses, free_poses, tiled

    from client.roles.controller import load_tree
    from lab.harness import resolve_world
    from server.world import World

    policy = load_tree(str(tree))
    spec = resolve_world("room")
    capacity = len(free_poses(spec, 10_000))
    print(f"tree {policy.classifier.node_count_} nodes; a tick's scans answered in this "
          f"process (best of 5, ms per tick):")
    print("| robots | one by one (act) | batched (act_many) | ratio |")
    print("|---|---|---|---|")
    for n in sizes:
        tiles = max(1, math.ceil(n / capacity))
        world = World(tiled(spec, tiles), robots=n)
        poses = fleet_poses(spec, tiles, n)
        world.reset(poses=poses)
        scans, yaws = world.scans(), [p[2] for p in poses]

        def one_by_one(scans=scans, yaws=yaws):
            return [policy.act(r, (0.0, 0.0, y)) for r, y in zip(scans, yaws, strict=True)]

        def batched(scans=scans, yaws=yaws):
            return policy.act_many(scans, yaws)

        if one_by_one() != batched():
            raise SystemExit(f"{n} robots: the batched actions differ from act's")
        a, b = (min(_seconds(f) for _ in range(5)) for f in (one_by_one, batched))
        print(f"| {n} | {a * 1e3:.3f} | {b * 1e3:.3f} | {a / b:.1f}x |")
    return 0


def _seconds(f) -> float:
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def _report_stages(path: Path) -> None:
    import json

    if not path.exists():
        print("the timed controller wrote no stage times (did it end cleanly?)")
        return
    times = json.loads(path.read_text())
    print("the controller's loop, per scan (p50 us, in the controller's process, the clock "
          "calls included):")
    for name, what in STAGES:
        if times.get(name):
            print(f"  {name:<15} {np.percentile(np.asarray(times[name]) * 1e6, 50):7.1f}  {what}")


class _Probe:
    """One message in flight at a time: a scan the controller answers with a command carrying
    its id (sense-to-act), or a scan-sized ping the echo process sends back (raw)."""

    def __init__(self, ranges) -> None:
        self.ranges = ranges
        self.got = threading.Event()
        self.box: dict = {}
        self.sid = 0
        self.scan_pubs: dict = {}  # robot -> its scan publisher, once the session is open
        self.ping_pub = None
        self.size = len(self.scan_payload(1))

    def scan_payload(self, i: int) -> bytes:
        return Scan(ts=i * 0.1, id=i, ranges=self.ranges, pose=(3.0, 0.7, 0.0)).encode()

    def on_pong(self, sample) -> None:
        self.box["t"] = time.perf_counter()
        self.got.set()

    def on_cmd(self, sample) -> None:
        t = time.perf_counter()
        cmd = VelCmd.decode(sample.payload.to_bytes())
        if cmd.scan_id == self.box.get("want"):
            self.box["t"] = t
            self.got.set()

    def one_scan(self, robot: str = ROBOT) -> float | None:
        self.sid += 1
        self.box["want"] = self.sid
        data = self.scan_payload(self.sid)
        pub = self.scan_pubs[robot]
        self.got.clear()
        t0 = time.perf_counter()
        pub.put(data)
        return (self.box["t"] - t0) if self.got.wait(1.0) else None

    def one_ping(self) -> float | None:
        data = os.urandom(self.size)
        self.box.pop("want", None)
        self.got.clear()
        t0 = time.perf_counter()
        self.ping_pub.put(data)
        return (self.box["t"] - t0) if self.got.wait(1.0) else None


def _measure(endpoint: str, children: list[Child], probe: _Probe, robots: list[str], n: int):
    """This process as the router on ``endpoint``: start ``children``, then n round trips of
    each kind, interleaved. Returns (raw seconds, {robot: sense-to-act seconds}, lost)."""
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as s:
        probe.ping_pub = s.declare_publisher(PING, express=True)
        subs = [s.declare_subscriber(PONG, probe.on_pong)]
        for robot in robots:
            probe.scan_pubs[robot] = s.declare_publisher(keys.scan_key(robot), express=True)
            subs.append(s.declare_subscriber(keys.cmd_vel_key(robot, source="controller"),
                                             probe.on_cmd))
        try:
            for c in children:
                c.start()
            return _round_trips(probe, robots, n)
        finally:
            for sub in subs:
                sub.undeclare()
            for c in children:
                c.stop()


def _round_trips(probe: _Probe, robots: list[str], n: int
                 ) -> tuple[list[float], dict[str, list[float]], int]:
    # warm up: every child answering
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (probe.one_ping() is None
                                           or any(probe.one_scan(r) is None for r in robots)):
        time.sleep(0.05)
    for _ in range(50):
        probe.one_ping(), [probe.one_scan(r) for r in robots]
    raw, s2a, lost = [], {r: [] for r in robots}, 0
    for _ in range(n):
        for got, into in [(probe.one_ping(), raw), *((probe.one_scan(r), s2a[r]) for r in robots)]:
            if got is None:
                lost += 1
            else:
                into.append(got)
    return raw, s2a, lost


def _report(raw, s2a: dict, lost: int, size: int, n: int, tree: Path, peer: Path | None
            ) -> None:
    r50, r99 = _pct(raw)
    from rhbl import load

    nodes = load(tree).node_count_
    print(f"payload {size} bytes (360-beam scan), {n} round trips each, one in flight; "
          f"tree {nodes} nodes; lost {lost}")
    print("| path | p50 us | p99 us | p50 / raw |")
    print("|---|---|---|---|")
    print(f"| raw zenoh round trip (echo process) | {r50:.0f} | {r99:.0f} | 1 |")
    for robot, what in ((ROBOT, "rhbl controller"), (PEER, f"the peer's controller ({peer})")):
        if robot in s2a:
            c50, c99 = _pct(s2a[robot])
            print(f"| scan -> {what} -> command | {c50:.0f} | {c99:.0f} | {c50 / r50:.2f}x |")
    c50, c99 = _pct(s2a[ROBOT])
    print(f"ratio p50 {c50 / r50:.2f}x (target <= 1.3x), p99 {c99 / r99:.2f}x")


if __name__ == "__main__":
    sys.exit(main())
