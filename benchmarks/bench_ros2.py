"""The latency ``rhbl ros2`` adds: a scan on the rhbl key -> a ``LaserScan`` on the ROS 2 key,
beside the native paths measured in the same run.

Topology as in the demo: this process plays the server (a zenoh session in router mode on
loopback, publishing each tick's ``State`` and a 360-beam ``Scan`` of the room world, answering
the laser's ``get_config``); a real ``rhbl ros2`` process bridges robot r0; the subscribers are a
client session of this process: an rhbl subscriber (``Scan.decode``) and a ROS 2 subscription
the rmw_zenoh way (an ``MS`` token, CDR decoded by rosbags) on ``/r0/scan``.

- rhbl native: ``Scan`` put on ``rhbl/r0/laser/0/data/scan`` -> the rhbl subscriber (one hop
  through the router).
- ROS 2 native: the same scan as a ``LaserScan`` in CDR, put on the ROS 2 key by a publisher
  of this process (what a robot on rmw_zenoh costs a subscriber: one hop).
- relay: the ``Scan`` put on a key of its own, forwarded as it is by a child process that does
  nothing else (``--relay``), to the rhbl subscriber: the cost of a second process and hop
  alone, with two Python callbacks.
- through the bridge: the ``Scan`` put -> ``rhbl ros2`` (decode, convert, CDR, put with its
  attachment) -> the ROS 2 subscription (two hops); "added" is, per scan, the bridge's arrival
  minus the rhbl subscriber's arrival of the same put.

One scan in flight at a time, the kinds interleaved; every time is this process's
``perf_counter`` (put to the subscriber's callback, decoding included). Prints p50/p99.

    python benchmarks/bench_ros2.py [--n 1000]
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from client.ros2.nodes import Ros2Graph  # noqa: E402
from lab.children import Child, free_port, rhbl_argv  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import LaserConfig, Scan, State  # noqa: E402
from protocol.ros2 import cdr  # noqa: E402
from protocol.ros2.convert import Frames, laserscan_from_scan, stamp  # noqa: E402
from protocol.ros2.graph import RobotTopics  # noqa: E402

ROBOT = "r0"
RELAY_IN, RELAY_OUT = "bench/relay/in", "bench/relay/out"
RATE = 10.0  # the laser's rate the bridge is told (scan_time = 1 / rate)


def _ns(t) -> int:
    """A header stamp (``builtin_interfaces/msg/Time``) in ns."""
    return t.sec * 1_000_000_000 + t.nanosec


class _Probe:
    """The subscribers' arrivals, keyed by what each sample carries: the rhbl scan's ``id``, the
    ``LaserScan``'s header stamp (ns)."""

    def __init__(self, ranges, laser) -> None:
        self.ranges, self.laser = ranges, laser
        self.cond = threading.Condition()
        self.native: dict[int, float] = {}
        self.relayed: dict[int, float] = {}
        self.ros: dict[int, float] = {}
        self.frame = Frames.for_robot(ROBOT).laser
        self.size = {"rhbl": len(self.scan(1).encode()),
                     "cdr": len(cdr.serialize(laserscan_from_scan(self.scan(1), self.frame)))}

    def scan(self, i: int) -> Scan:
        return Scan(ts=i * 0.1, id=i, ranges=self.ranges, pose=(3.0, 0.7, 0.0),
                    min_angle=self.laser.min_angle, max_angle=self.laser.max_angle,
                    resolution=self.laser.resolution, max_range=self.laser.max_range)

    def on_scan(self, sample) -> None:
        t = time.perf_counter()
        scan = Scan.decode(sample.payload.to_bytes())
        with self.cond:
            self.native[scan.id] = t
            self.cond.notify_all()

    def on_relayed(self, sample) -> None:
        t = time.perf_counter()
        scan = Scan.decode(sample.payload.to_bytes())
        with self.cond:
            self.relayed[scan.id] = t
            self.cond.notify_all()

    def on_laserscan(self, sample) -> None:
        t = time.perf_counter()
        msg = cdr.deserialize(sample.payload.to_bytes(), cdr.LASER_SCAN)
        with self.cond:
            self.ros[_ns(msg.header.stamp)] = t
            self.cond.notify_all()

    def wait(self, book: dict, key: int, timeout: float = 1.0) -> float | None:
        with self.cond:
            self.cond.wait_for(lambda: key in book, timeout)
            return book.pop(key, None)


def relay(endpoint: str) -> int:
    signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(SystemExit(0)))
    with zenoh.open(make_config(mode="client", connect=[endpoint])) as s:
        pub = s.declare_publisher(RELAY_OUT, express=True)
        sub = s.declare_subscriber(RELAY_IN, lambda sample: pub.put(sample.payload.to_bytes()))
        with contextlib.suppress(SystemExit):
            signal.pause()
        sub.undeclare()
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="scans of each kind")
    ap.add_argument("--relay", metavar="ENDPOINT", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.relay:
        return relay(args.relay)
    if args.n < 1:
        ap.error(f"--n must be >= 1, got {args.n}")

    from lab.harness import resolve_world
    from server.world import LASER, World

    probe = _Probe(World(resolve_world("room")).scan(0), LASER)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    children = [
        Child("ros2", rhbl_argv("ros2", "--robot", ROBOT, "--connect", endpoint,
                                "--log-level", "WARNING"), cwd=ROOT),
        Child("relay", [sys.executable, __file__, "--relay", endpoint]),
    ]
    times, lost = _measure(endpoint, children, probe, args.n)
    _report(times, lost, probe, args.n)
    return 0


def _timed(one_tick, one_direct, one_relay, n: int) -> tuple[dict[str, list[float]], int]:
    """50 rounds to warm up, then ``n`` of the three paths interleaved: ({path: seconds},
    scans lost)."""
    for _ in range(50):  # warm up
        one_tick(), one_direct(), one_relay()
    times: dict[str, list[float]] = {k: [] for k in PATHS}
    lost = 0
    for _ in range(n):
        (a, b), c, d = one_tick(), one_direct(), one_relay()
        got = {"native": a, "direct": c, "relay": d, "bridge": b,
               "added": None if a is None or b is None else b - a}
        lost += (a is None) + (b is None) + (c is None) + (d is None)
        for k, v in got.items():
            if v is not None:
                times[k].append(v)
    return times, lost


def _measure(endpoint: str, children: list[Child], probe: _Probe, n: int):
    """This process as the router (and the server) on ``endpoint``: start ``children`` (the
    bridge, the relay), then n scans of each kind, interleaved. Returns ({path: seconds},
    lost)."""
    topics = RobotTopics.of(ROBOT)
    config = LaserConfig(min_angle=probe.laser.min_angle, max_angle=probe.laser.max_angle,
                         resolution=probe.laser.resolution, max_range=probe.laser.max_range,
                         count=probe.laser.count, rate=RATE).encode()
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as s, \
            zenoh.open(make_config(mode="client", connect=[endpoint])) as listener:
        state_pub = s.declare_publisher(keys.state_key(ROBOT), express=True)
        scan_pub = s.declare_publisher(keys.scan_key(ROBOT), express=True)
        answer = s.declare_queryable(keys.request_key(ROBOT, "laser", "get_config"),
                                     lambda q: q.reply(q.key_expr, config))
        robot = Ros2Graph(s, 0)  # the "ROS 2 native" robot: a LaserScan publisher of its own
        direct_pub = robot.node("bench_robot", f"/{ROBOT}").publisher(topics.scan)
        graph = Ros2Graph(listener, 0)
        node = graph.node("bench_listener", f"/{ROBOT}")
        node.subscription(topics.scan, probe.on_laserscan)
        native_sub = listener.declare_subscriber(keys.scan_key(ROBOT), probe.on_scan)
        relay_sub = listener.declare_subscriber(RELAY_OUT, probe.on_relayed)
        relay_pub = s.declare_publisher(RELAY_IN, express=True)
        tick = iter(range(1, 1 << 40))

        def one_tick():
            """A tick as the server sends it (state, then scan): (rhbl, bridge) seconds."""
            i = next(tick)
            scan = probe.scan(i)
            state = State(ts=scan.ts, seq=i, pos=scan.pose).encode()
            data = scan.encode()
            state_pub.put(state)
            t0 = time.perf_counter()
            scan_pub.put(data)
            a = probe.wait(probe.native, i)
            b = probe.wait(probe.ros, _ns(stamp(scan.ts)))
            return (None if a is None else a - t0), (None if b is None else b - t0)

        def one_direct():
            i = next(tick)
            scan = probe.scan(i)
            data = cdr.serialize(laserscan_from_scan(scan, probe.frame, 1.0 / RATE))
            t0 = time.perf_counter()
            direct_pub.put_cdr(data)
            b = probe.wait(probe.ros, _ns(stamp(scan.ts)))
            return None if b is None else b - t0

        def one_relay():
            i = next(tick)
            data = probe.scan(i).encode()
            t0 = time.perf_counter()
            relay_pub.put(data)
            b = probe.wait(probe.relayed, i)
            return None if b is None else b - t0

        try:
            for c in children:
                c.start()
            deadline = time.monotonic() + 60  # both up (the bridge waits for a first scan)
            while one_tick()[1] is None or one_relay() is None:
                if time.monotonic() > deadline:
                    raise SystemExit("bench_ros2: the bridge or the relay did not answer")
            return _timed(one_tick, one_direct, one_relay, n)
        finally:
            for c in children:
                c.stop()
            relay_sub.undeclare()
            native_sub.undeclare()
            graph.close()
            robot.close()
            answer.undeclare()


def _pct(a) -> tuple[float, float]:
    a = np.asarray(a) * 1e6
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


PATHS = {
    "native": "rhbl native: Scan -> rhbl subscriber",
    "direct": "ROS 2 native: LaserScan -> ROS 2 subscription",
    "relay": "relay: Scan -> a process forwarding it -> rhbl subscriber",
    "bridge": "through rhbl ros2: Scan -> bridge -> ROS 2 subscription",
    "added": "added by the bridge (bridge - rhbl native, per scan)",
}


def _report(times: dict[str, list[float]], lost: int, probe: _Probe, n: int) -> None:
    pct = {k: _pct(v) for k, v in times.items()}
    print(f"360-beam scan: rhbl Scan {probe.size['rhbl']} bytes, LaserScan CDR "
          f"{probe.size['cdr']} bytes; {n} scans of each kind, one in flight; lost {lost}")
    print("| path | p50 us | p99 us |")
    print("|---|---|---|")
    for k, label in PATHS.items():
        print(f"| {label} | {pct[k][0]:.0f} | {pct[k][1]:.0f} |")
    b, nat, rel = pct["bridge"], pct["native"], pct["relay"]
    print(f"through the bridge / rhbl native: p50 {b[0] / nat[0]:.2f}x, p99 {b[1] / nat[1]:.2f}x;"
          f" / relay: p50 {b[0] / rel[0]:.2f}x, p99 {b[1] / rel[1]:.2f}x")


if __name__ == "__main__":
    sys.exit(main())
