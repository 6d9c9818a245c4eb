"""Practice speed: closed-loop episodes per second where ``lab.practice`` runs them.

    python benchmarks/bench_practice.py [--behaviour wall-following] [--tree T] [--episodes 48]
                                        [--seconds 120] [--cluster-workers 2,4]

The same episode tasks (a tree of ``rhbl train --behaviour B``, trained here unless ``--tree``,
driving from the teaching world's start poses, seeds 0..N-1, traced as ``rhbl refine`` traces
them) run: in this process; on a process per core (``Runner()``, what ``rhbl evaluate`` and
``rhbl refine`` use by default); on a local Dask cluster of each ``--cluster-workers`` count
(one thread per worker, started here on 127.0.0.1: what ``--cluster ADDRESS`` talks to). Each
is timed after one warm-up round (the processes started, the kernels loaded), and printed side
by side: episodes/s, sim seconds per wall second, and the speed-up over serial. The results must
be the same everywhere (checked: the script fails otherwise).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client.behaviour.learning import TreePolicy  # noqa: E402
from lab.behaviours import get, recipe_of, teaching_world  # noqa: E402
from lab.harness import make_learner  # noqa: E402
from lab.practice import EpisodeTask, Runner, cores, tree_bytes  # noqa: E402
from lab.train import train  # noqa: E402


def _tree(behaviour: str) -> Path:
    b = get(behaviour)
    learner = make_learner(recipe_of(b))
    train(teaching_world(b), learner, recipe_of(b), seed=0, behaviour=b)
    path = Path(tempfile.mkdtemp(prefix="bench-practice-")) / "tree.rhbl"
    learner.save(path)
    return path


def _judged(results):
    return [(r["success"], r["metrics"], r["steps"]) for r in results]


def _timed(runner: Runner, tasks) -> tuple[float, list]:
    runner.map(tasks[: max(1, runner.workers)])  # warm-up: processes up, kernels loaded
    t0 = time.perf_counter()
    out = runner.map(tasks)
    return time.perf_counter() - t0, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--behaviour", default="wall-following")
    ap.add_argument("--tree", default=None, help="a snapshot (default: trained here)")
    ap.add_argument("--episodes", type=int, default=48)
    ap.add_argument("--seconds", type=float, default=None,
                    help="sim seconds per episode (default: the behaviour's time limit)")
    ap.add_argument("--cluster-workers", default="2",
                    help="local Dask clusters of these worker counts (comma list; '' none)")
    args = ap.parse_args()
    b = get(args.behaviour)
    tree = Path(args.tree) if args.tree else _tree(args.behaviour)
    data = tree_bytes(TreePolicy.load(tree))
    starts = teaching_world(b).start_poses
    seconds = args.seconds or b.seconds
    tasks = [EpisodeTask(b.name, b.teach[0], data, starts[k % len(starts)], seed=k,
                         seconds=seconds, trace=True) for k in range(args.episodes)]
    rows = []
    with Runner(workers=1) as r:
        wall, serial = _timed(r, tasks)
    rows.append(("serial (this process)", 1, wall))
    with Runner() as r:
        wall, out = _timed(r, tasks)
    assert _judged(out) == _judged(serial), "the pool's results differ from serial"
    rows.append((f"process pool, every core ({cores()})", cores(), wall))
    counts = [int(v) for v in args.cluster_workers.split(",") if v.strip()]
    if counts:
        from distributed import LocalCluster

        for n in counts:
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                              host="127.0.0.1", dashboard_address=None) as cluster, \
                    Runner(cluster=cluster.scheduler_address) as r:
                r.workers = n  # the warm-up's size
                wall, out = _timed(r, tasks)
            assert _judged(out) == _judged(serial), f"the {n}-worker cluster's results differ"
            rows.append((f"local Dask cluster, {n} workers", n, wall))
    base = rows[0][2]
    print(f"{args.episodes} episodes of {seconds:g} sim s ({b.name}, tree {tree}, "
          f"{TreePolicy.load(tree).classifier.node_count_} nodes); this machine: {cores()} "
          f"cores; results identical everywhere")
    print("| where | workers | wall s | episodes/s | sim s per wall s | speed-up |")
    print("|---|---|---|---|---|---|")
    for name, n, wall in rows:
        print(f"| {name} | {n} | {wall:.2f} | {args.episodes / wall:.2f} | "
              f"{args.episodes * seconds / wall:.0f} | {base / wall:.2f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
