"""Sense-to-act latency across processes, beside the raw zenoh round trip measured in the same run.

Topology as in the demo: this process plays the server (a zenoh session in router mode listening
on loopback); the others connect to it as clients.

- raw: a scan-sized payload published here, echoed back by a child process (``--echo``) that
  does nothing else: the transport's round trip with two Python callbacks.
- sense-to-act: a real ``Scan`` (a 360-beam scan of the room world) published on the robot's scan
  key, answered by a real ``rhbl controller`` process (a tree trained in-process for 120 s of the
  room) with a ``VelCmd`` carrying that scan's id: decode, features, ``predict_one``, encode,
  publish, through the same router.

One message in flight at a time, the two kinds interleaved. Prints p50/p99 and the ratio
(target: sense-to-act p50 within 3x of the raw round trip). ``--breakdown`` runs the controller
with a clock around each stage of its loop (the scan's bytes taken from the ring channel and
decoded, features and tree, the command encoded and put, the decision for viewers) and prints
each stage's median beside the round trips.

    python benchmarks/bench_latency.py [--n 1000] [--breakdown]
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
from protocol import keys  # noqa: E402
from protocol.messages import Scan, VelCmd  # noqa: E402
from protocol.session import make_config  # noqa: E402

PING, PONG = "bench/ping", "bench/pong"


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
STAGES = (("decode", "the scan's bytes from the ring channel to a Scan"),
          ("answer", "features, the tree's predict_one, the guard"),
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

    def recv(self):
        sample = self._recv()
        t = mark[0] = clock()
        scan = self._decoder.decode(Scan, sample.payload.to_bytes())
        times["decode"].append(clock() - t)
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

    player.ScanChannel.recv = recv
    timed(controller.ControllerProcess, "answer", "answer")
    timed(player.PlayerClient, "answer", "command", end_to_end=True)
    timed(controller.ControllerProcess, "publish_decision", "decision")
    atexit.register(lambda: Path(out).write_text(json.dumps(times)))
    return rhbl_main(argv)


def _train_tree(path: Path) -> None:
    from lab.harness import make_learner, resolve_world
    from lab.recipe import RECIPES
    from lab.train import train

    spec = resolve_world("room")
    learner = make_learner(spec.task)
    train(spec, learner, RECIPES[spec.task].replace(seconds=120.0), seed=0)
    learner.save(path)


def _pct(a) -> tuple[float, float]:
    a = np.asarray(a) * 1e6
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="round trips of each kind")
    ap.add_argument("--breakdown", action="store_true",
                    help="also time each stage of the controller's loop")
    ap.add_argument("--echo", metavar="ENDPOINT", help=argparse.SUPPRESS)
    ap.add_argument("--timed-controller", metavar="OUT", help=argparse.SUPPRESS)
    args, rest = ap.parse_known_args()
    if args.echo:
        return echo(args.echo)
    if args.timed_controller:
        return timed_controller(args.timed_controller, rest)
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")

    from lab.harness import resolve_world
    from server.world import World

    tmp = Path(tempfile.mkdtemp(prefix="rhbl-bench-"))
    tree = tmp / "tree.rhbl"
    _train_tree(tree)
    probe = _Probe(World(resolve_world("room")).scan(0))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argv = ["controller", "--tree", str(tree), "--connect", endpoint, "--log-level", "WARNING"]
    stages = tmp / "stages.json"
    children = [
        Child("echo", [sys.executable, __file__, "--echo", endpoint]),
        Child("controller", [sys.executable, __file__, "--timed-controller", str(stages), *argv]
              if args.breakdown else rhbl_argv(*argv), cwd=ROOT),
    ]
    raw, s2a, lost = _measure(endpoint, children, probe, args.n)
    _report(raw, s2a, lost, probe.size, args.n, tree)
    if args.breakdown:
        _report_stages(stages)
    return 0


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
        self.scan_pub = self.ping_pub = None  # set once the session is open
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

    def one_scan(self) -> float | None:
        self.sid += 1
        self.box["want"] = self.sid
        data = self.scan_payload(self.sid)
        self.got.clear()
        t0 = time.perf_counter()
        self.scan_pub.put(data)
        return (self.box["t"] - t0) if self.got.wait(1.0) else None

    def one_ping(self) -> float | None:
        data = os.urandom(self.size)
        self.box.pop("want", None)
        self.got.clear()
        t0 = time.perf_counter()
        self.ping_pub.put(data)
        return (self.box["t"] - t0) if self.got.wait(1.0) else None


def _measure(endpoint: str, children: list[Child], probe: _Probe, n: int):
    """This process as the router on ``endpoint``: start ``children``, then n round trips of
    each kind, interleaved. Returns (raw seconds, sense-to-act seconds, lost)."""
    robot = "r0"
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as s:
        probe.scan_pub = s.declare_publisher(keys.scan_key(robot), express=True)
        probe.ping_pub = s.declare_publisher(PING, express=True)
        subs = [s.declare_subscriber(PONG, probe.on_pong),
                s.declare_subscriber(keys.cmd_vel_key(robot, source="controller"), probe.on_cmd)]
        try:
            for c in children:
                c.start()
            return _round_trips(probe, n)
        finally:
            for sub in subs:
                sub.undeclare()
            for c in children:
                c.stop()


def _round_trips(probe: _Probe, n: int) -> tuple[list[float], list[float], int]:
    # warm up: both children answering
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (probe.one_scan() is None or probe.one_ping() is None):
        time.sleep(0.05)
    for _ in range(50):
        probe.one_scan(), probe.one_ping()
    raw, s2a, lost = [], [], 0
    for _ in range(n):
        a, b = probe.one_ping(), probe.one_scan()
        lost += (a is None) + (b is None)
        if a is not None:
            raw.append(a)
        if b is not None:
            s2a.append(b)
    return raw, s2a, lost


def _report(raw, s2a, lost: int, size: int, n: int, tree: Path) -> None:
    r50, r99 = _pct(raw)
    c50, c99 = _pct(s2a)
    from rhbl import load

    nodes = load(tree).node_count_
    print(f"payload {size} bytes (360-beam scan), {n} round trips each, one in flight; "
          f"tree {nodes} nodes; lost {lost}")
    print("| path | p50 us | p99 us |")
    print("|---|---|---|")
    print(f"| raw zenoh round trip (echo process) | {r50:.0f} | {r99:.0f} |")
    print(f"| scan -> rhbl controller -> command | {c50:.0f} | {c99:.0f} |")
    print(f"ratio p50 {c50 / r50:.2f}x (target <= 3x), p99 {c99 / r99:.2f}x")


if __name__ == "__main__":
    sys.exit(main())
