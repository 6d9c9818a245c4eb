"""Benchmark: the RHBL hypersphere tree against scikit-learn's 1-NN and decision tree.

    python benchmarks/bench_classifier.py           # full run (about a minute)
    python benchmarks/bench_classifier.py --quick   # a fast run

Every figure is measured in the same run, on the same data and machine: training time,
single-query predict latency (median over individual calls; ``predict_one`` for rhbl,
``predict`` of one row for scikit-learn), batch predict throughput (20,000 queries) and
held-out accuracy. Data sets: a synthetic 5-feature, 5-action set, a 6-feature tree of about
400 spheres (the issue's speed targets), and scikit-learn's bundled iris, wine and
breast-cancer sets, min-max scaled to [0, 1]. Ratios are "how many times faster rhbl is".
The compaction section compares a tree with its compacted copies (``rhbl.compact``: exact, and
pruned against the training labels); ``--tree SNAPSHOT --data FILE.npz`` adds a robot's tree
compacted on its recorded training vectors (arrays X, y).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

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


def target_run(args) -> bool:
    """The issue's targets on a 6-feature tree of about 400 spheres."""
    from sklearn.neighbors import KNeighborsClassifier

    X, y = synthetic(20000, 6, seed=7)
    clf = HypersphereClassifier("fwd")
    clf.fit(np.zeros((0, 6)), [])
    used = 0
    while clf.node_count_ < 400:
        clf.learn_one(X[used], y[used])
        used += 1
    Xtr, ytr = X[:used], y[:used]
    Xte, yte = synthetic(2000, 6, seed=8)
    Q = queries(Xte, 20000, seed=9)
    knn = KNeighborsClassifier(n_neighbors=1).fit(Xtr, ytr)
    rows = Q[: args.single]
    s_tree = median_latency_us(clf.predict_one, rows)
    s_row = median_latency_us(lambda r: clf.predict(r.reshape(1, -1)), rows)
    s_knn = median_latency_us(lambda r: knn.predict(r.reshape(1, -1)), rows)
    b_tree = best_of(lambda: clf.predict(Q), args.repeat)
    b_knn = best_of(lambda: knn.predict(Q), args.repeat)
    print(f"\n== targets: 6 features, rhbl literal tree of {clf.node_count_} spheres "
          f"(height {clf.height_}) from {used} vectors; 1-NN on the same {used} vectors")
    ok1 = s_knn / s_tree >= 50
    ok2 = b_knn / b_tree >= 1
    print(f"single-query predict_one: rhbl {s_tree:.1f} us, 1-NN {s_knn:.1f} us -> "
          f"{s_knn / s_tree:.1f}x faster (target >= 50x, goal >= 100x): "
          f"{'PASS' if ok1 else 'FAIL'}")
    print(f"single-query predict (1 row): rhbl {s_row:.1f} us -> {s_knn / s_row:.1f}x faster")
    print(f"batch predict of {len(Q)}: rhbl {b_tree * 1e3:.1f} ms, 1-NN {b_knn * 1e3:.1f} ms -> "
          f"{b_knn / b_tree:.2f}x (target >= 1x, goal >= 2x): {'PASS' if ok2 else 'FAIL'}")
    print(f"accuracy on held-out: rhbl {clf.score(Xte, yte):.3f}, "
          f"1-NN {np.mean(knn.predict(Xte) == yte):.3f}")
    return ok1 and ok2


def scaling_run(args) -> None:
    """Single-query latency and training cost against tree size (6 features, literal)."""
    sizes = (400, 5000) if args.quick else (400, 5000, 50000)
    X, y = synthetic(80000, 6, seed=7)
    Q = queries(synthetic(2000, 6, seed=8)[0], 20000, seed=9)
    print("\n== scaling: 6 features, literal trees grown vector by vector (learn_one)")
    print(f"{'spheres':>8} {'height':>6} {'vectors':>8} {'train us/vector':>16} "
          f"{'predict_one us':>15} {'batch us/query':>15}")
    clf = HypersphereClassifier("fwd")
    clf.fit(np.zeros((0, 6)), [])
    used = 0
    for size in sizes:
        t = time.perf_counter()
        start = used
        while clf.node_count_ < size and used < len(X):
            clf.learn_one(X[used], y[used])
            used += 1
        train = (time.perf_counter() - t) / max(used - start, 1)
        single = median_latency_us(clf.predict_one, Q[: args.single])
        batch = best_of(lambda: clf.predict(Q), 1) / len(Q)
        print(f"{clf.node_count_:>8} {clf.height_:>6} {used:>8} {train * 1e6:>16.0f} "
              f"{single:>15.1f} {batch * 1e6:>15.2f}")


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
    args = parser.parse_args(argv)
    if (args.tree is None) != (args.data is None):
        parser.error("--tree and --data go together")
    args.single = 100 if args.quick else 400
    args.repeat = 1 if args.quick else 3
    n_batch = 5000 if args.quick else 20000
    m_syn = 1500 if args.quick else 4000

    import sklearn

    print(f"numpy {np.__version__}, scikit-learn {sklearn.__version__}, python "
          f"{sys.version.split()[0]}; single = median of {args.single} one-row calls, "
          f"batch = {n_batch} queries (best of {args.repeat})")
    ok = target_run(args)
    scaling_run(args)

    sets = [("synthetic 5 features, 5 actions", *synthetic(m_syn, 5, seed=1), "fwd")]
    for name in ("iris", "wine", "breast-cancer"):
        X, y = sklearn_set(name)
        sets.append((f"{name} ({X.shape[1]} features)", X, y, int(y[0])))
    for title, X, y, default in sets:
        Xtr, ytr, Xte, yte = split(X, y, seed=0)
        Q = queries(Xte, n_batch, seed=2)
        rows = [measure(name, make, Xtr, ytr, Xte, yte, Q, Q[: args.single], args.repeat)
                for name, make in models(default)]
        print_table(f"{title}: train {len(Xtr)}, test {len(Xte)}", rows)
    compact_run(args, *synthetic(m_syn, 5, seed=1), "synthetic 5 features, rhbl winner", "fwd")
    if args.tree:
        from rhbl import load

        with np.load(args.data) as d:
            data = (np.asarray(d["X"], dtype=np.float64), np.asarray(d["y"]).astype(str))
        compact_run(args, load(args.tree), data, f"{args.tree}", None)
    return 0 if (ok or not args.check) else 1


if __name__ == "__main__":
    sys.exit(main())
