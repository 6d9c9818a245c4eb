"""``rhbl compact``: make an existing tree smaller, keeping what it does on its labelled vectors.

    rhbl compact --tree wall.rhbl --out wall-small.rhbl            # data: every vector it learned
    rhbl compact --tree T --out T2 --data a.journal --data run.mcap --method prune --max-error 0.01
    rhbl compact --tree T --out T2 --method prune --class-weight balanced --max-nodes 200

The data are the labelled vectors the tree should keep its behaviour on: learner journals
(``client.journal``; each record's scan is turned into features with the snapshot's own feature
spec), recordings (``.mcap``: the teacher labels paired with their scans as the learner pairs
them, ``lab.retrain.labeled_scans``) or ``.npz`` files with arrays ``X`` (feature vectors) and
``y`` (labels). Without ``--data``, every vector the tree was learned from: the journals of its
lineage (its own, and for a tree that extends another, ``rhbl learner --resume``, its parent's
up to where it was extended, and so on), or the recordings it was trained from (``rhbl train
--from-recording``); a tree whose data cannot all be found is refused, naming what is
missing. ``--method exact`` keeps every prediction on them; ``--method prune`` deletes the
weakest spheres against their labels (``rhbl.compaction``). The step is recorded in the snapshot's
``metadata["compaction"]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from client.behaviour.features import FeatureSpec
from client.behaviour.learning import load_snapshot
from client.journal import Journal, JournalError, journal_path
from process import arguments
from rhbl.compaction import METHODS

__all__ = ["add_arguments", "lineage_data", "load_data", "main"]


def _journal_rows(path: Path, features: FeatureSpec, stop: int | None = None
                  ) -> tuple[list, list]:
    """Features and labels of a journal's records ``0 .. stop - 1`` (all by default) that stand
    (not withdrawn by their teacher); a journal folded into its snapshot (``--fold-journal``) no
    longer holds its first records: refused."""
    with Journal.open(path, readonly=True) as j:
        if j.base:
            raise ValueError(f"{path}: its first {j.base} records were folded into its snapshot "
                             f"(--fold-journal) and cannot be read back: give the data with "
                             f"--data")
        rows, labels = [], []
        for rec in j.standing(stop=stop):  # labels the teacher withdrew are no data
            rows.append(features.extract(rec.ranges, rec.yaw))
            labels.append(rec.label)
    return rows, labels


def _recording_rows(path: Path, features: FeatureSpec) -> tuple[list, list]:
    from lab.retrain import labeled_scans

    rows, labels = [], []
    for _robot, scan, act in labeled_scans(path):
        rows.append(features.extract(scan.ranges, float(scan.pose[2])))
        labels.append(act.action)
    return rows, labels


def load_data(path: str | Path, features: FeatureSpec,
              stop: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(X, y)`` of a journal (its records before ``stop``), a recording (``.mcap``) or an
    ``.npz`` file (ValueError naming the file if unusable)."""
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
    if path.suffix == ".mcap":
        from client.recording.mcap_file import RecordingError

        try:
            rows, labels = _recording_rows(path, features)
        except RecordingError as exc:
            raise ValueError(str(exc)) from None
    else:
        try:
            rows, labels = _journal_rows(path, features, stop)
        except JournalError as exc:
            raise ValueError(f"{exc} (--data takes a learner journal, a recording .mcap or an "
                             f".npz with X and y)") from None
    return np.array(rows, dtype=np.float64).reshape(-1, features.dim), np.array(labels, dtype=str)


def lineage_data(tree: str | Path) -> list[tuple[Path, int | None]]:
    """Where every vector ``tree`` was learned from is: ``(file, stop)`` per journal of its
    lineage (``stop``: the records before it; None: all), or its recordings. ValueError naming
    what is missing when some cannot be found."""
    tree = Path(tree)
    own = journal_path(tree)
    if not own.exists():
        prov = load_snapshot(tree)[3].get("provenance") or {}
        recordings = [Path(p) for p in prov.get("recordings") or []]
        if not recordings:
            raise ValueError(f"no data to compact {tree} on: {own} does not exist and the tree "
                             f"names no recordings it was trained from (give --data JOURNAL, "
                             f"--data RECORDING.mcap or --data FILE.npz)")
        missing = [str(p) for p in recordings if not p.exists()]
        if missing:
            raise ValueError(f"{tree} was trained from the recordings {', '.join(missing)}, "
                             f"which do not exist: give them with --data")
        return [(p, None) for p in recordings]
    out: list[tuple[Path, int | None]] = [(own, None)]
    while True:
        with Journal.open(out[-1][0], readonly=True) as j:
            parent, fork = j.header.get("parent"), j.header.get("fork") or {}
        if parent is None:
            return out
        pj = journal_path(parent)
        if not pj.exists():
            raise ValueError(f"{tree} extends {parent} (rhbl learner --resume), whose vectors "
                             f"are in {pj}, which does not exist: give the data {parent} was "
                             f"learned from with --data (and {out[0][0]})")
        with Journal.open(pj, readonly=True) as j:
            lineage = j.lineage
        if fork.get("lineage") not in (None, lineage):
            raise ValueError(f"{tree} extends {parent} as it was in lineage {fork['lineage']}, "
                             f"but {pj} now holds lineage {lineage}: give the data with --data")
        out.append((pj, fork.get("records")))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tree", required=True, type=arguments.input_file,
                        help="snapshot to compact")
    parser.add_argument("--out", required=True, type=arguments.output_file,
                        help="snapshot to write")
    parser.add_argument("--data", action="append", default=None, metavar="FILE",
                        type=arguments.input_file,
                        help="labelled vectors: a learner journal, a recording (.mcap) or an "
                             ".npz with X and y (repeatable; default: every vector the tree "
                             "was learned from: its lineage's journals, or the recordings it "
                             "was trained from)")
    parser.add_argument("--method", choices=METHODS, default="exact",
                        help="exact: keep every prediction on the data (default); prune: delete "
                             "the weakest spheres against the data's labels")
    parser.add_argument("--max-error", type=arguments.fraction, default=0.0,
                        help="prune: fraction of the rows whose errors the pruning may add (0)")
    parser.add_argument("--class-weight", choices=["balanced"], default=None,
                        help="prune: weigh each label's rows the same in total (rare labels, such "
                             "as a turn in place before a wall, are not pruned away as cheap)")
    parser.add_argument("--max-nodes", type=arguments.positive_int, default=None,
                        help="prune: delete the weakest spheres until at most this many are left")


def main(args) -> int:
    clf, features, _actions, _meta = load_snapshot(args.tree)
    files = [(Path(f), None) for f in args.data] if args.data else lineage_data(args.tree)
    parts = [load_data(f, features, stop) for f, stop in files]
    X = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    if not len(y):
        raise ValueError(f"no labelled vectors in {', '.join(str(f) for f, _ in files)}: "
                         f"nothing to keep {args.tree}'s behaviour on")
    small = clf.compact(X, y, method=args.method, max_error=args.max_error,
                        max_nodes=args.max_nodes, class_weight=args.class_weight,
                        data=", ".join(f.name for f, _ in files))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    small.save(out)
    rec = small.metadata["compaction"][-1]
    agree = float(np.mean(small.predict(X) == y))
    print(f"{args.method}: {rec['nodes_before']} -> {rec['nodes_after']} nodes, height "
          f"{rec['height_before']} -> {rec['height_after']}; {len(y)} labelled vectors from "
          f"{len(files)} file(s), agreement with their labels {agree:.1%}")
    print(f"wrote {out}")
    return 0
