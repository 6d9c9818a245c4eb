"""The sphere radii docs/studies/margin-radius.md compared, as learners of the peer benchmark
(``bench_peers.py``: the same demonstrations, the same closed-loop runs, its options), kept for
that study (the product has two: the paper's radius and ``radius="margin"``).

Each learner fits the vectors the scripted expert taught (``rhbl train --behaviour``'s), in
their order, with the recipe's tree parameters but the radius:

    rhbl-parent       the paper's: a sphere as large as its parent allows
    margin-root       bounded by its margin (the nearest vector of another label, all of them),
                      but the root answers what no other sphere encloses (the paper's rule)
    margin-answer     bounded by its margin, the nearest centre answering what only the root
                      encloses, but learned by the paper's rule (there the root's label is
                      taken for right)
    margin-x2         as margin-answer, bounded by twice its margin
    margin-past       as margin-answer, bounded by its margin among the vectors before it only
                      (online)
    margin-centres    as margin-answer, bounded by the nearest centre of another label in the
                      tree (an RCE network's prototypes)

(``rhbl``, the benchmark's own, is the product: ``radius="margin"``.) ``--agreement DIR``: instead
of driving, how often each learner gives the expert's own label on fresh demonstrations of the
worlds in DIR (the development worlds: ``rhbl generate rooms --seed 1000 --out DIR``).

    python benchmarks/study_margin.py --behaviour wall-following --seeds 0,1,2 \\
        --learners rhbl,rhbl-parent,margin-root --eval-world DEV1 --eval-world DEV2 ...
    python benchmarks/study_margin.py --behaviour maze --seeds 0 --agreement /tmp/dev-mazes
"""

from __future__ import annotations

import glob
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_peers as peers  # noqa: E402

from rhbl import HypersphereClassifier  # noqa: E402
from rhbl._kernels import _better, _candidates, _jit  # noqa: E402
from rhbl._layout import DEPTH, FIRST, LABEL, LAST, NEXT, PARENT  # noqa: E402
from rhbl.tree import SphereTree, margins  # noqa: E402

VARIANTS = {
    "rhbl-parent": "the paper's radius",
    "margin-root": "bounded by the margin, the root answering",
    "margin-answer": "bounded by the margin, the nearest centre answering (learned by the "
                     "paper's rule)",
    "margin-x2": "bounded by twice the margin, the nearest centre answering (learned by the "
                 "paper's rule)",
    "margin-past": "bounded by the margin among the vectors before it, the nearest centre "
                   "answering",
    "margin-centres": "bounded by the nearest centre of another label, the nearest centre "
                      "answering",
}


@_jit
def _online_learn(table, X, labels, winner_only, past):
    """``rhbl._kernels.learn`` (no growth limits, a table large enough) with each spawn bounded
    by the nearest earlier row of another label (``past``) or the nearest centre of another
    label in the tree: the two online bounds."""
    tf = table.view(np.float64)
    capacity = table.shape[0]
    rc = X.shape[1]
    c_parent, c_depth, c_label = rc + 1 + PARENT, rc + 1 + DEPTH, rc + 1 + LABEL
    c_first, c_next, c_last = rc + 1 + FIRST, rc + 1 + NEXT, rc + 1 + LAST
    stack = np.empty(capacity, dtype=np.int64)
    dstack = np.empty(capacity)
    cand = np.empty(capacity, dtype=np.int64)
    cand_d = np.empty(capacity)
    n = 1
    for row in range(X.shape[0]):
        x = X[row]
        a = labels[row]
        count = _candidates(table, x, 1e-9, False, stack, dstack, cand, cand_d)
        if winner_only:
            w = 0
            for j in range(1, count):
                if _better(tf, table, cand[j], cand[w], rc):
                    w = j
            cand[0], cand_d[0] = cand[w], cand_d[w]
            count = 1
        cap = -1.0
        for j in range(count):
            p = cand[j]
            if table[p, c_label] == a:
                continue
            if cand_d[j] <= 1e-9:
                table[p, c_label] = a
                continue
            if cap < 0.0:
                cap = np.inf
                m = row if past else n
                for i in range(m):
                    if (labels[i] if past else table[i, c_label]) == a:
                        continue
                    s = 0.0
                    for k in range(rc):
                        t = (X[i, k] if past else tf[i, k]) - x[k]
                        s += t * t
                    cap = min(cap, s)
            r = max(min(tf[p, rc] - cand_d[j], cap), 0.0)
            for k in range(rc):
                tf[n, k] = x[k]
            tf[n, rc] = r
            table[n, rc + 1:] = -1
            table[n, c_parent] = p
            table[n, c_depth] = table[p, c_depth] + 1
            table[n, c_label] = a
            if table[p, c_first] < 0:
                table[p, c_first] = n
            else:
                table[table[p, c_last], c_next] = n
            table[p, c_last] = n
            n += 1
    return n


def variant(name: str, recipe, X: np.ndarray, y: np.ndarray, default: str
            ) -> HypersphereClassifier:
    """The tree of variant ``name`` on ``(X, y)`` with ``recipe``'s tree parameters (the root
    labelled ``default``)."""
    params = {"default_label": default, **recipe.tree_params(), "radius": "parent"}
    clf = HypersphereClassifier(**params).fit(X[:0], y[:0])
    labels = np.array(clf._intern_all(list(y)), dtype=np.int64)
    if name == "rhbl-parent":
        clf._learn(X, labels)
        return clf
    nearest = name != "margin-root"
    if name in ("margin-root", "margin-answer", "margin-x2"):
        caps = margins(X, labels) * (4.0 if name == "margin-x2" else 1.0)  # squared units
        clf._learn(X, labels, caps)
        tree = clf.tree_
    else:
        tree = SphereTree(X.shape[1], 0, distance="squared", eps=1e-9)
        tree._allocate(len(X) + 1)
        tree._table[0] = clf.tree_._table[0]
        tree.node_count = _online_learn(tree._table, np.ascontiguousarray(X), labels,
                                        params.get("spawn") == "winner", name == "margin-past")
        tree.height = int(tree._depth[:tree.node_count].max())
        tree._link(tree.node_count)
        tree._changed()
    arr = tree.to_arrays()
    spheres = SphereTree.from_arrays(**arr, distance="squared", eps=1e-9,
                                     uncovered="nearest" if nearest else "root")
    return HypersphereClassifier.from_tree(spheres, clf.classes_.tolist(), **{
        **params, "radius": "margin" if nearest else "parent"})


_fit = peers.fit


def fit(name, X, y, recipe, seed, learner):
    """bench_peers.fit with the study's variants."""
    if name not in VARIANTS:
        return _fit(name, X, y, recipe, seed, learner)
    from client.behaviour.learning import TreePolicy

    t0 = time.perf_counter()
    clf = variant(name, recipe, X, y, learner.actions.names[0])
    return (TreePolicy(clf, learner.features, learner.actions), time.perf_counter() - t0,
            int(clf.node_count_), clf)


def agreement(behaviour: str, folder: str, seeds: list[int], learners: list[str]) -> None:
    """Print how often each learner gives the expert's label on fresh demonstrations (the
    quick recipe, no randomised worlds, seed 77) of every world file in ``folder``."""
    from lab.behaviours import get, recipe_of
    from lab.harness import make_learner
    from lab.train import train
    from server.worldfile import load_world

    b = get(behaviour)
    quick = recipe_of(b).replace(**peers.QUICK, round_generated=0)
    tests = []
    for path in sorted(glob.glob(str(Path(folder) / "*.toml"))):
        lr = make_learner(quick, record=True)
        train(load_world(path), lr, quick, seed=77, behaviour=b)
        tests.append(lr.recorded())
    Xt = np.concatenate([t[0] for t in tests])
    yt = np.concatenate([t[1] for t in tests])
    print(f"{behaviour}: {len(Xt)} fresh vectors in {len(tests)} worlds of {folder}")
    for seed in seeds:
        learner, X, y, recipe = peers.demonstrations(b, seed)
        for name in learners:
            _, _, size, model = fit(name, X, y, recipe, seed, learner)
            got = np.asarray(model.predict(Xt)).astype(str)
            print(f"  seed {seed} {name}: {np.mean(got == yt):.2%} agreement, size {size}",
                  flush=True)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    peers.LEARNERS.update(VARIANTS)
    peers.fit = fit
    if "--agreement" in argv:
        i = argv.index("--agreement")
        folder = argv[i + 1]
        del argv[i:i + 2]
        args = peers._parser().parse_args(argv)
        for bname in args.behaviour:
            agreement(bname, folder, args.seeds, args.learners)
        return 0
    return peers.main(argv)


if __name__ == "__main__":
    sys.exit(main())
