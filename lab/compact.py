"""``rhbl compact``: make an existing tree smaller, keeping what it does on its labelled vectors.

    rhbl compact --tree wall.rhbl --out wall-small.rhbl                  # data: wall.rhbl.journal
    rhbl compact --tree T --out T2 --data a.journal --data b.npz --method prune --max-error 0.01
    rhbl compact --tree T --out T2 --method prune --class-weight balanced --max-nodes 200

The data are the labelled vectors the tree should keep its behaviour on: learner journals
(``client.journal``; each record's scan is turned into features with the snapshot's own feature
spec) or ``.npz`` files with arrays ``X`` (feature vectors) and ``y`` (labels). ``--method exact``
keeps every prediction on them; ``--method prune`` deletes the weakest spheres against their
labels (``rhbl.compact``). The step is recorded in the snapshot's ``metadata["compaction"]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from client.behaviour.features import FeatureSpec
from client.behaviour.learning import load_snapshot
from client.journal import Journal, journal_path
from rhbl.compact import METHODS

__all__ = ["add_arguments", "load_data", "main"]


def load_data(path: str | Path, features: FeatureSpec) -> tuple[np.ndarray, np.ndarray]:
    """``(X, y)`` of a journal or an ``.npz`` file (ValueError naming the file if unusable)."""
    path = Path(path)
    if path.suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as d:
                X, y = np.asarray(d["X"], dtype=np.float64), np.asarray(d["y"]).astype(str)
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not an .npz with arrays X and y ({exc})") from None
        if X.ndim != 2 or X.shape[1] != features.dim or len(y) != len(X):
            raise ValueError(f"{path}: X has shape {X.shape} and y {len(y)} labels; the tree "
                             f"needs ({len(y)}, {features.dim})")
        return X, y
    j = Journal.open(path, readonly=True)
    try:
        rows, labels = [], []
        for rec in j.records():
            rows.append(features.extract(rec.ranges, rec.yaw))
            labels.append(rec.label)
    finally:
        j.close()
    return np.array(rows, dtype=np.float64).reshape(-1, features.dim), np.array(labels, dtype=str)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tree", required=True, help="snapshot to compact")
    parser.add_argument("--out", required=True, help="snapshot to write")
    parser.add_argument("--data", action="append", default=None, metavar="FILE",
                        help="labelled vectors: a learner journal or an .npz with X and y "
                             "(repeatable; default: the tree's journal TREE.journal)")
    parser.add_argument("--method", choices=METHODS, default="exact",
                        help="exact: keep every prediction on the data (default); prune: delete "
                             "the weakest spheres against the data's labels")
    parser.add_argument("--max-error", type=float, default=0.0,
                        help="prune: fraction of the rows whose errors the pruning may add (0)")
    parser.add_argument("--class-weight", choices=["balanced"], default=None,
                        help="prune: weigh each label's rows the same in total (rare labels, such "
                             "as a turn in place before a wall, are not pruned away as cheap)")
    parser.add_argument("--max-nodes", type=int, default=None,
                        help="prune: delete the weakest spheres until at most this many are left")


def main(args) -> int:
    clf, features, _actions, _meta = load_snapshot(args.tree)
    files = args.data or [str(journal_path(args.tree))]
    if not args.data and not Path(files[0]).exists():
        raise ValueError(f"no data to compact {args.tree} on: {files[0]} does not exist "
                         "(give --data JOURNAL or --data FILE.npz)")
    parts = [load_data(f, features) for f in files]
    X = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    small = clf.compact(X, y, method=args.method, max_error=args.max_error,
                        max_nodes=args.max_nodes, class_weight=args.class_weight,
                        data=", ".join(Path(f).name for f in files))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    small.save(out)
    rec = small.metadata["compaction"][-1]
    agree = float(np.mean(small.predict(X) == y)) if len(y) else float("nan")
    print(f"{args.method}: {rec['nodes_before']} -> {rec['nodes_after']} nodes, height "
          f"{rec['height_before']} -> {rec['height_after']}; {len(y)} labelled vectors, "
          f"agreement with their labels {agree:.1%}")
    print(f"wrote {out}")
    return 0
