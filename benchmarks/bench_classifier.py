"""Benchmark: the RHBL hypersphere tree against its numpy reference and scikit-learn.

    python benchmarks/bench_classifier.py           # full run (several minutes)
    python benchmarks/bench_classifier.py --quick   # trees up to 10k spheres, fewer repeats
    python benchmarks/bench_classifier.py --check   # exit 1 if a target is missed
    python benchmarks/bench_classifier.py --wall-only --repeat 5   # the issue's targets only

Every figure is measured in the same run, on the same machine, the peers' calls alternating:

* the wall tree that ``rhbl train --world room --seconds 1200 --rounds 0 --starts world``
  writes (trained first, or ``--wall-tree SNAPSHOT``), 5000 queries near its centres: one query
  and a batch of 5000 for rhbl (compiled: a batch in ``RHBL_THREADS`` threads, and in one),
  rhbl's compiled descent on the node table (``rhbl node tab``: the search before the search
  table, which a tree that has just changed uses), rhbl's numpy reference (``compiled=False``,
  the code before the kernels), scikit-learn's ``KNeighborsClassifier(1)`` (kd-tree on one
  thread, its default, and with ``n_jobs`` as many as rhbl's threads; brute force, on
  scikit-learn's OpenMP threads) and ``BallTree`` on the same centres with the spheres'
  labels; the threads each used are printed; spheres visited per query. Targets: one query at
  most 3 us, a batch of 5000 at least 5x faster than the kd-tree 1-NN (its default, one
  thread; the ratios thread for thread are printed beside it);
* scaling: trees of 1k, 10k and 100k spheres grown from noisy labels (6 features, 10% of the
  labels flipped): one query, batches of 1, 100 and 10,000, learning per vector (a batch, and
  one vector at a time), spheres visited per query; the issue's noisy case (12,000 vectors);
* start-up: a fresh process importing rhbl, loading a snapshot, predicting once, with numba's
  cache empty and warm, and with the kernels compiled ahead of time;
* accuracy and speed on data sets (a synthetic 5-feature, 5-action set, scikit-learn's iris,
  wine and breast-cancer, min-max scaled to [0, 1]) beside 1-NN and a decision tree (median
  one-row latency, batch throughput of 20,000 queries, held-out accuracy).
The compaction section compares a tree with its compacted copies (``rhbl.compaction``: exact, and
pruned against the training labels); ``--tree SNAPSHOT --data FILE.npz`` adds a robot's tree
compacted on its recorded training vectors (arrays X, y).
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import rhbl.tree
from rhbl import HypersphereClassifier

ACTIONS = np.array(["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"])


def synthetic(m: int, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Vectors in [0, 1]^n labelled by the nearest of 5 fixed prototypes (a smooth teacher)."""
    protos = np.random.default_rng(1000 + n).random((5, n))
    X = np.random.default_rng(seed).random((m, n))
    return X, ACTIONS[np.argmin(((X[:, None, :] - protos) ** 2).sum(-1), axis=1)]


def sklearn_set(name: str) -> tuple[np.ndarray, np.ndarray]:
    from sklearn import datasets

    loader = {"iris": datasets.load_iris, "wine": datasets.load_wine,
              "breast-cancer": datasets.load_breast_cancer}[name]
    X, y = loader(return_X_y=True)
    lo, hi = X.min(axis=0), X.max(axis=0)
    return (X - lo) / np.where(hi > lo, hi - lo, 1.0), y


def split(X, y, seed, test=0.3):
    idx = np.random.default_rng(seed).permutation(len(X))
    k = int(len(X) * (1 - test))
    return X[idx[:k]], y[idx[:k]], X[idx[k:]], y[idx[k:]]


def queries(Xtest: np.ndarray, count: int, seed: int) -> np.ndarray:
    """Test rows resampled with a little jitter, clipped into the cube."""
    rng = np.random.default_rng(seed)
    Q = Xtest[rng.integers(0, len(Xtest), count)] + rng.normal(0, 0.01, (count, Xtest.shape[1]))
    return np.clip(Q, 0.0, 1.0)


def median_latency_us(call: Callable, rows: np.ndarray) -> float:
    call(rows[0])  # warm caches / lazy layouts
    times = []
    for row in rows:
        t = time.perf_counter_ns()
        call(row)
        times.append(time.perf_counter_ns() - t)
    return statistics.median(times) / 1e3


def best_of(fn: Callable, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def measure(name, make, Xtr, ytr, Xte, yte, Q, single_rows, repeat) -> dict:
    t = time.perf_counter()
    model = make().fit(Xtr, ytr)
    train = time.perf_counter() - t
    if isinstance(model, HypersphereClassifier):
        single = median_latency_us(model.predict_one, single_rows)
        size = f"{model.node_count_} sph, h {model.height_}"
    else:
        single = median_latency_us(lambda r: model.predict(r.reshape(1, -1)), single_rows)
        size = f"{model.tree_.node_count} nodes" if hasattr(model, "tree_") else f"{len(Xtr)} pts"
    batch = best_of(lambda: model.predict(Q), repeat)
    acc = float(np.mean(model.predict(Xte) == yte))
    return dict(model=name, size=size, train_ms=train * 1e3, single_us=single,
                batch_qps=len(Q) / batch, batch_ms=batch * 1e3, acc=acc)


def models(default):
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.tree import DecisionTreeClassifier

    return [
        ("rhbl literal", lambda: HypersphereClassifier(default)),
        ("rhbl winner", lambda: HypersphereClassifier(default, spawn="winner")),
        ("sklearn 1-NN", lambda: KNeighborsClassifier(n_neighbors=1)),
        ("sklearn tree", lambda: DecisionTreeClassifier(random_state=0)),
    ]


def print_table(title: str, rows: list[dict]) -> None:
    print(f"\n== {title}")
    print(f"{'model':<14} {'size':>18} {'train ms':>9} {'1-query us':>11} {'batch q/s':>11} "
          f"{'acc':>6}  {'1-query x1NN':>12} {'batch x1NN':>10}")
    knn = next(r for r in rows if r["model"] == "sklearn 1-NN")
    for r in rows:
        print(f"{r['model']:<14} {r['size']:>18} {r['train_ms']:>9.1f} {r['single_us']:>11.1f} "
              f"{r['batch_qps']:>11.0f} {r['acc']:>6.3f}  "
              f"{knn['single_us'] / r['single_us']:>12.1f} {r['batch_qps'] / knn['batch_qps']:>10.2f}")


# ---------------------------------------------------------------- rhbl against its peers
WALL_TRAIN = ["train", "--world", "room", "--seconds", "1200", "--rounds", "0", "--starts", "world",
              "--seed", "0"]


def rhbl_command() -> list[str]:
    """The ``rhbl`` command of this environment."""
    script = Path(sys.executable).with_name("rhbl")
    return [str(script)] if script.exists() else ["rhbl"]


def wall_tree(path: str | None) -> HypersphereClassifier:
    """The issue's tree: what ``rhbl train --world room --seconds 1200 --rounds 0 --starts world``
    writes (or the snapshot ``path``)."""
    from rhbl import load

    if path:
        return load(path)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "wall.rhbl"
        subprocess.run([*rhbl_command(), *WALL_TRAIN, "--out", str(out)], check=True,
                       stdout=subprocess.DEVNULL)
        return load(out)


def near(centers: np.ndarray, count: int, seed: int) -> np.ndarray:
    """Queries near the tree's centres: centres resampled with a jitter of 0.01, in the cube."""
    rng = np.random.default_rng(seed)
    Q = centers[rng.integers(0, len(centers), count)]
    return np.clip(Q + rng.normal(0, 0.01, Q.shape), 0.0, 1.0)


def per_call_us(call: Callable, rows: np.ndarray, repeat: int) -> float:
    """Best over ``repeat`` passes of the mean time of one call on each row (microseconds)."""
    call(rows[0])
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        for row in rows:
            call(row)
        best = min(best, (time.perf_counter() - t) / len(rows))
    return best * 1e6


class Peers:
    """rhbl (compiled and its numpy reference) and scikit-learn's 1-NN (kd-tree, brute force)
    and BallTree, all on the spheres' centres with the spheres' labels."""

    def __init__(self, clf: HypersphereClassifier) -> None:
        from sklearn.neighbors import BallTree, KNeighborsClassifier

        self.clf = clf
        self.ref = copy.deepcopy(clf).set_params(compiled=False)
        C = clf.tree_.centers.copy()
        y = clf.tree_.label.copy()
        self.labels = y
        self.kd = KNeighborsClassifier(n_neighbors=1, algorithm="kd_tree").fit(C, y)
        self.kd_brute = KNeighborsClassifier(n_neighbors=1, algorithm="brute").fit(C, y)
        self.threads = rhbl.tree.threads()
        self.kd_jobs = KNeighborsClassifier(n_neighbors=1, algorithm="kd_tree",
                                            n_jobs=self.threads).fit(C, y)
        self.ball = BallTree(C)
        self.names = ["rhbl", "rhbl 1 thread", "rhbl node tab", "rhbl numpy", "1-NN kd-tree",
                      f"kd {self.threads} jobs", "1-NN brute", "BallTree"]

    def _walk_one(self, x: np.ndarray):
        """The compiled descent on the node table (the search before the search table: what
        a tree that has just changed uses), one query, as ``predict_one`` calls it."""
        tree = self.clf.tree_
        i = rhbl.tree._kernels().winner(tree._table, tree.node_count, x, tree.eps,
                                        tree.distance == "euclidean")
        return self.clf.classes_[tree.label[i]]

    def _walk(self, Q: np.ndarray) -> np.ndarray:
        return self.clf.classes_[self.clf.tree_.label[self.clf.tree_._searched(
            Q, "descent", True, walk=True)[0]]]

    def _one_thread(self, Q: np.ndarray) -> np.ndarray:
        """``predict`` on the search table in the calling thread alone."""
        return self.clf.classes_[self.clf.tree_.label[self.clf.tree_._searched(
            Q, "auto", True, parts=1)[0]]]

    def one(self) -> dict[str, Callable]:
        """One query: ``predict_one`` for rhbl, ``predict``/``query`` of one row for the others."""
        return {"rhbl": self.clf.predict_one, "rhbl 1 thread": self.clf.predict_one,
                "rhbl node tab": self._walk_one,
                "rhbl numpy": self.ref.predict_one,
                "1-NN kd-tree": lambda r: self.kd.predict(r[None, :]),
                f"kd {self.threads} jobs": lambda r: self.kd_jobs.predict(r[None, :]),
                "1-NN brute": lambda r: self.kd_brute.predict(r[None, :]),
                "BallTree": lambda r: self.labels[self.ball.query(r[None, :], 1,
                                                                  return_distance=False)]}

    def batch(self) -> dict[str, Callable]:
        """A batch of rows: ``predict`` (rhbl, 1-NN), ``query`` then the label (BallTree)."""
        return {"rhbl": self.clf.predict, "rhbl 1 thread": self._one_thread,
                "rhbl node tab": self._walk, "rhbl numpy": self.ref.predict,
                "1-NN kd-tree": self.kd.predict, f"kd {self.threads} jobs": self.kd_jobs.predict,
                "1-NN brute": self.kd_brute.predict,
                "BallTree": lambda Q: self.labels[self.ball.query(Q, 1, return_distance=False)]}


def time_batches(peers: Peers, Q: np.ndarray, sizes: tuple[int, ...], repeat: int,
                 skip: set[str]) -> dict[str, dict[int, float]]:
    """Per peer and batch size: the best time of one ``predict`` call (ms); the calls of the
    peers alternate, so load on the machine falls on all of them alike."""
    calls = {k: v for k, v in peers.batch().items() if k not in skip}
    out: dict[str, dict[int, float]] = {k: {} for k in calls}
    for size in sizes:
        rows = Q[:size]
        for call in calls.values():
            call(rows)
        for _ in range(repeat):
            for name, call in calls.items():
                t = time.perf_counter()
                call(rows)
                dt = (time.perf_counter() - t) * 1e3
                out[name][size] = min(out[name].get(size, float("inf")), dt)
    return out


def check_same(peers: Peers, Q: np.ndarray) -> None:
    """The compiled and numpy searches give the same labels (else the figures mean nothing)."""
    got = peers.clf.predict(Q)
    if not np.array_equal(got, peers._walk(Q)):
        raise SystemExit("the searches on the search table and on the node table differ")
    if not np.array_equal(got, peers._one_thread(Q)):
        raise SystemExit("the searches in threads and in one thread differ")
    for algorithm in ("brute", "descent"):
        ref = peers.ref.set_params(algorithm=algorithm).predict(Q)
        if not np.array_equal(got, ref):
            raise SystemExit(f"compiled and numpy ({algorithm}) predictions differ")
    peers.ref.set_params(algorithm="auto")


def openmp_threads() -> int | str:
    """The OpenMP threads scikit-learn's compiled code runs (its brute-force 1-NN uses them)."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "?"
    return max((i["num_threads"] for i in threadpool_info() if i.get("user_api") == "openmp"),
               default="?")


def wall_run(args) -> bool:
    """The issue's measurement: the 1687-sphere wall tree, 5000 queries near its centres."""
    clf = wall_tree(args.wall_tree)
    tree = clf.tree_
    Q = near(tree.centers, 5000, seed=1)
    peers = Peers(clf)
    check_same(peers, Q)
    print(f"\n== the wall tree of `rhbl {' '.join(WALL_TRAIN[:-2])}` (seed 0): "
          f"{clf.node_count_} spheres, height {clf.height_}, {clf.n_features_in_} features; "
          f"queries near its centres; scikit-learn on the same centres")
    one = {name: per_call_us(call, Q[: args.single], args.repeat)
           for name, call in peers.one().items()}
    batch = time_batches(peers, Q, (5000,), args.repeat, skip=set())
    visits = tree.visits(Q)
    print(f"{'':<14} {'1 query us':>11} {'5000 ms':>9} {'x rhbl (5000)':>14}")
    for name in peers.names:
        print(f"{name:<14} {one[name]:>11.1f} {batch[name][5000]:>9.2f} "
              f"{batch[name][5000] / batch['rhbl'][5000]:>14.1f}")
    print(f"spheres visited per query (distance computed): mean {visits.mean():.1f}, "
          f"max {visits.max()} of {tree.node_count - 1}")
    # learning: a fresh tree (the recipe's spawn rule) on the tree's centres in creation order
    C, y = tree.centers[1:], clf.classes_[tree.label[1:]]
    params = {"default_label": clf.classes_[tree.label[0]], "spawn": clf.spawn}
    fast, single = learning_us(HypersphereClassifier(**params).fit(C[:1], y[:1]), C[1:], y[1:])
    slow, _ = learning_us(HypersphereClassifier(compiled=False, **params).fit(C[:1], y[:1]),
                          C[1:], y[1:], single=False)
    print(f"learning the {len(C)} centres afresh (spawn={clf.spawn!r}): rhbl {fast:.1f} us per "
          f"vector (one at a time {single:.1f} us), numpy reference {slow:.1f} us")
    jobs = f"kd {peers.threads} jobs"
    print(f"threads: rhbl {peers.threads} for a batch of {rhbl.tree.PARALLEL_BATCH} rows or more "
          f"(RHBL_THREADS), 1 otherwise ('rhbl 1 thread': always 1); '1-NN kd-tree' and "
          f"'BallTree' 1 (scikit-learn's default n_jobs=None); '{jobs}' n_jobs={peers.threads}; "
          f"'1-NN brute' {openmp_threads()} OpenMP threads (scikit-learn's own choice)")
    ok1 = one["rhbl"] <= 3.0
    ratio = batch["1-NN kd-tree"][5000] / batch["rhbl"][5000]
    ok2 = ratio >= 5.0
    print(f"batch of 5000: rhbl {batch['1-NN kd-tree'][5000] / batch['rhbl 1 thread'][5000]:.1f}x "
          f"faster than the kd-tree on one thread each, "
          f"{batch[jobs][5000] / batch['rhbl'][5000]:.1f}x on {peers.threads} each")
    print(f"target one query <= 3 us: {one['rhbl']:.1f} us: {'PASS' if ok1 else 'FAIL'}; "
          f"target batch of 5000 >= 5x 1-NN (kd-tree, scikit-learn's default): {ratio:.1f}x: "
          f"{'PASS' if ok2 else 'FAIL'}")
    return ok1 and ok2


MARGIN_TRAIN = ["train", "--behaviour", "wall-following", "--seed", "0"]


def margin_run(args) -> None:
    """One query of a margin tree (``radius="margin"``, ``rhbl train --behaviour``'s default):
    where only the root encloses a query, the sphere with the nearest centre answers, found
    by the compiled kernel (``predict_one``) or by scipy's k-d tree of the centres (the batch
    path, and one query's before the kernel); scikit-learn's 1-NN on the same centres beside.
    Queries near the centres (mostly enclosed) and uniform in the cube (mostly not)."""
    from sklearn.neighbors import KNeighborsClassifier

    from rhbl import load

    if args.margin_tree:
        clf = load(args.margin_tree)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "wall.rhbl"
            subprocess.run([*rhbl_command(), *MARGIN_TRAIN, "--out", str(out)], check=True,
                           stdout=subprocess.DEVNULL)
            clf = load(out)
    tree = clf.tree_
    if clf.get_params().get("radius") != "margin":
        raise SystemExit(f"--margin-tree: {args.margin_tree} is not a margin tree")
    rng = np.random.default_rng(2)
    sets = {"near the centres": near(tree.centers, args.single, seed=2),
            "uniform in the cube": rng.random((args.single, clf.n_features_in_))}
    knn = KNeighborsClassifier(n_neighbors=1, algorithm="kd_tree").fit(
        tree.centers[1:], tree.label[1:])
    tree._nearest(next(iter(sets.values())))  # the k-d tree built before timing

    def by_kd(x):  # predict_one as it was: the k-d tree for a query only the root encloses
        node = tree._enclosing_one(x, True)
        return tree.label[tree._nearest(x) if node == 0 else node]

    print(f"\n== a margin tree (`rhbl {' '.join(MARGIN_TRAIN)}`): {clf.node_count_} spheres, "
          f"height {clf.height_}, {clf.n_features_in_} features; one query, microseconds")
    print(f"{'queries':<22} {'only the root':>13} {'rhbl':>8} {'rhbl, k-d':>10} {'1-NN kd':>9}")
    for name, Q in sets.items():
        root = float(np.mean(tree._searched(Q, "auto", True)[0] == 0))
        want = [by_kd(q) for q in Q]
        got = [clf.classes_.tolist().index(clf.predict_one(q)) for q in Q]
        if got != want:  # both take the first of equally near centres
            wrong = sum(a != b for a, b in zip(got, want, strict=True))
            raise SystemExit(f"{name}: the kernel and the k-d tree answered {wrong} queries "
                             "otherwise")
        times = [per_call_us(f, Q, args.repeat) for f in
                 (clf.predict_one, by_kd, lambda q: knn.predict(q[None, :]))]
        print(f"{name:<22} {root:>13.0%} {times[0]:>8.1f} {times[1]:>10.1f} {times[2]:>9.1f}")


def noisy(m: int, n: int, flip: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Vectors labelled by the nearest of 5 prototypes, a fraction ``flip`` of labels random
    (noisy teaching: trees grow past the number of vectors)."""
    rng = np.random.default_rng(seed)
    X = rng.random((m, n))
    y = np.argmin(((X[:, None, :] - rng.random((5, n))) ** 2).sum(-1), axis=1)
    flipped = rng.random(m) < flip
    y[flipped] = rng.integers(0, 5, int(flipped.sum()))
    return X, y


def learning_us(clf: HypersphereClassifier, X: np.ndarray, y: np.ndarray,
                single: bool = True) -> tuple[float, float]:
    """Microseconds per vector: ``partial_fit`` of all rows at once, then (``single``) of one
    row at a time (what a learner does per labelled scan) on a copy of the tree."""
    one = copy.deepcopy(clf)
    t = time.perf_counter()
    clf.partial_fit(X, y)
    many = (time.perf_counter() - t) / len(X)
    if not single:
        return many * 1e6, float("nan")
    t = time.perf_counter()
    for i in range(len(X)):
        one.partial_fit(X[i : i + 1], y[i : i + 1])
    single = (time.perf_counter() - t) / len(X)
    return many * 1e6, single * 1e6


def scaling_run(args) -> None:
    """Trees of 1k, 10k and 100k spheres grown from noisy labels (6 features, 10% flipped)."""
    sizes = (1000, 10000) if args.quick else (1000, 10000, 100000)
    X, y = noisy(40000, 6, 0.1, seed=2)
    held, held_y = noisy(12000, 6, 0.1, seed=3)
    print("\n== scaling: trees from noisy labels (6 features, 10% of labels flipped), grown "
          "vector by vector; batches of queries near the centres; ms per call, best of "
          f"{args.repeat}")
    print(f"{'spheres':>8} {'height':>6} {'visited':>8} {'peer':<14} {'1 query us':>11} "
          f"{'batch 1 ms':>11} {'100 ms':>8} {'10,000 ms':>10} {'learn us/vec':>13} "
          f"{'one at a time':>13}")
    clf = HypersphereClassifier(0).fit(X[:1], y[:1])
    used = 1
    for size in sizes:
        while clf.node_count_ < size and used < len(X):
            clf.partial_fit(X[used : used + 50], y[used : used + 50])
            used += 50
        tree = clf.tree_
        Q = near(tree.centers, 10000, seed=size)
        peers = Peers(clf)
        check_same(peers, Q[:500])
        skip = {"rhbl numpy"} if size > 20000 else set()  # minutes at 100k spheres
        batch = time_batches(peers, Q, (1, 100, 10000), max(1, args.repeat - 1), skip)
        ref_batch = time_batches(peers, Q, (1, 100, 1000), 1, set(peers.names) - {"rhbl numpy"})
        one = {name: per_call_us(call, Q[: args.single // 4], 2)
               for name, call in peers.one().items()}
        visits = tree.visits(Q)
        n_learn = 2000
        fast = learning_us(copy.deepcopy(clf), held[:n_learn], held_y[:n_learn])
        slow = learning_us(copy.deepcopy(peers.ref), held[:200], held_y[:200])
        for name in peers.names:
            b = batch.get(name, {})
            big = f"{b[10000]:>10.2f}" if 10000 in b else \
                f"{ref_batch[name][1000] * 10:>9.0f}*"
            learn = {"rhbl": fast, "rhbl numpy": slow}.get(name)
            lcol = f"{learn[0]:>13.1f} {learn[1]:>13.1f}" if learn else f"{'':>13} {'':>13}"
            small = b if b else ref_batch[name]
            print(f"{tree.node_count:>8} {tree.height:>6} {visits.mean():>8.1f} {name:<14} "
                  f"{one[name]:>11.1f} {small[1]:>11.3f} {small[100]:>8.2f} {big} {lcol}")
    print("(* 10x the time of a batch of 1,000: the numpy reference is slow on large trees;\n"
          "visited: spheres whose distance the compiled descent computed, mean per query;\n"
          "learn: partial_fit of 2,000 new vectors at once (numpy: 200), then one at a time)")
    X, y = noisy(12000, 6, 0.1, seed=1)
    clf = HypersphereClassifier(0).fit(X[:1], y[:1])
    t = time.perf_counter()
    clf.partial_fit(X[1:], y[1:])
    dt = (time.perf_counter() - t) / (len(X) - 1)
    Q = near(clf.tree_.centers, 5000, seed=4)
    peers = Peers(clf)
    one = per_call_us(clf.predict_one, Q[: args.single], args.repeat)
    b = time_batches(peers, Q, (5000,), args.repeat, {"rhbl numpy", "1-NN brute", "BallTree"})
    print(f"the issue's noisy case, 12,000 vectors: {clf.node_count_} spheres, height "
          f"{clf.height_}, learning {dt * 1e6:.1f} us per vector, predict_one {one:.1f} us, "
          f"batch of 5000 {b['rhbl'][5000]:.2f} ms vs 1-NN kd-tree {b['1-NN kd-tree'][5000]:.2f} "
          f"ms ({b['1-NN kd-tree'][5000] / b['rhbl'][5000]:.1f}x)")


STARTUP = """
import sys, time
t0 = time.perf_counter()
import numpy as np
import rhbl
t1 = time.perf_counter()
clf = rhbl.loads(open(sys.argv[1], 'rb').read())
t2 = time.perf_counter()
clf.predict_one(np.full(clf.n_features_in_, 0.3))
t3 = time.perf_counter()
print((t1 - t0) * 1e3, (t2 - t1) * 1e3, (t3 - t2) * 1e3, 'numba' in sys.modules)
"""


def startup_run(args) -> None:
    """A fresh process: import rhbl, load a snapshot (the first tree built: the kernels loaded:
    numba imported and its kernels compiled or loaded from its cache, or the kernels compiled
    ahead of time), the first predict_one; numba's cache empty (cold), then filled (warm), then
    the kernels compiled ahead of time."""
    clf = HypersphereClassifier("a").fit(*noisy(300, 5, 0.0, seed=5))
    print("\n== start-up of a fresh process (ms): import numpy + rhbl, load a snapshot "
          "(the first tree: numba and the kernels), the first predict_one")
    print(f"{'':<34} {'import':>7} {'load':>7} {'first':>7} {'numba imported':>15}")
    with tempfile.TemporaryDirectory() as tmp:
        snap = Path(tmp) / "t.rhbl"
        clf.save(snap)
        cache = Path(tmp) / "numba-cache"
        jit = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "RHBL_KERNELS": "jit"}
        aot = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "RHBL_KERNELS": ""}
        for title, runs, env in (("numba cache empty (compiles)", 1, jit),
                                 ("numba cache warm, best of 3", 3, jit),
                                 ("ahead of time (setup.py), best of 3", 3, aot)):
            if env is aot and rhbl.tree._ahead_of_time() is None:
                print(f"{title:<34} not built (no C compiler when rhbl was installed)")
                continue
            best = None
            for _ in range(runs):
                out = subprocess.run([sys.executable, "-c", STARTUP, str(snap)], env=env,
                                     check=True, capture_output=True, text=True).stdout.split()
                figures = [float(v) for v in out[:3]]
                best = figures if best is None else [min(a, b) for a, b in zip(best, figures,
                                                                                strict=True)]
            print(f"{title:<34} {best[0]:>7.0f} {best[1]:>7.0f} {best[2]:>7.1f} {out[3]:>15}")


def compact_run(args, X, y, title: str, default) -> None:
    """Single-query predict of a tree and its compactions, against 1-NN on the tree's data."""
    from sklearn.neighbors import KNeighborsClassifier

    if isinstance(X, HypersphereClassifier):  # a given tree and the data it was trained on
        tree, (X, y) = X, y
    else:
        tree = HypersphereClassifier(default, spawn="winner").fit(X, y)
    Q = queries(X, max(args.single, 2000), seed=3)
    rows = [("uncompacted", tree), ("exact", tree.compact(X)),
            ("prune", tree.compact(X, y, method="prune")),
            ("prune 1%", tree.compact(X, y, method="prune", max_error=0.01)),
            ("bal. 53", tree.compact(X, y, method="prune", class_weight="balanced",
                                     max_nodes=53))]
    knn = KNeighborsClassifier(n_neighbors=1).fit(X, y)
    s_knn = median_latency_us(lambda r: knn.predict(r.reshape(1, -1)), Q[: args.single])
    print(f"\n== compaction: {title}; 1-NN on the same {len(X)} vectors: {s_knn:.1f} us")
    print(f"{'tree':<12} {'spheres':>8} {'height':>6} {'1-query us':>11} {'x1NN':>7} "
          f"{'x uncompacted':>13} {'agree with y':>12}")
    base = None
    for name, clf in rows:
        us = median_latency_us(clf.predict_one, Q[: args.single])
        base = base or us
        print(f"{name:<12} {clf.node_count_:>8} {clf.height_:>6} {us:>11.1f} {s_knn / us:>7.1f} "
              f"{base / us:>13.2f} {np.mean(clf.predict(X) == y):>12.3f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller sets, fewer repeats")
    parser.add_argument("--check", action="store_true", help="exit 1 if a target is missed")
    parser.add_argument("--tree", default=None, help="also compact this snapshot (needs --data)")
    parser.add_argument("--data", default=None, help="the tree's training vectors (.npz: X, y)")
    parser.add_argument("--wall-tree", default=None, metavar="SNAPSHOT",
                        help="the wall tree to measure (default: train it with rhbl train)")
    parser.add_argument("--wall-only", action="store_true",
                        help="only the wall tree's section (the issue's targets)")
    parser.add_argument("--margin-tree", default=None, metavar="SNAPSHOT",
                        help="the margin tree to measure (default: train it with rhbl train "
                             "--behaviour wall-following)")
    parser.add_argument("--margin-only", action="store_true",
                        help="only the margin tree's section (one query)")
    parser.add_argument("--repeat", type=int, default=None, metavar="N",
                        help="passes and batch calls, best of N (default 3; --quick 1)")
    args = parser.parse_args(argv)
    if args.repeat is not None and args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat}")
    if (args.tree is None) != (args.data is None):
        parser.error("--tree and --data go together")
    args.single = 100 if args.quick else 400
    if args.repeat is None:
        args.repeat = 1 if args.quick else 3
    n_batch = 5000 if args.quick else 20000
    m_syn = 1500 if args.quick else 4000

    import numba
    import sklearn

    print(f"numpy {np.__version__}, numba {numba.__version__}, scikit-learn "
          f"{sklearn.__version__}, python {sys.version.split()[0]}; one query = best of "
          f"{args.repeat} passes over {args.single} queries, mean per call; batches = best of "
          f"{args.repeat} calls")
    if args.margin_only:
        margin_run(args)
        return 0
    ok = wall_run(args)
    if args.wall_only:
        return 0 if (ok or not args.check) else 1
    scaling_run(args)
    startup_run(args)
    margin_run(args)

    sets = [("synthetic 5 features, 5 actions", *synthetic(m_syn, 5, seed=1), "fwd")]
    for name in ("iris", "wine", "breast-cancer"):
        X, y = sklearn_set(name)
        sets.append((f"{name} ({X.shape[1]} features)", X, y, int(y[0])))
    for title, X, y, default in sets:
        Xtr, ytr, Xte, yte = split(X, y, seed=0)
        Q = queries(Xte, n_batch, seed=2)
        rows = [measure(name, make, Xtr, ytr, Xte, yte, Q, Q[: args.single], args.repeat)
                for name, make in models(default)]
        print_table(f"{title}: train {len(Xtr)}, test {len(Xte)}; one query = median of "
                    f"{args.single} calls, batch of {n_batch}", rows)
    compact_run(args, *synthetic(m_syn, 5, seed=1), "synthetic 5 features, rhbl winner", "fwd")
    if args.tree:
        from rhbl import load

        with np.load(args.data) as d:
            data = (np.asarray(d["X"], dtype=np.float64), np.asarray(d["y"]).astype(str))
        compact_run(args, load(args.tree), data, f"{args.tree}", None)
    return 0 if (ok or not args.check) else 1


if __name__ == "__main__":
    sys.exit(main())
