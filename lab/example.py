"""``rhbl example``: a small end-to-end run of the hypersphere tree on synthetic data.

Five features in [0, 1] (think: five laser beams, clamped and scaled) and the five default
actions. A hidden "teacher" labels each vector with the action of its nearest prototype. The
example trains a tree, reports its size and accuracy, saves a snapshot, reloads it, extends
the reloaded tree with more demonstrations and checks that this equals training in one go.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from process import arguments
from rhbl import HypersphereClassifier, load

ACTIONS = ["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--vectors", type=arguments.Number(int, 2, 10**7, name="vectors"),
                        default=1500, help="training vectors (default 1500; 2 .. 10^7)")
    parser.add_argument("--seed", type=arguments.seed, default=0, help="random seed")
    parser.add_argument("--spawn", choices=["all", "winner"], default="all",
                        help="spawn rule: the paper's literal 'all' or the compact 'winner'")
    parser.add_argument("--distance", choices=["squared", "euclidean"], default="squared")
    parser.add_argument("--out", type=arguments.output_file, default=None,
                        help="snapshot path (default: a temporary file, removed afterwards)")


def make_data(m: int, rng: np.random.Generator, n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    protos = np.random.default_rng(12345).random((len(ACTIONS), n))
    X = rng.random((m, n))
    y = np.argmin(((X[:, None, :] - protos) ** 2).sum(-1), axis=1)
    return X, np.array(ACTIONS)[y]


def main(args: argparse.Namespace) -> int:
    rng = np.random.default_rng(args.seed)
    X, y = make_data(args.vectors, rng)
    Xt, yt = make_data(2000, rng)
    half = len(X) // 2
    params = dict(default_label="fwd", spawn=args.spawn, distance=args.distance)

    t0 = time.perf_counter()
    clf = HypersphereClassifier(**params).fit(X[:half], y[:half])
    t_train = time.perf_counter() - t0
    print(f"trained on {half} vectors in {t_train * 1e3:.0f} ms: "
          f"{clf.node_count_} spheres, height {clf.height_}, "
          f"test accuracy {clf.score(Xt, yt):.3f}")
    print("spheres per label:", clf.label_counts())

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(args.out) if args.out else Path(tmp) / "example.rhbl"
        clf.save(path, metadata={"task": "example", "vectors": half, "seed": args.seed})
        print(f"saved snapshot {path} ({path.stat().st_size} bytes)")
        again = load(path)
        assert again.tree_equal(clf), "reloaded tree differs"
        again.partial_fit(X[half:], y[half:])
        print(f"reloaded and extended with {len(X) - half} vectors: "
              f"{again.node_count_} spheres, height {again.height_}, "
              f"test accuracy {again.score(Xt, yt):.3f}")
        one_go = HypersphereClassifier(**params).fit(X, y)
        same = again.tree_equal(one_go)
        print(f"extended tree equals training in one go: {same}")

    x = Xt[0]
    path_info = again.decision_path(x)
    print(f"decision path of {np.round(x, 2).tolist()} -> {again.predict_one(x)!r}:")
    for node in path_info:
        print(f"  #{node['index']:<5d} depth {node['depth']:<3d} radius {node['radius']:.4f} "
              f"label {node['label']}")
    return 0 if same else 1
