"""Benchmark: the start-up of every ``rhbl`` command, this checkout beside another revision.

    python benchmarks/bench_startup.py                  # against e5b649a (before issue 24 B)
    python benchmarks/bench_startup.py --before REV     # against another revision
    python benchmarks/bench_startup.py --train          # also rhbl train end to end

A command's start-up here is what a fresh process pays before it can serve: the interpreter,
the imports of the command (``lab.cli.build_parser``: the command's module and what it imports)
and the compiled kernels it loads at start (the server's laser: a ``World``; the learner's and
the controller's tree: ``rhbl.tree.load_kernels``; train and evaluate: both). Not counted:
connecting to zenoh and the work itself. Each figure is the best of ``--repeat`` fresh
processes, the revisions alternating (load on the machine falls on both alike), after one
unmeasured run of each (numba's cache filled). The revision before is a ``git archive`` of
``--before`` run from a temporary folder with this environment's packages (PYTHONPATH first).
Rows: ``before`` (that revision), ``after`` (this checkout as installed: kernels compiled ahead
of time where setup.py could), ``after, numba`` (this checkout with ``RHBL_KERNELS=jit``).

``--train`` also times ``rhbl train --world room --seconds 1200 --rounds 0 --starts world``
(wall clock of the whole process, start-up included, and the time its learner spends in the
tree per vector) and checks that both revisions wrote the same tree.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# command -> the kernels it loads at start ("laser", "tree")
COMMANDS = {
    "server": ("laser",), "learner": ("tree",), "controller": ("tree",), "teacher": (),
    "console": (), "train": ("laser", "tree"), "evaluate": ("laser", "tree"), "record": (),
    "replay": (), "inspect": (), "foxglove": (),
}
CODE = """
import sys
from lab.cli import build_parser
build_parser(sys.argv[1])
if "laser" in sys.argv[2:]:
    import server
    from server.world import World, load_world
    World(load_world(server.world_path("room")))
if "tree" in sys.argv[2:]:
    import rhbl.tree
    rhbl.tree.load_kernels()
"""
TRAIN = ("train", "--world", "room", "--seconds", "1200", "--rounds", "0", "--starts", "world",
         "--seed", "0")
# rhbl train, timing the learner's calls into the tree (e5b649a: a partial_fit per vector in
# _learn; now: the queue's partial_fit in _flush); prints the seconds spent there
TRAIN_CODE = """
import sys, time
from client.behaviour import learning
cls = learning.DemonstrationLearner
name = "_flush" if hasattr(cls, "_flush") else "_learn"
inner, spent = getattr(cls, name), [0.0]
def timed(self, *a):
    t = time.perf_counter()
    inner(self, *a)
    spent[0] += time.perf_counter() - t
setattr(cls, name, timed)
from lab.cli import main
main(sys.argv[1:])
print("learning", spent[0])
"""


def _env(source: Path | None, jit: bool = False) -> dict:
    env = dict(os.environ)
    if source is not None:
        env["PYTHONPATH"] = str(source) + os.pathsep + env.get("PYTHONPATH", "")
    env["RHBL_KERNELS"] = "jit" if jit else ""
    return env


def _seconds(argv: list[str], env: dict, cwd: Path) -> float:
    return _run(argv, env, cwd)[0]


def _run(argv: list[str], env: dict, cwd: Path) -> tuple[float, str]:
    """(wall-clock seconds, standard output) of a fresh process."""
    t = time.perf_counter()
    done = subprocess.run(argv, env=env, cwd=cwd, check=True, stdout=subprocess.PIPE,
                          stderr=subprocess.DEVNULL, text=True)
    return time.perf_counter() - t, done.stdout


def _archive(rev: str, into: Path) -> Path:
    with tempfile.TemporaryFile() as tar:
        subprocess.run(["git", "archive", rev], cwd=ROOT, stdout=tar, check=True)
        tar.seek(0)
        with tarfile.open(fileobj=tar) as t:
            t.extractall(into, filter="data")
    return into


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", default="e5b649a", help="the revision to compare with")
    parser.add_argument("--repeat", type=int, default=5, help="fresh processes per figure")
    parser.add_argument("--train", action="store_true", help="also time rhbl train")
    args = parser.parse_args(argv)
    import rhbl.tree
    import server.laser

    with tempfile.TemporaryDirectory() as tmp:
        before = _archive(args.before, Path(tmp) / "before")
        rows = {"before": (_env(before), before), "after": (_env(None), ROOT),
                "after, numba": (_env(None, jit=True), ROOT)}
        print(f"start-up of a fresh process (s, best of {args.repeat}): python, the command's "
              f"imports, the kernels it loads at start; before = {args.before}; after: tree "
              f"kernels {rhbl.tree.load_kernels()}, laser {server.laser.kernels_origin()}")
        print(f"{'command':<11} {'kernels':<11}" + "".join(f"{r:>14}" for r in rows))
        for command, kernels in COMMANDS.items():
            call = [sys.executable, "-c", CODE, command, *kernels]
            best = {}
            for env, cwd in rows.values():
                _seconds(call, env, cwd)  # numba's cache filled, files in the page cache
            for _ in range(args.repeat):
                for name, (env, cwd) in rows.items():
                    best[name] = min(best.get(name, float("inf")), _seconds(call, env, cwd))
            print(f"{command:<11} {'+'.join(kernels) or '-':<11}"
                  + "".join(f"{best[r]:>14.2f}" for r in rows))
        if args.train:
            _train(rows, Path(tmp), args.repeat)
    return 0


def _train(rows: dict, tmp: Path, repeat: int) -> None:
    """``rhbl train`` end to end, the revisions alternating; the trees compared."""
    import numpy as np

    import rhbl

    times: dict[str, list[float]] = {name: [] for name in rows}
    learning: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(max(1, repeat // 2)):
        for name, (env, cwd) in rows.items():
            out = tmp / f"{name.replace(', ', '-')}.rhbl"
            seconds, text = _run([sys.executable, "-c", TRAIN_CODE, *TRAIN, "--out", str(out)],
                                 env, cwd)
            times[name].append(seconds)
            last = [ln for ln in text.splitlines() if ln.startswith("learning ")][-1]
            learning[name].append(float(last.split()[1]))
    trees = {name: rhbl.load(tmp / f"{name.replace(', ', '-')}.rhbl") for name in rows}
    vectors = trees["before"].n_seen_
    print(f"\nlearning on the product's path (rhbl train's DemonstrationLearner into the tree, "
          f"{vectors} vectors), us per vector: "
          + "; ".join(f"{name} {min(v) / vectors * 1e6:.1f}" for name, v in learning.items()))
    first = trees["before"]
    same = all(t.tree_equal(first) and all(
        np.array_equal(a, b) for a, b in zip(t.tree_.to_arrays().values(),
                                              first.tree_.to_arrays().values(), strict=True))
        for t in trees.values())
    print(f"\nrhbl {' '.join(TRAIN)} (1200 s simulated), wall clock of the process (s): "
          + "; ".join(f"{name} {min(v):.2f} (median {statistics.median(v):.2f}, "
                      f"{1200 / min(v):.0f}x real time)" for name, v in times.items()))
    print(f"the same tree ({first.node_count_} spheres) from every row: {same}")


if __name__ == "__main__":
    sys.exit(main())
