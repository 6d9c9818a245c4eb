"""The person rule's rebuild as a teaching session grows: what one snapshot of ``rhbl learner
--teacher person`` costs at N labels (10 labels a second: 1,000 is under two minutes, 36,000 an
hour of teaching).

Labels come from the scripted teacher driving the room (``lab.train``'s world, the wall
features: real feature vectors, consecutive scans alike), 12% of them replaced by a wrong key
(a person's), each with the 6 scans shown before it (as the learner's pairing keeps them, for
the lag estimate). For each N it times, in this process, the three parts of a rebuild
(``PersonLearner``'s defaults: the lag estimated, the sided vote of its neighbours, its
jittered copies of each label): the lag estimate (``estimate_lag``), the vote
(``PersonLearner.training_set``: the labels' vote and their copies', ``nearest_votes``) and the
tree learning the voted vectors, best of ``--repeat``; beside the vote the same neighbours
found by scikit-learn's ``KNeighborsClassifier`` (kd-tree, the same k, the same queries: the
labels and their copies) as the peer a user would reach for.

    python benchmarks/bench_person.py [--sizes 1000,5000,10000,36000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from client.behaviour.actions import DEFAULT_ACTIONS  # noqa: E402
from client.behaviour.features import FEATURES  # noqa: E402
from client.behaviour.rule import PERSON  # noqa: E402
from client.behaviour.teaching import PersonLearner, estimate_lag  # noqa: E402

MAX_LAG = PERSON.alignment.max_lag


def demonstration(n: int, wrong: float = 0.12, seed: int = 0):
    """``(W, y)``: n labels of the scripted wall follower in the room, ``W`` (n, MAX_LAG + 1,
    dim) the features of each label's scan and of the 6 before it, ``y`` action indices with
    ``wrong`` of them replaced by another action."""
    from client.behaviour.policies import WallFollower
    from lab.episode import DT
    from lab.harness import resolve_world
    from server.world import World

    spec = resolve_world("room")
    features = FEATURES["wall"]
    world = World(spec, robots=1, seed=seed)
    teacher = WallFollower()
    names = DEFAULT_ACTIONS.names
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    starts = list(spec.start_poses)
    world.reset(poses=[tuple(starts[0])])
    teacher.reset()
    for k in range(n + MAX_LAG):
        if k and k % 600 == 0:  # a new start every minute, as a person pressing Home
            world.set_pose(0, starts[(k // 600) % len(starts)])
            teacher.reset()
        ranges, odom = world.scan(0), world.odom(0)
        xs.append(features.extract(ranges, odom[2]))
        label = teacher.act(ranges, odom)
        ys.append(names.index(label))
        world.set_command(0, *DEFAULT_ACTIONS[label])
        world.step(DT)
    X = np.asarray(xs, dtype=np.float64)
    y = np.asarray(ys[MAX_LAG:], dtype=np.int64)
    flip = rng.random(len(y)) < wrong
    y[flip] = (y[flip] + rng.integers(1, len(names), flip.sum())) % len(names)
    W = np.stack([X[MAX_LAG - j:MAX_LAG - j + n] for j in range(MAX_LAG + 1)], axis=1)
    return W, y


def best(f, repeat: int) -> tuple[float, object]:
    """The fastest of ``repeat`` calls of ``f`` (seconds) and what the last call returned."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,5000,10000,36000",
                    help="label counts, comma-separated (default 1000,5000,10000,36000)")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many (default 3)")
    args = ap.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s]
    except ValueError:
        ap.error(f"--sizes {args.sizes!r}: expected label counts like 1000,5000")
    if not sizes or min(sizes) < 50 or args.repeat < 1:
        ap.error("--sizes: each at least 50 labels; --repeat at least 1")
    try:
        from sklearn.neighbors import KNeighborsClassifier
    except ImportError:  # the peer is optional (pip install -e '.[dev]')
        KNeighborsClassifier = None
    from rhbl import HypersphereClassifier

    k, n_actions = PERSON.editing.k, len(DEFAULT_ACTIONS)
    names = np.array(DEFAULT_ACTIONS.names)
    W_all, y_all = demonstration(max(sizes))
    print(f"the person rule's rebuild (k={k}, sided vote, jittered copies "
          f"a label: {PERSON.editing.copies}, lag estimated over 0..{MAX_LAG}), best of "
          f"{args.repeat}, seconds:")
    print("| labels | decisions | lag estimate | ... every decision answered (once) | "
          "vote (rhbl) | neighbours (scikit-learn kd-tree) | tree | rebuild | tree nodes |")
    print("|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        W, y = W_all[:n], y_all[:n]
        lag_s, (lag, _) = best(lambda W=W, y=y: estimate_lag(W, y, k, n_actions), args.repeat)
        change = y[1:] != y[:-1]
        decisions = int((np.r_[True, change] | np.r_[change, False]).sum())
        every_s, _ = best(lambda W=W, y=y, n=n: estimate_lag(W, y, k, n_actions, decisions=n),
                          1)
        X = np.ascontiguousarray(W[:, lag])
        learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, lag=int(lag))
        learner.observe_vectors(X, names[y])
        vote_s, (XT, yT) = best(learner.training_set, args.repeat)
        peer = "-"
        if KNeighborsClassifier is not None:
            def sk(X=X, y=y, XT=XT):
                knn = KNeighborsClassifier(k, algorithm="kd_tree").fit(X, y)
                return knn.kneighbors(XT, return_distance=False)
            peer = f"{best(sk, args.repeat)[0]:.3f}"
        labels = names[yT]
        def tree(XT=XT, labels=labels, params=learner.tree_params):
            clf = HypersphereClassifier(default_label=DEFAULT_ACTIONS.names[0], **params)
            return clf.partial_fit(XT, labels)
        tree_s, clf = best(tree, args.repeat)
        print(f"| {n} | {decisions} | {lag_s:.3f} | {every_s:.3f} | {vote_s:.3f} | {peer} | "
              f"{tree_s:.3f} | "
              f"{lag_s + vote_s + tree_s:.3f} | {clf.node_count_} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
