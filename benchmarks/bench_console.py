"""The teacher's console in a real headless Chromium: key press to command on the bus, and the
page's frame rate with the server's 360-beam scans at 10 Hz.

Starts a real ``rhbl server`` (room world, real time) and a real ``rhbl console`` on loopback,
opens the page in Debian's Chromium (selenium) and, ``--n`` times: dispatches a ``keydown``
ArrowUp in the page, stamped with the browser's clock (``performance.timeOrigin + now()``, the
same wall clock as this process), and waits for the teacher's ``VelCmd`` on
``.../cmd/vel/teacher`` at a zenoh subscriber here; then a ``keyup`` and its stop command (the
release latency). The frame rate is the page's requestAnimationFrame count over ``--seconds``
while scans arrive, with the mean time to draw a frame.

    python benchmarks/bench_console.py [--n 200] [--seconds 10]
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "integration"))

from browser import ConsoleProcess, chromium, close_chromium  # noqa: E402

from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import VelCmd  # noqa: E402
from tests.conftest import _server_factory  # noqa: E402

KEY = ("window.__t = performance.timeOrigin + performance.now();"
       "window.dispatchEvent(new KeyboardEvent(arguments[0], {key: 'ArrowUp'}));"
       "return window.__t;")


def decision_cost(n: int = 2000) -> str:
    """The controller's extra cost per scan: ``decision_path`` + a ``Decision`` encoded, against
    ``predict_one``, on a tree of a few thousand spheres (20 features)."""
    from protocol.messages import Decision
    from rhbl import HypersphereClassifier

    rng = np.random.default_rng(0)
    X = rng.random((3000, 20))
    y = np.where(X[:, 0] > 0.5, "fwd", "rot-left")
    clf = HypersphereClassifier(default_label="fwd").fit(X, y)
    for i in range(200):  # warm up both paths
        clf.predict_one(X[i])
        clf.decision_path(X[i])
    plain, decided, size = [], [], 0
    for i in range(n):  # interleaved, one call at a time: medians resist a loaded machine
        x = X[i % 3000]
        t0 = time.perf_counter()
        clf.predict_one(x)
        t1 = time.perf_counter()
        path = clf.decision_path(x)
        size += len(Decision(scan_id=i, action=str(path[-1]["label"]), nodes=clf.node_count_,
                             path=tuple((e["index"], e["depth"], e["radius"], str(e["label"]))
                                        for e in path)).encode())
        t2 = time.perf_counter()
        plain.append(t1 - t0)
        decided.append(t2 - t1)
    return (f"controller per scan ({clf.node_count_}-node tree, height {clf.height_}), median: "
            f"predict_one {np.median(plain) * 1e6:.0f} us, decision_path + Decision encoded "
            f"{np.median(decided) * 1e6:.0f} us ({size / n:.0f} bytes)")


class _Commands:
    """The teacher's commands on the bus, with their arrival (wall) time."""

    def __init__(self, session) -> None:
        self.arrivals: list[tuple[float, float]] = []  # (wall time, vx)
        self.cond = threading.Condition()
        self.sub = session.declare_subscriber(keys.cmd_vel_key("r0", source="teacher"),
                                              self._on)

    def _on(self, sample) -> None:
        t = time.time()
        c = VelCmd.decode(sample.payload.to_bytes())
        with self.cond:
            self.arrivals.append((t, c.vx))
            self.cond.notify_all()

    def first(self, pred, seen: int) -> float:
        """When the first command after the ``seen`` first ones with ``pred(vx)`` arrived."""
        with self.cond:
            if not self.cond.wait_for(lambda: any(pred(v) for _, v in self.arrivals[seen:]),
                                      5.0):
                raise SystemExit("no command arrived within 5 s")
            return next(t for t, v in self.arrivals[seen:] if pred(v))


def key_latency(drv, cmds: _Commands, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Key press -> the teacher's command, key release -> its stop (ms), ``n`` times."""
    press, release = [], []
    for _ in range(n):
        seen = len(cmds.arrivals)
        t0 = drv.execute_script(KEY, "keydown") / 1000.0
        press.append(cmds.first(lambda v: v > 0, seen) - t0)
        seen = len(cmds.arrivals)
        t0 = drv.execute_script(KEY, "keyup") / 1000.0
        release.append(cmds.first(lambda v: v == 0, seen) - t0)
    return np.array(press) * 1e3, np.array(release) * 1e3


def frame_rate(drv, seconds: float) -> tuple[float, float, int]:
    """Frames per second drawn over ``seconds``, ms to draw one, beams per scan drawn."""
    f0 = int(drv.find_element("id", "fps").get_attribute("data-frames"))
    t0 = time.monotonic()
    time.sleep(seconds)  # the measuring window itself, not a wait for an event
    f1 = int(drv.find_element("id", "fps").get_attribute("data-frames"))
    fps = (f1 - f0) / (time.monotonic() - t0)
    draw_ms = float(drv.find_element("id", "fps").get_attribute("data-draw-ms"))
    return fps, draw_ms, drv.execute_script("return S.scan.ranges.length")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=200, help="key presses measured (default 200)")
    ap.add_argument("--seconds", type=float, default=10.0,
                    help="how long the frame rate is counted (default 10)")
    args = ap.parse_args()
    started = []
    srv = _server_factory(started)("room")
    console = ConsoleProcess(srv.endpoint)
    drv = None
    try:
        url = console.wait_url()
        with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
            cmds = _Commands(session)
            drv = chromium()
            drv.get(url)
            end = time.monotonic() + 20
            while not drv.find_element("id", "pose").get_attribute("data-scan"):
                if time.monotonic() > end:
                    raise SystemExit("the page shows no scan")
                time.sleep(0.05)
            p, r = key_latency(drv, cmds, args.n)
            cmds.sub.undeclare()
            fps, draw_ms, beams = frame_rate(drv, args.seconds)
        print(f"key press -> VelCmd on the bus ({args.n} presses): p50 {np.percentile(p, 50):.2f} "
              f"ms, p99 {np.percentile(p, 99):.2f} ms")
        print(f"key release -> stop command: p50 {np.percentile(r, 50):.2f} ms, "
              f"p99 {np.percentile(r, 99):.2f} ms")
        print(decision_cost())
        print(f"page frame rate with {beams}-beam scans at 10 Hz: {fps:.1f} frames/s over "
              f"{args.seconds:g} s, {draw_ms:.2f} ms to draw a frame")
    finally:
        if drv is not None:
            close_chromium(drv)
        console.stop()
        for s in started:
            s.stop()
    return 0

if __name__ == "__main__":
    sys.exit(main())
