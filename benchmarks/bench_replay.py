"""Benchmark: ``rhbl replay``'s memory against the size of the recording it plays.

    python benchmarks/bench_replay.py                        # 2,000,000 messages
    python benchmarks/bench_replay.py --messages 200000      # quicker
    python benchmarks/bench_replay.py --peer DIR             # also another checkout, same file

Writes one recording of N small state messages (one robot), then plays it at full speed
(``--speed 0 --wait-subscriber 0``, a zenoh peer on a free loopback port, nobody subscribed)
with this checkout's ``rhbl replay`` and, with ``--peer DIR``, with the checkout at DIR (for
a before/after figure in one run), and prints each run's peak resident memory (the child's
``ru_maxrss``), wall time and exit code.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def write_recording(path: Path, n: int) -> None:
    from client.recording.mcap_file import RecordingWriter
    from protocol import keys
    from protocol import messages as m

    key = keys.state_key("r0")
    with RecordingWriter(path, viewer=False, chunk_seconds=1e9) as w:
        for k in range(n):
            w.write(key, m.State(ts=k * 0.1, seq=k, pos=(0.0, 0.0, 0.0)).encode(),
                    1_000_000_000 + k * 1000, kind="state", robot="r0", sim_time=k * 0.1)


def play(checkout: Path, rec: Path, port: int) -> tuple[int, float, float]:
    """(exit code, peak RSS MiB, wall s) of ``rhbl replay`` from ``checkout``."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    t0 = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, "-m", "lab.cli", "replay", str(rec), "--speed", "0",
         "--wait-subscriber", "0", "--mode", "peer", "--listen", f"tcp/127.0.0.1:{port}",
         "--log-level", "WARNING"], cwd=checkout, env=env, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    return child.returncode, usage.ru_maxrss / 1024, wall


def main() -> int:
    from lab.children import free_port

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=2_000_000)
    ap.add_argument("--peer", type=Path, default=None,
                    help="another checkout to run side by side (e.g. the code before)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "big.mcap"
        t0 = time.perf_counter()
        write_recording(rec, args.messages)
        print(f"recording: {args.messages} messages, {rec.stat().st_size / 2**20:.1f} MiB "
              f"(written in {time.perf_counter() - t0:.0f} s)")
        runs = [("this checkout", ROOT)] + ([("peer " + str(args.peer), args.peer)]
                                            if args.peer else [])
        for name, checkout in runs:
            code, rss, wall = play(checkout, rec, free_port())
            print(f"{name}: rhbl replay peak RSS {rss:.0f} MiB, {wall:.0f} s, exit {code}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
