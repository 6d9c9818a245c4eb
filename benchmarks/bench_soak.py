"""Soak: the full loop for a long time, sped up; memory of every process and file sizes sampled.

    python benchmarks/bench_soak.py [--minutes 30] [--speedup 5] [--out soak.csv]

Processes (real ``rhbl`` commands on loopback, as in ``rhbl demo``): a server (``--speedup``
times real time, room world), a learner (snapshots every 2 s, its journal folding into them, a
``--max-nodes`` cap so the tree itself is bounded), a teacher that demonstrates for 60 sim
seconds and then corrects (``--correct``), and a controller driving with the learner's latest
tree (``--from-learner --follow``). Every ``--every`` seconds one CSV row: wall seconds, each
process's resident memory (VmRSS, KiB, from /proc) and the size of every file in the learner's
folder (bytes). At the end: first and last rows, the maximum of each column over the second
half against the first half (bounded: the second half's maximum is not above the first's by
more than the stated tolerance), and the processes' exit statuses.

Meant to run in the background at low priority (``nice -n 19``); not part of the test suite.
"""

from __future__ import annotations

import argparse
import csv
import signal
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lab.children import Child, free_port, rhbl_argv  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    work = Path(args.dir) if args.dir else Path(tempfile.mkdtemp(prefix="rhbl-soak-"))
    work.mkdir(parents=True, exist_ok=True)
    tree = work / "tree.rhbl"
    procs: dict[str, Child] = {}
    try:
        _start(_commands(args, tree, f"tcp/127.0.0.1:{free_port()}"), procs, tree, work)
        rows = _sample_until_done(args, procs, work)
    finally:
        _stop(procs)
    _report(rows, procs, work)
    return 0


def _parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="wall minutes (30)")
    ap.add_argument("--speedup", type=float, default=5.0, help="server speed-up (5)")
    ap.add_argument("--every", type=float, default=30.0, help="seconds between samples (30)")
    ap.add_argument("--max-nodes", type=int, default=4000, help="learner's tree cap (4000)")
    ap.add_argument("--out", default="soak.csv", help="CSV of the samples (soak.csv)")
    ap.add_argument("--fold-journal", action="store_true",
                    help="the learner folds its journal into each snapshot")
    ap.add_argument("--dir", default=None, help="the learner's folder (default: a temp dir)")
    return ap.parse_args(argv)


def _commands(args: argparse.Namespace, tree: Path, endpoint: str) -> dict[str, list[str]]:
    """The four processes' ``rhbl`` arguments, in start order."""
    return {
        "server": ["server", "--world", "room", "--speedup", str(args.speedup), "--listen",
                   endpoint, "--log-level", "WARNING"],
        "learner": ["learner", "--features", "wall", "--out", str(tree), "--max-nodes",
                    str(args.max_nodes), *(["--fold-journal"] if args.fold_journal else []),
                    "--connect", endpoint, "--log-level", "WARNING"],
        "teacher": ["teacher", "--policy", "wall-follower", "--correct", "--demonstrate", "60",
                    "--connect", endpoint, "--log-level", "WARNING"],
        "controller": ["controller", "--from-learner", "--follow", "--connect", endpoint,
                       "--log-level", "WARNING"],
    }


def _start(cmds: dict[str, list[str]], procs: dict[str, Child], tree: Path, work: Path) -> None:
    """Start each process in order (into ``procs``, so that a failure stops those started)."""
    for name, argv_ in cmds.items():
        if name == "controller":  # it needs the learner's first snapshot
            deadline = time.monotonic() + 300
            while not tree.exists() and time.monotonic() < deadline:
                time.sleep(0.5)
        procs[name] = Child(name, rhbl_argv(*argv_), work, cwd=ROOT,
                            stop_signal=signal.SIGINT, stop_timeout=30.0,
                            escalate=False).start()
        time.sleep(2.0 if name == "server" else 0.5)


def _sample_until_done(args: argparse.Namespace, procs: dict[str, Child], work: Path) -> list[dict]:
    """One CSV row every ``--every`` seconds until ``--minutes`` or a process exits."""
    t0 = time.monotonic()
    rows = []
    files: list[str] = []
    with open(args.out, "w", newline="") as f:
        w = None
        while True:
            now = time.monotonic() - t0
            row = _sample(now, procs, work, files)
            rows.append(row)
            if w is None or set(row) != set(w.fieldnames):
                w = csv.DictWriter(f, fieldnames=list(row))
                w.writeheader()
            w.writerow(row)
            f.flush()
            dead = [n for n, p in procs.items() if p.poll() is not None]
            if dead or now >= args.minutes * 60:
                break
            time.sleep(args.every)
    return rows


def _sample(now: float, procs: dict[str, Child], work: Path, files: list[str]) -> dict:
    """A row: the time, each process's memory, the size of every file seen so far (``files``,
    in order of appearance)."""
    sizes = {p.name: p.stat().st_size for p in sorted(work.iterdir())
             if p.is_file() and not p.name.endswith(".log")}
    for name in sizes:
        if name not in files:
            files.append(name)
    row = {"seconds": round(now, 1)}
    row.update({f"rss_kib_{n}": p.rss_kib() for n, p in procs.items()})
    row.update({f"bytes_{n}": sizes.get(n, 0) for n in files})
    return row


def _stop(procs: dict[str, Child]) -> None:
    # the teacher first: it waits for the learner to acknowledge its last labels (its
    # outbox); then the others, all asked at once, each waited for (SIGKILL after 30 s)
    if "teacher" in procs:
        procs["teacher"].stop()
    for p in procs.values():
        p.send_signal(signal.SIGINT)
    for p in procs.values():
        p.stop()


def _report(rows: list[dict], procs: dict[str, Child], work: Path) -> None:
    print(f"soak: {len(rows)} samples over {rows[-1]['seconds']:.0f} s, folder {work}")
    half = len(rows) // 2
    for key in rows[-1]:
        if key == "seconds":
            continue
        first = [r.get(key, 0) for r in rows[:half] if r.get(key, 0) >= 0] or [0]
        second = [r.get(key, 0) for r in rows[half:] if r.get(key, 0) >= 0] or [0]
        print(f"  {key}: first half max {max(first)}, second half max {max(second)}, "
              f"last {rows[-1].get(key)}")
    print("  exit statuses: " + ", ".join(f"{n} {p.poll()}" for n, p in procs.items()))


if __name__ == "__main__":
    sys.exit(main())
