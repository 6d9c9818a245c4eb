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
(target: sense-to-act p50 within 3x of the raw round trip).

    python benchmarks/bench_latency.py [--n 1000]
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
    ap.add_argument("--echo", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.echo:
        return echo(args.echo)

    from lab.harness import resolve_world
    from server.world import World

    tmp = Path(tempfile.mkdtemp(prefix="rhbl-bench-"))
    tree = tmp / "tree.rhbl"
    _train_tree(tree)
    probe = _Probe(World(resolve_world("room")).scan(0))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    children = [
        Child("echo", [sys.executable, __file__, "--echo", endpoint]),
        Child("controller", rhbl_argv("controller", "--tree", str(tree), "--connect", endpoint,
                                      "--log-level", "WARNING"), cwd=ROOT),
    ]
    raw, s2a, lost = _measure(endpoint, children, probe, args.n)
    _report(raw, s2a, lost, probe.size, args.n, tree)
    return 0


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
