"""Live at an hour of teaching: how long a person's tree takes to reflect a new label as the
session grows (10 labels a second: 1,000 is under two minutes, 36,000 an hour), and memory,
side by side with the rebuild from every label the learner did before.

Labels come from ``bench_person.demonstration`` (the scripted teacher driving the room with
12% wrong keys, each label with the 6 scans shown before it). One ``PersonLearner`` by the
person rule (``client.behaviour.rule.PERSON``: the lag estimated, the sided vote of its
neighbours, its jittered copies of each label) is given the labels one by one, as ``rhbl learner``
is; at each size it is brought up to date, then for each of ``--repeat`` new labels the time
until ``learner.classifier`` is the tree with that label (what the next snapshot publishes:
only the votes the new label enters, then the tree extended with what changed, past the
rule's ``extend_above`` vectors, else learned again at once), its median and worst, and its
CPU time; the same for ``--batch`` labels at once (a snapshot every 2 s at 10 Hz: 20); the
tree learned again at once from every vector; a new label at a growth point (past
``extend_above``, once the labels grew by an eighth: one lag's agreement of the lag estimated
again, and the tree learned again from every vector: beside, in a thread of its own, as the
live learner does, the tree so far extended with the label meanwhile), then while it relearns
``--batch`` labels every 2 s (10 a second, a snapshot every 2 s: ``rhbl learner``'s pace), each
batch's build timed (their worst, and how many, the last the build that takes the relearned
tree), how long the relearn took, and the growth point's label with the tree relearned in its
place (as before); a label when the lag estimated again is another (every vote at it taken
beside, the old lag's tree extended meanwhile); the whole lag estimate (at once below
``extend_above``); the whole rebuild with the kd-tree (a restart's recovery, or a
new lag) and the rebuild of before
(every vote again by numpy's brute-force search, as the learner did at every snapshot:
``--old-max`` caps the sizes it runs at); the tree's nodes; the process's resident memory and
the learner's own arrays.

    python benchmarks/bench_live.py [--sizes 1000,6000,12000,24000,36000] [--repeat 5]
        [--batch 20] [--old-max 36000]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_person import demonstration  # noqa: E402

from client.behaviour import teaching  # noqa: E402
from client.behaviour.actions import DEFAULT_ACTIONS  # noqa: E402
from client.behaviour.features import FEATURES  # noqa: E402
from client.behaviour.rule import PERSON  # noqa: E402
from client.behaviour.teaching import PersonLearner, estimate_lag  # noqa: E402

NAMES = np.array(DEFAULT_ACTIONS.names)
MEANWHILE = 1000  # at most this many labels while a growth point's tree is relearned beside
SNAPSHOT_EVERY = 2.0  # seconds: rhbl learner's --snapshot-every (a build each)


class BruteIndex:
    """The neighbours' search of before: numpy's brute force (every distance, in blocks, the
    ``k`` smallest by ``argpartition``), behind the kd-tree's ``query``."""

    def __init__(self, X: np.ndarray):
        self.X = np.asarray(X, dtype=np.float64)
        self.xx = np.einsum("ij,ij->i", self.X, self.X)

    def query(self, Q: np.ndarray, k: int, workers: int = 1):
        n, out_d, out_i = len(self.X), [], []
        step = max(1, (1 << 22) // max(1, n))
        for s in range(0, len(Q), step):
            q = Q[s:s + step]
            d = np.einsum("ij,ij->i", q, q)[:, None] + self.xx[None, :] - 2.0 * q @ self.X.T
            nn = np.argpartition(d, k - 1, axis=1)[:, :k] if k < n else np.broadcast_to(
                np.arange(n), (len(q), n))
            dd = np.take_along_axis(d, nn, axis=1)
            order = np.argsort(dd, axis=1)
            out_i.append(np.take_along_axis(nn, order, axis=1))
            out_d.append(np.sqrt(np.maximum(np.take_along_axis(dd, order, axis=1), 0.0)))
        return np.concatenate(out_d), np.concatenate(out_i)


def feed(learner: PersonLearner, W: np.ndarray, y: np.ndarray, lo: int, hi: int) -> None:
    """Labels ``lo``..``hi - 1``, each with the scans shown before it, as the learner gets
    them."""
    for i in range(lo, hi):
        learner.observe_vector(W[i, 0], NAMES[y[i]], earlier=W[i, 1:])


def timed(fn, cpu: list | None = None):
    """(wall seconds, what ``fn`` returns); its CPU seconds appended to ``cpu`` (the process's:
    the figure a machine shared with other work changes least)."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    if cpu is not None:
        cpu.append(time.process_time() - c0)
    return time.perf_counter() - t0, out


def rss_mb() -> float:
    """The process's resident memory now (MB)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 1e6


def learner_mb(learner: PersonLearner) -> float:
    """The learner's own arrays (labels with their earlier scans, the copies' noise, the
    votes and distances of every row, the rows), MB; the kd-tree and the hypersphere tree
    aside."""
    arrays = [learner._W, learner._y, learner._noise]
    ed = learner._edited
    if ed is not None:
        arrays += [ed.X, ed.Q, ed.votes, ed.radius, ed.labels]
    return sum(a.nbytes for a in arrays if a is not None) / 1e6


def full_rebuild(W, y, n, brute: bool) -> tuple[float, int]:
    """(seconds, nodes): a learner given ``n`` labels builds its tree from all of them at once
    (``brute``: with the search of before, the lag estimated from every label as before)."""
    rule = PERSON
    if brute:
        rule = PERSON.replace(alignment=dataclasses.replace(PERSON.alignment, regrow=0.0))
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule)
    feed(learner, W, y, 0, n)
    saved = teaching._kdtree
    if brute:
        teaching._kdtree = BruteIndex
    try:
        seconds, clf = timed(lambda: learner.classifier)
    finally:
        teaching._kdtree = saved
    return seconds, int(clf.node_count_)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1000,6000,12000,24000,36000",
                    help="label counts (10 a second: 36000 is an hour)")
    ap.add_argument("--repeat", type=int, default=5, help="new labels timed one by one a size")
    ap.add_argument("--batch", type=int, default=20, help="labels at once (a snapshot's)")
    ap.add_argument("--old-max", type=int, default=36000,
                    help="the rebuild of before only up to this many labels (0: never)")
    args = ap.parse_args(argv)
    try:
        sizes = sorted(int(s) for s in args.sizes.split(",") if s)
    except ValueError:
        ap.error(f"--sizes {args.sizes!r}: expected label counts like 1000,6000")
    if not sizes or sizes[0] < 50 or args.repeat < 1 or args.batch < 1:
        ap.error("--sizes: each at least 50 labels; --repeat and --batch at least 1")
    extra = args.repeat + 2 * args.batch + 2 + MEANWHILE
    W, y = demonstration(sizes[-1] + extra)
    print(f"a person's tree reflecting new labels (the person rule: k={PERSON.editing.k}, "
          f"sided vote, {PERSON.editing.copies} jittered copies a label, lag estimated over "
          f"0..{PERSON.alignment.max_lag}), seconds:")
    print("| labels | a new label: median | worst | median CPU | tree learned at once | "
          f"{args.batch} new labels | a growth point's label | {args.batch} labels every {SNAPSHOT_EVERY:g} s while it "
          "relearns: worst (builds) | relearn beside | a growth point's label, relearned in its place | "
          "a new lag's label | "
          "lag estimate | whole rebuild (kd-tree) | "
          "rebuild of before (brute force) | before / now | tree nodes | RSS MB | learner MB |")
    print("|---" * 18 + "|")
    live = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, background=True)
    have = 0
    for n in sizes:
        feed(live, W, y, have, n)
        _ = live.classifier  # brought up to date: the session so far, a relearn it began
        live.wait_relearned()  # done (the labels below are timed alone)
        feed(live, W, y, n, n + 1)
        _ = live.classifier
        have = n + 1
        one, cpu = [], []
        for _ in range(args.repeat):  # one new label at a time
            feed(live, W, y, have, have + 1)
            have += 1
            one.append(timed(lambda: live.classifier, cpu)[0])
        tree_s = tree_only(live)
        probe = copy.deepcopy(live)  # a snapshot's labels at once, the session left as it was
        feed(probe, W, y, have, have + args.batch)
        batch_s = timed(lambda p=probe: p.classifier)[0]
        del probe
        growth = beside = meanwhile = at_once = new_lag = "-"
        if live._long():
            growth, meanwhile, beside, at_once = growth_point(live, W, y, have, args.batch)
            new_lag = another_lag(live, W, y, have)
        Wn, yn = live._W[:have], live._y[:have]
        lag_s = timed(lambda Wn=Wn, yn=yn: estimate_lag(Wn, yn, PERSON.editing.k,
                                                        len(DEFAULT_ACTIONS)))[0]
        whole_s, nodes = full_rebuild(W, y, n, brute=False)
        old = "-"
        ratio = "-"
        if n <= args.old_max:
            old_s, _ = full_rebuild(W, y, n, brute=True)
            old, ratio = f"{old_s:.3f}", f"{old_s / np.median(one):.0f}x"
        print(f"| {n} | {np.median(one):.3f} | {max(one):.3f} | {np.median(cpu):.3f} | "
              f"{tree_s:.3f} | {batch_s:.3f} | {growth} | {meanwhile} | {beside} | {at_once} | "
              f"{new_lag} | "
              f"{lag_s:.3f} | {whole_s:.3f} | {old} | {ratio} | {nodes} | {rss_mb():.0f} | "
              f"{learner_mb(live):.1f} |", flush=True)
    return 0


def growth_point(live: PersonLearner, W, y, have: int, batch: int) -> tuple[str, ...]:
    """A build at a growth point of (a copy of) ``live``: one lag's agreement of the estimate
    begun, and the tree learned again from every vector beside (the live learner's): the
    label's seconds; then ``batch`` labels every ``SNAPSHOT_EVERY`` s until the relearned tree
    is taken: their worst build (and how many); how long the relearn took; and the label with
    the tree learned again in its place (as before). The figures as printed."""
    probe = copy.deepcopy(live)
    probe._whole, probe._work = 1, (have, [])
    sync = copy.deepcopy(probe)
    sync.background = False
    feed(probe, W, y, have, have + 1)
    growth = timed(lambda: probe.classifier)[0]
    t0, waits, k = time.perf_counter(), [], have + 1
    while probe.relearning and k + batch <= have + 1 + MEANWHILE:
        if probe.wait_relearned(max(0.0, t0 + SNAPSHOT_EVERY * (len(waits) + 1)
                                    - time.perf_counter())):
            break
        feed(probe, W, y, k, k + batch)
        k += batch
        waits.append(timed(lambda: probe.classifier)[0])
    probe.wait_relearned()
    beside = time.perf_counter() - t0
    feed(probe, W, y, k, k + batch)
    waits.append(timed(lambda: probe.classifier)[0])  # the relearned tree taken
    feed(sync, W, y, have, have + 1)
    at_once = timed(lambda: sync.classifier)[0]
    return f"{growth:.3f}", f"{max(waits):.3f} ({len(waits)})", f"{beside:.1f}", f"{at_once:.3f}"


def another_lag(live: PersonLearner, W, y, have: int) -> str:
    """A label's build in (a copy of) ``live`` when the lag estimated again is another: every
    vote at it taken beside, the old lag's tree extended meanwhile (seconds, as printed)."""
    probe = copy.deepcopy(live)
    n0, lag, agreement = probe._estimate
    probe._estimate = (n0, (lag + 1) % (PERSON.alignment.max_lag + 1), agreement)
    feed(probe, W, y, have, have + 1)
    seconds = timed(lambda: probe.classifier)[0]
    probe.wait_relearned()  # (not beside the figures after it)
    return f"{seconds:.3f}"


def tree_only(learner: PersonLearner) -> float:
    """Seconds the hypersphere tree takes to learn the learner's training set (of a label's
    time: the rest is the vote)."""
    from rhbl import HypersphereClassifier

    X, y = learner.training_set()
    labels = NAMES[y]
    clf = HypersphereClassifier(default_label=NAMES[0], **learner.tree_params)
    return timed(lambda: clf.partial_fit(X, labels))[0]


if __name__ == "__main__":
    sys.exit(main())
