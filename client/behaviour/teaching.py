"""Learning from a person: what to do with labels given by hand at the console.

People react 200-450 ms after what they see, press wrong keys, over-steer and correct
themselves; the scripted teachers do none of that. Learning every label as it arrives (the
paper's rule, ``DemonstrationLearner``) carves a sphere for every late or wrong key, and the
tree copies the noise. The person rule (``client.behaviour.rule.PERSON``: its parts and their
settings, one object) copes with it; this module is its code (docs/teaching.md has the study):

* **reaction-time alignment** (``answered_scan``, on the console's side): a key held while
  scan ``n`` is displayed answers what the person saw ``lag`` scans earlier, so the label is
  tied to scan ``n - lag`` (the scan displayed when the key went out, if that one is unknown
  or the robot was moved since).
* **the lag estimated from the data** (the rule's ``alignment.lag`` None, the default;
  ``rhbl learner --lag auto``; ``estimate_lag``): each label also carries the scans shown up to
  ``max_lag`` scans before its own; the lag is the shift at which the changes of key are best
  predicted from the features of the scan that many scans earlier, held out in blocks of time.
* **editing by the neighbours' vote** (Wilson's edited nearest neighbour, as kNN smoothing;
  ``PersonLearner``): every label is kept as given; the tree learns each labelled vector with
  the action nearest to the mean command of those of its ``k`` nearest labelled vectors that
  agree on the turning side (``sided_actions``), and ``copies`` jittered copies of it (normal
  noise of ``sigma``) with the vote at their place: a wrong key or a late release is outvoted
  by the labels around it, and the tree answers the states around the labels as their
  neighbours vote, whatever the order it learned them in (the copies are model compression's
  synthetic examples: where the robot goes when it drives a little off the person's path).
* **passes**: the tree learns the edited set the rule's ``passes`` times, each in another
  shuffled order, until it answers nearly all of it as labelled.

The vote is kept up to date as labels come (``PersonLearner``: a kd-tree over the labels;
only the labels and copies whose ``k`` nearest a new label enters are voted again; the tree
is then extended with the voted vectors in the rule's shuffled orders, and past
``extend_above`` vectors learned again at once when they grew by an eighth: in the live
learner (``background``) in a thread of its own while the tree so far is extended meanwhile;
``benchmarks/bench_live.py`` measures both at an hour of teaching).

    shown = 812                                         # the scan the page displayed
    answered = answered_scan(shown, scans, lag=3)       # scans: id -> scan (with .pose)
    learner = PersonLearner(FEATURES["around"], DEFAULT_ACTIONS)   # rule=PERSON
    learner.observe(ranges, yaw, "fwd-left")            # the label, tied to the answered scan
    learner.classifier                                  # the tree of every label so far

Pure (no zenoh, no I/O): the processes and the in-process study run this same code.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Mapping

import numpy as np

from process import arguments

from .actions import DEFAULT_ACTIONS, ActionSet
from .features import FeatureSpec
from .learning import DemonstrationLearner
from .rule import PERSON, LearningRule

log = logging.getLogger(__name__)
NICE = 10  # the work beside's thread's niceness (Linux: per thread): the builds come first

__all__ = [
    "PersonLearner",
    "add_person_arguments",
    "answered_scan",
    "estimate_lag",
    "nearest_votes",
    "parse_lag",
    "sided_actions",
]

_KEEP = object()  # PersonLearner's lag: the rule's


def answered_scan(shown: int, scans: Mapping[int, object], lag: int = PERSON.alignment.default,
                  pose: Callable[[object], tuple] = lambda s: s.pose,
                  jump: float = PERSON.alignment.jump) -> int:
    """The id of the scan a key answers: ``lag`` scans before ``shown`` (the scan displayed when
    the key was sent), or ``shown`` itself when that earlier scan is not in ``scans`` (id ->
    scan, ``pose(scan)`` its (x, y, ...)) or the robot jumped more than ``jump`` metres from one
    scan to the next in between (it was put elsewhere: the person saw another place)."""
    if lag <= 0:
        return shown
    ids = [shown - i for i in range(lag + 1)]
    if any(i not in scans for i in ids):
        return shown
    for a, b in zip(ids, ids[1:], strict=False):
        pa, pb = pose(scans[a]), pose(scans[b])
        if math.hypot(pa[0] - pb[0], pa[1] - pb[1]) > jump:
            return shown
    return shown - lag


# rows of a neighbours' search at least this many: searched by every core (scipy's workers)
PARALLEL_QUERY = 20000
# rows a new label's distances are computed for at once (``_nearer``: 8192 x 64 fit the cache)
ROW_BLOCK = 8192


def _kdtree(X: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(X, balanced_tree=False, compact_nodes=False)


def _neighbours(tree, Q: np.ndarray, k: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(distances, indices), each (len(Q), min(k, n)): the nearest rows of the ``n`` rows
    ``tree`` holds, nearest first (Euclidean)."""
    k = max(1, min(int(k), n))
    # a whole rebuild's rows (every label and its copies) on every core; a new label's few
    # on this thread
    d, i = tree.query(Q, k=k, workers=-1 if len(Q) >= PARALLEL_QUERY else 1)
    return d.reshape(len(Q), k), i.reshape(len(Q), k)


def _counts(nn: np.ndarray, y: np.ndarray, n_labels: int) -> np.ndarray:
    """(rows, n_labels): per row of neighbour indices ``nn`` the count of each label of ``y``."""
    flat = np.repeat(np.arange(len(nn)) * n_labels, nn.shape[1]) + y[nn].ravel()
    return np.bincount(flat, minlength=len(nn) * n_labels).reshape(len(nn), n_labels).astype(
        np.float64)


def nearest_votes(Q: np.ndarray, X: np.ndarray, y: np.ndarray, k: int,
                  n_labels: int) -> np.ndarray:
    """(len(Q), n_labels): for each row of ``Q`` the count of each label index of ``y`` among
    its ``k`` nearest rows of ``X`` (Euclidean distance; a kd-tree: n log n, not n^2)."""
    if not len(Q):
        return np.zeros((0, n_labels))
    _, nn = _neighbours(_kdtree(X), Q, k, len(X))
    return _counts(nn, y, n_labels)


def _commands(actions: ActionSet) -> np.ndarray:
    """(actions, 2): each action's (vx, va), each scaled by the largest of the set."""
    v = np.array([actions[n] for n in actions.names], dtype=np.float64)
    return v / np.maximum(np.abs(v).max(axis=0), 1e-12)


def _nearest_action(points: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per row of ``points`` (scaled commands) the index of the nearest row of ``v``."""
    return ((points[:, None, :] - v[None, :, :]) ** 2).sum(axis=2).argmin(axis=1)


def _mean_commands(votes: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(len(votes), 2): per row the mean of the scaled commands ``v`` weighted by the counts."""
    return votes @ v / np.maximum(votes.sum(axis=1, keepdims=True), 1e-12)


def sided_actions(votes: np.ndarray, actions: ActionSet,
                  share: float = PERSON.editing.side_share) -> np.ndarray:
    """Per row of ``votes`` (counts per action index) the index of the action nearest to the
    mean command ((vx, va), each scaled by the largest of the set) of the keys that agree on
    the side: turning keys to one side weighing less than ``share`` (two thirds) of those to
    the other are taken for confusions (left and right, or a turn let go of late) and left
    out, the rest averaged (forward keys always count). A zig-zag of left and right in like
    numbers averages to forward; forward keys with a minority of turns to one side (a person
    who steers by tapping a rotation between forward presses, never an arc) keep that turn's
    weight; a minority on the other side does not pull a turn towards forward."""
    v = _commands(actions)
    left, right = v[:, 1] > 0, v[:, 1] < 0
    wl, wr = votes[:, left].sum(axis=1), votes[:, right].sum(axis=1)
    keep = np.ones_like(votes)
    keep[:, right] = (wr >= share * wl)[:, None]
    keep[:, left] = (wl >= share * wr)[:, None]
    return _nearest_action(_mean_commands(votes * keep, v), v)


def parse_lag(text: str, max_lag: int = PERSON.alignment.max_lag) -> int | None:
    """A ``--lag`` value: ``auto`` (None: estimated from the labels) or an integer 0..max_lag
    (ValueError naming what is wrong otherwise)."""
    if text.strip() == "auto":
        return None
    try:
        lag = int(text.strip())
    except ValueError:
        lag = -1
    if not 0 <= lag <= max_lag:
        raise ValueError(f"must be 'auto' or an integer 0..{max_lag} (scans), got {text!r}")
    return lag


def add_person_arguments(parser) -> None:
    """``--lag SCANS|auto`` (``parse_lag``; None: the person rule's, estimated) as ``rhbl
    learner`` and ``rhbl train --from-recording`` take it."""
    a = PERSON.alignment
    parser.add_argument("--lag", type=arguments.Checked("lag", parse_lag), default=None,
                        metavar="SCANS|auto",
                        help="with the person rule: a label answers the scan this many scans "
                             f"(0..{a.max_lag}) before the one it names; 'auto' (default): "
                             "estimated from the labels, re-estimated as they accumulate "
                             f"({a.default} until there are {a.min_labels}; docs/teaching.md)")


def estimate_lag(W: np.ndarray, y: np.ndarray, k: int, n_labels: int, block: int = 50,
                 folds: int = 5,
                 decisions: int = PERSON.alignment.max_decisions) -> tuple[int, list[float]]:
    """The lag (0 .. ``W.shape[1] - 1`` scans) at which the person's decisions are best
    predicted from the features ``W[:, lag]`` of the scan that many scans before each label's
    own, and the agreement at every lag. ``W``: (labels, lags, dim) in the order given.

    The decisions are the labels on either side of a change of key (the last label of a key
    and the first of the next): while a key is held every lag sees nearly the same place, so
    only the changes tell when the person reacted; at the right lag the last label before a
    change still sees the old side of the person's boundary and the first after it the new
    side. Each is answered by the majority of its ``k`` nearest labels held out by time (the
    labels cut in blocks of ``block`` consecutive ones, dealt round-robin into ``folds`` folds;
    the references are the other folds: consecutive labels are near copies of each other;
    a kd-tree per fold, the ``k`` nearest of the other folds' merged). The agreement is
    smoothed over neighbouring lags (weights 1/4, 1/2, 1/4) and ties go to the shorter lag.
    More than ``decisions`` decisions: that many of them, evenly spread over the session, are
    answered. Deterministic: a function of ``W`` and ``y`` only."""
    raw = [agreement_at(W, y, lag, k, n_labels, block, folds, decisions)
           for lag in range(W.shape[1])]
    return smoothed_lag(raw)


def agreement_at(W: np.ndarray, y: np.ndarray, lag: int, k: int, n_labels: int,
                  block: int = 50, folds: int = 5,
                  decisions: int = PERSON.alignment.max_decisions) -> float:
    """``estimate_lag``'s raw agreement at one ``lag``: the share of the decisions the
    majority of their ``k`` nearest labels of the other folds answers (a kd-tree per fold, the
    ``k`` nearest of the other folds' merged)."""
    n = len(y)
    fold = (np.arange(n) // block) % folds
    change = y[1:] != y[:-1]
    q = np.flatnonzero(np.r_[True, change] | np.r_[change, False])
    if len(q) > decisions:
        q = q[np.linspace(0, len(q) - 1, decisions).round().astype(np.int64)]
    members = [np.flatnonzero(fold == f) for f in range(folds)]
    X = np.ascontiguousarray(W[:, lag])
    trees = [_kdtree(X[m]) if len(m) else None for m in members]
    hit = 0
    for f in range(folds):
        qi = q[fold[q] == f]
        others = [g for g in range(folds) if g != f and trees[g] is not None]
        if not len(qi) or not others:
            continue
        d_all, i_all = [], []
        for g in others:
            d, i = _neighbours(trees[g], X[qi], k, len(members[g]))
            d_all.append(d)
            i_all.append(members[g][i])
        d, i = np.concatenate(d_all, axis=1), np.concatenate(i_all, axis=1)
        kk = min(k, d.shape[1])
        nn = np.take_along_axis(i, np.argsort(d, axis=1, kind="stable")[:, :kk], axis=1)
        hit += int((_counts(nn, y, n_labels).argmax(axis=1) == y[qi]).sum())
    return hit / max(1, len(q))


def smoothed_lag(raw) -> tuple[int, list[float]]:
    """The lag of the best agreement ``raw`` (one per lag 0..) smoothed over neighbouring
    lags (1/4, 1/2, 1/4; ties to the shorter lag), and the smoothed agreement."""
    a = np.array(raw, dtype=np.float64)
    smooth = 0.5 * a + 0.25 * np.r_[a[:1], a[:-1]] + 0.25 * np.r_[a[1:], a[-1:]]
    return int(np.argmax(smooth)), [float(v) for v in smooth]


def _nearer(rows: np.ndarray, radius: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Which ``rows`` have one of the ``new`` labels within their ``radius`` (their ``k``-th
    nearest's distance, ties included): in blocks of rows and of new labels, so that the
    distances stay in the cache (a build's memory traffic, with a relearn beside)."""
    near = np.zeros(len(rows), bool)
    rr = np.einsum("ij,ij->i", rows, rows)
    r2 = radius ** 2 * (1 + 1e-9) + 1e-12
    for s in range(0, len(new), 64):
        part = new[s:s + 64]
        pp = np.einsum("ij,ij->i", part, part)
        for b in range(0, len(rows), ROW_BLOCK):
            block = slice(b, b + ROW_BLOCK)
            d2 = rr[block, None] + pp[None, :] - 2.0 * rows[block] @ part.T
            near[block] |= (d2 <= r2[block, None]).any(axis=1)
    return near


class _Edited:
    """The edited training set of a person's labels at one lag, kept up to date as labels
    come: the labelled vectors ``X`` and their jittered copies ``Q``, a kd-tree over ``X``,
    for every row of both its vote (counts of each action among its ``k`` nearest labels) and
    the distance of its ``k``-th nearest (a new label nearer than that enters its vote: only
    those rows are voted again), and the edited label of each."""

    def __init__(self, lag: int, k: int, n_actions: int, edit: Callable[[np.ndarray], np.ndarray]):
        self.lag, self.k, self.n_actions, self.edit = lag, k, n_actions, edit
        self.n = 0
        self.X = self.Q = None
        # rows: the labels', then the copies': the vote, the k-th nearest's distance, the label
        self.votes = self.radius = self.labels = None
        self.tree = None

    def rows(self) -> np.ndarray:
        return np.concatenate([self.X, self.Q]) if self.Q is not None and len(self.Q) else self.X

    def update(self, X: np.ndarray, Q: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Take the labels ``X`` (the first ``n`` as before), their copies ``Q`` (likewise)
        and every label index ``y``: the rows a new label is nearer to than their ``k``-th
        nearest (and the new ones) voted again; returns them (indices into ``rows()``)."""
        old, oldq = self.n, 0 if self.Q is None else len(self.Q)
        n = len(X)
        if self.votes is not None and n == old and len(Q) == oldq:
            self.changed, self.fresh = np.zeros(0, np.int64), False
            return self.changed  # no label came
        self.tree = _kdtree(X)
        if old <= self.k or self.votes is None:  # a row's vote held every label: all again
            again = np.arange(n + len(Q))
            self.fresh = True
        else:
            near = _nearer(self.rows(), self.radius, X[old:])
            self.fresh = False
            again = np.concatenate([np.flatnonzero(near[:old]),
                                    np.arange(old, n),
                                    n + np.flatnonzero(near[old:old + oldq]),
                                    n + np.arange(oldq, len(Q))])
            self.votes = np.concatenate([self.votes[:old], np.zeros((n - old, self.n_actions)),
                                         self.votes[old:], np.zeros((len(Q) - oldq,
                                                                     self.n_actions))])
            self.radius = np.concatenate([self.radius[:old], np.zeros(n - old),
                                          self.radius[old:], np.zeros(len(Q) - oldq)])
            self.labels = np.concatenate([self.labels[:old], np.zeros(n - old, np.int64),
                                          self.labels[old:], np.zeros(len(Q) - oldq, np.int64)])
        if self.votes is None or len(self.votes) != n + len(Q):
            self.votes = np.zeros((n + len(Q), self.n_actions))
            self.radius = np.zeros(n + len(Q))
            self.labels = np.zeros(n + len(Q), np.int64)
        self.X, self.Q, self.n = X, Q, n
        if len(again):
            rows = self.rows()
            d, nn = _neighbours(self.tree, rows[again], self.k, n)
            self.votes[again] = _counts(nn, y, self.n_actions)
            self.radius[again] = d[:, -1]
            before = self.labels[again].copy()
            before[(again >= old) & (again < n)] = -1  # new labels' rows
            before[again >= n + oldq] = -1  # new copies' rows
            self.labels[again] = self.edit(self.votes[again])
            self.changed = again[self.labels[again] != before]  # new, or voted otherwise
        else:
            self.changed = again
        return again


class _Beside:
    """``work(cancelled)`` run in a thread of its own (``PersonLearner``'s ``background``): its
    ``result``, or the ``error`` it raised; ``cancel`` sets the event it is given. ``info``:
    what the caller keeps with it (a vote's ``lag``; a relearn's ``size``, when it ``began``
    and ``since``, the (labels, copies) new or voted otherwise meanwhile, which its tree is
    extended with when it is taken)."""

    def __init__(self, work: Callable[[threading.Event], object], **info):
        self.result = None
        self.error: BaseException | None = None
        self.__dict__.update(info)
        self._cancelled = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(work,), name="rhbl-beside",
                                        daemon=True)
        self._thread.start()

    def _run(self, work) -> None:
        with contextlib.suppress(AttributeError, OSError):  # not Linux: the process's
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE)
        try:
            self.result = work(self._cancelled)
        except Exception as exc:  # noqa: BLE001 - reported where it is taken
            self.error = exc

    def cancel(self) -> None:
        self._cancelled.set()

    def done(self) -> bool:
        return not self._thread.is_alive()

    def wait(self, timeout: float | None = None) -> bool:
        self._thread.join(timeout)
        return self.done()


def _relearned(make: Callable, rows: np.ndarray, names: np.ndarray, orders: list):
    """The work of a relearn beside: a new tree (``make()``) learned from ``rows`` labelled
    ``names`` in each of ``orders`` (None when cancelled between passes)."""
    def work(cancelled: threading.Event):
        return _learned_whole(make(), rows, names, orders, cancelled)
    return work


def _learned_whole(clf, rows: np.ndarray, names: np.ndarray, orders: list,
                   cancelled: threading.Event | None = None):
    """``clf`` (a fresh tree) learned from ``rows`` labelled ``names`` in each of ``orders``,
    one pass after another; with ``radius="margin"`` the passes in one ``fit`` (each sphere
    bounded by its margin among every vector). None when ``cancelled`` between passes (the
    margin's one ``fit``: before or after it)."""
    if getattr(clf, "radius", "parent") == "margin":
        if cancelled is not None and cancelled.is_set():
            return None
        every = np.concatenate(orders)
        clf.fit(rows[every], names[every])
        return None if cancelled is not None and cancelled.is_set() else clf
    for order in orders:
        if cancelled is not None and cancelled.is_set():
            return None
        clf.partial_fit(rows[order], names[order])
    return clf


def _voted(lag: int, k: int, n_actions: int, edit: Callable, X: np.ndarray, Q: np.ndarray,
           y: np.ndarray):
    """The work of a vote beside at a new ``lag``: every row of ``X`` and ``Q`` voted."""
    def work(cancelled: threading.Event) -> _Edited:
        ed = _Edited(lag, k, n_actions, edit)
        ed.update(X, Q, y)
        return ed
    return work


class PersonLearner(DemonstrationLearner):
    """A ``DemonstrationLearner`` for labels given by a person (see the module's docstring),
    learning by ``rule`` (a ``LearningRule`` that edits its labels; default
    ``client.behaviour.rule.PERSON``); ``lag``, ``k``, ``copies``, ``sigma``, ``side_share``,
    ``seed`` and ``passes`` given here replace the rule's (``lag`` None: estimated).

    Every label offered (``observe``, ``observe_vector``) is kept; ``classifier`` is the tree
    of ``training_set``: every labelled vector and its copies with their edited labels,
    learned the rule's ``passes`` times, each in an order shuffled with the rule's seed
    (``**tree_params`` join the rule's tree parameters, default ``spawn="winner"``). It is
    brought up to date when labels came since it was last asked for: the lag re-estimated
    when the labels grew by the rule's ``regrow`` since the last estimate (a new lag: every
    vote again), else only the votes a new label enters, then the tree learned again (past the
    rule's ``extend_above`` vectors: extended with what changed, learned again at once when the
    vectors grew by the alignment's ``regrow``). Sample selection (``stride``, ``min_delta``)
    does not apply: the vote needs every label.

    ``background`` (the live learner's): the tree learned again at once in a thread of its own,
    from the training set as it was then, while each build extends the tree so far with what
    changed; the relearned tree is taken, extended with what came meanwhile, at the first
    build after it is done (``relearning``; ``wait_relearned``). A new label is in the next
    tree within an extension's time at any size, but which builds get the relearned tree
    depends on how fast it was learned: off (the default), every build is the same whatever
    the machine."""

    def __init__(self, features: FeatureSpec, actions: ActionSet = DEFAULT_ACTIONS, *,
                 rule: LearningRule = PERSON, lag=_KEEP, k: int | None = None,
                 copies: int | None = None, sigma: float | None = None,
                 side_share: float | None = None, seed: int | None = None,
                 passes: int | None = None, background: bool = False, task: str | None = None,
                 parent: str | None = None, provenance: Mapping | None = None, **tree_params):
        import dataclasses

        if not rule.person:
            raise ValueError(f"a PersonLearner learns by a rule that edits its labels, not "
                             f"the {rule.name!r} rule")
        edits = {name: v for name, v in (("k", k), ("copies", copies), ("sigma", sigma),
                                         ("side_share", side_share)) if v is not None}
        if edits:
            rule = rule.replace(editing=dataclasses.replace(rule.editing, **edits))
        if lag is not _KEEP:
            rule = rule.replace(lag=lag)
        if seed is not None:
            rule = rule.replace(seed=seed)
        if passes is not None:
            rule = rule.replace(passes=passes)
        rule = rule.replace(tree={"spawn": "winner", **rule.tree, **tree_params})
        self.rule = rule
        a, e = rule.alignment, rule.editing
        # None: estimated from the labels (each keeps the scans before its own: ``observe``'s
        # ``earlier``); an integer: fixed, the scans the labels were shifted by when paired
        self.lag = a.lag
        self.k, self.copies, self.sigma, self.seed = e.k, e.copies, float(e.sigma), rule.seed
        self._lags = a.max_lag + 1 if a.lag is None else 1  # feature columns kept per label
        self._W = np.zeros((0, self._lags, features.dim))  # per label: its features at lags
        self._y = np.zeros(0, np.int64)
        self._n = 0
        self._noise = np.zeros((0, features.dim))  # the copies' noise, drawn as labels come
        self._rng = np.random.default_rng(rule.seed)  # has drawn exactly ``_noise``
        self._estimate: tuple[int, int, list[float]] | None = None  # (labels, lag, agreement)
        self._work: tuple[int, list[float]] | None = None  # an estimate under way (labels, raw)
        self._edited: _Edited | None = None
        self._whole: int | None = None  # the vectors the tree was last learned from at once
        self._pending: list = []  # (labels, copies) new or voted otherwise since the last tree
        self._stale = True  # every vote was taken again since the last tree
        self.background = bool(background)
        self._job: _Beside | None = None  # the tree being learned again at once (background)
        self._revote: _Beside | None = None  # every vote at a new lag (background)
        self._tree_n = 0  # the labels the tree so far was built with
        self._clf = None
        self._built = -1
        super().__init__(features, actions, task=task, parent=parent, provenance=provenance,
                         rule=rule, **rule.tree)

    # the tree: brought up to date when asked for
    @property
    def classifier(self):
        if self._built != self._n:
            self._clf = self._build()
            self._built = self._n
        return self._clf

    @classifier.setter
    def classifier(self, clf) -> None:  # DemonstrationLearner's __init__: the empty tree
        self._clf = clf
        self._built = self._n

    def _learn(self, x: np.ndarray, label: str, earlier=None) -> None:
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        w = np.repeat(x[None, :], self._lags, axis=0)  # lags not held: the label's own scan
        if self._lags > 1 and earlier is not None and len(earlier):
            e = np.asarray(earlier, dtype=np.float64).reshape(-1, self.features.dim)
            m = min(len(e), self._lags - 1)
            w[1:1 + m] = e[:m]
        if self._n == len(self._W):  # grown by doubling: appending stays O(1) a label
            cap = max(64, 2 * len(self._W))
            self._W = np.concatenate([self._W, np.zeros((cap - len(self._W), *self._W.shape[1:]))])
            self._y = np.concatenate([self._y, np.zeros(cap - len(self._y), np.int64)])
        self._W[self._n] = w
        self._y[self._n] = self.actions.names.index(label)
        self._n += 1
        self.vectors += 1
        if self._rec_x is not None:
            self._rec_x.append(x)
            self._rec_y.append(label)

    def observe(self, ranges, yaw: float, label: str, earlier=None) -> bool:
        """Keep one labelled observation (every one is kept: True). ``earlier``: with the lag
        estimated, the feature vectors of the scans shown 1, 2, ... scans before this one
        (nearest first, at most the rule's ``max_lag``; fewer when they are not known or the
        robot was put elsewhere: the lags beyond take this scan)."""
        return self.observe_vector(self.features.extract(ranges, yaw), label, earlier)

    def observe_vector(self, x: np.ndarray, label: str, earlier=None) -> bool:
        self._check_label(label)
        self.seen += 1
        self._learn(x, label, earlier)
        return True

    def observe_vectors(self, X: np.ndarray, labels) -> int:
        X, labels = self._checked(X, labels)
        for x, label in zip(X, labels, strict=True):  # (no earlier scans: lag 0 if estimated)
            self.seen += 1
            self._learn(x, label)
        return len(X)

    @property
    def estimated_lag(self) -> int:
        """The lag the tree is built with: fixed, or estimated from the labels (``estimate_lag``
        over lags 0..max_lag; the rule's default below its ``min_labels`` labels; estimated
        again once the labels grew by its ``regrow`` since the last estimate: past the rule's
        ``extend_above`` vectors one lag's agreement at each build, the lag so far meanwhile,
        so that no build waits for a whole estimate)."""
        if self.lag is not None:
            return self.lag
        self._estimating(all_at_once=not self._long())
        return self._estimate[1]

    def _long(self) -> bool:
        """Past the rule's ``extend_above`` vectors (labels and copies)."""
        ext = self.rule.extend_above
        return ext is not None and self._n * (1 + self.copies) >= ext

    def _estimating(self, all_at_once: bool, step: bool = False) -> None:
        """Bring the lag estimate up to date: all at once, or (``step``) one more lag's
        agreement of an estimate begun at the labels there were then."""
        a, n = self.rule.alignment, self._n
        last = self._estimate
        if n < a.min_labels:
            if last is None or last[0] != n:
                self._estimate = (n, a.default, [])
            return
        first = last is None or last[0] < a.min_labels
        if self._work is None and (first or (n != last[0] and n >= last[0] * (1.0 + a.regrow))):
            self._work = (n, [])  # an estimate begun at n labels
        if self._work is None or not (all_at_once or first or step):
            return
        n0, raw = self._work
        while len(raw) < self._lags:
            raw.append(agreement_at(self._W[:n0], self._y[:n0], len(raw), self.k,
                                     len(self.actions), a.block, a.folds, a.max_decisions))
            if not (all_at_once or first):
                break  # one lag a build
        if len(raw) == self._lags:
            self._estimate = (n0, *smoothed_lag(raw))
            self._work = None

    @property
    def lag_agreement(self) -> list[float]:
        """The held-out agreement at each lag 0..max_lag behind ``estimated_lag`` (empty when
        the lag is fixed or not estimated yet)."""
        _ = self.estimated_lag
        return list(self._estimate[2]) if self.lag is None else []

    def _vectors(self, lag: int | None = None) -> np.ndarray:
        """The labelled vectors at ``lag`` (default: the lag estimated)."""
        if lag is None:
            lag = self.estimated_lag
        return np.ascontiguousarray(self._W[:self._n, lag if self._lags > 1 else 0])

    def labelled(self) -> tuple[np.ndarray, list[str]]:
        """The labels as given, in order: per label its features at lags 0..max_lag (the scan
        it names, then the scans shown before it; with a fixed lag, one column: the scan it
        was paired with), (labels, lags, dim), and its action's name."""
        return (self._W[:self._n].copy(),
                [self.actions.names[i] for i in self._y[:self._n]])

    def _edit(self, votes: np.ndarray) -> np.ndarray:
        """The edited label (an action index) of each row of ``votes``: the rule's vote."""
        return sided_actions(votes, self.actions, self.rule.editing.side_share)

    def _copies(self, X: np.ndarray) -> np.ndarray:
        """The jittered copies of the labelled vectors ``X`` (``copies`` a label, in order),
        their noise drawn once for each label as it came (seeded: the same copies whatever
        the build)."""
        want = len(X) * self.copies
        if len(self._noise) < want:
            self._noise = np.concatenate([self._noise, self._rng.normal(
                0.0, self.sigma, (want - len(self._noise), X.shape[1]))])
        return np.clip(np.repeat(X, self.copies, axis=0) + self._noise[:want], 0.0, 1.0)

    def _update(self) -> tuple[np.ndarray, np.ndarray]:
        """The training set, votes brought up to date (``_Edited``): (rows, edited labels)."""
        if self.lag is None:
            self._estimating(all_at_once=not self._long(), step=True)
        y = self._y[:self._n]
        lag = self.estimated_lag
        if (self.background and self._edited is not None and self._edited.lag != lag
                and self._long()):
            lag = self._revoting(lag, y)
        X = self._vectors(lag)
        if self._edited is None or self._edited.lag != lag or self._edited.n > len(X):
            self._edited = _Edited(lag, self.k, len(self.actions), self._edit)  # all again
        ed = self._edited
        ed.update(X, self._copies(X), y)
        # what the tree has not learned yet, for ``_build`` (labels' and copies' own indices:
        # a row's index in ``rows()`` moves as labels come)
        self._stale |= ed.fresh
        self._pending.append((ed.changed[ed.changed < ed.n], ed.changed[ed.changed >= ed.n] - ed.n))
        return ed.rows(), ed.labels

    def _revoting(self, lag: int, y: np.ndarray) -> int:
        """With ``background``, a new ``lag`` estimated: every vote at it taken beside, the
        lag the tree was built with kept meanwhile; returns the lag to build with now (the
        new one once its votes are done: every vote was taken again)."""
        job = self._revote
        if job is not None and job.lag != lag:
            job = self._revote = None  # estimated otherwise since: that vote is dropped
        if job is None:
            X = self._vectors(lag)
            self._revote = _Beside(_voted(lag, self.k, len(self.actions), self._edit, X,
                                          self._copies(X), y.copy()), lag=lag)
            return self._edited.lag
        if not job.done():
            return self._edited.lag
        self._revote = None
        if job.result is None:  # it failed: voted again here, at once
            log.error("voting a person's labels at lag %d failed: %r", lag, job.error)
            self._edited = None
        else:
            self._edited, self._stale = job.result, True
        return lag

    def training_set(self) -> tuple[np.ndarray, np.ndarray]:
        """``(X, y)`` the tree is built from: the labelled vectors with their edited labels,
        then their jittered copies with theirs, label indices into ``actions.names``, in the
        order the tree learns them (shuffled with the rule's seed)."""
        if self._n == 0:
            return np.zeros((0, self.features.dim)), np.zeros(0, np.int64)
        rows, labels = self._update()
        order = self._orders(len(labels), 1)[0]
        return rows[order], labels[order]

    def _orders(self, n: int, passes: int | None = None) -> list[np.ndarray]:
        """The first ``passes`` (default: the rule's) of the rule's orders of ``n`` vectors,
        shuffled with its seed (the first: ``training_set``'s); the same whatever the build."""
        rng = copy.deepcopy(self._rng)
        return [rng.permutation(n) for _ in range(self.rule.passes if passes is None else passes)]

    def _build(self):
        """The tree of ``training_set``, learned in the rule's ``passes`` orders; past the
        rule's ``extend_above`` vectors, the tree so far (a copy) extended with the vectors
        new or voted otherwise since (in ``passes`` orders shuffled with the seed), learned
        again from every vector once they grew by the alignment's ``regrow`` since it last
        was (or every vote was taken again): at once, or with ``background`` beside
        (``_live``)."""
        from rhbl import HypersphereClassifier

        names = np.array(self.actions.names)
        if self._n == 0:
            return HypersphereClassifier(**{"default_label": names[0], **self.tree_params})
        rows, labels = self._update()
        ext = self.rule.extend_above
        pending, stale, self._stale, self._pending = self._pending, self._stale, False, []
        extending = (ext is not None and self._clf is not None and self._whole is not None
                     and len(labels) >= ext)
        if extending and self.background:
            clf = self._live(rows, labels, pending, stale)
        elif (extending and not stale
              and len(labels) < self._whole * (1.0 + self.rule.alignment.regrow)):
            clf = self._extended(copy.deepcopy(self._clf), rows, labels, pending)
        else:
            clf = _learned_whole(
                HypersphereClassifier(**{"default_label": names[0], **self.tree_params}),
                rows, names[labels], self._orders(len(labels)))
            self._whole = len(labels)
        self._tree_n = self._edited.n
        return clf

    def _extended(self, clf, rows: np.ndarray, labels: np.ndarray, pending: list):
        """``clf`` extended with the ``pending`` (labels, copies) (their rows in ``rows``),
        in the rule's ``passes`` orders."""
        n = self._edited.n
        todo = np.unique(np.concatenate([np.zeros(0, np.int64)]
                                        + [np.concatenate([x, n + q]) for x, q in pending]))
        names = np.array(self.actions.names)
        for order in self._orders(len(todo)) if len(todo) else []:
            clf.partial_fit(rows[todo[order]], names[labels[todo[order]]])
        return clf

    def _live(self, rows: np.ndarray, labels: np.ndarray, pending: list, stale: bool):
        """A build with ``background``: the relearned tree once it is done (extended with what
        came since it began), else the tree so far extended with ``pending``; a relearn begun
        when the vectors grew by ``regrow`` since the last (or every vote was taken again: the
        one under way is cancelled, and meanwhile only the new labels are added to the tree
        of the old votes)."""
        from rhbl import HypersphereClassifier

        job, names = self._job, np.array(self.actions.names)
        if stale:
            n, c, old = self._edited.n, self.copies, self._tree_n
            pending = [(np.arange(old, n), np.arange(old * c, n * c))]
            if job is not None:
                job.cancel()
                job = self._job = None
        if job is not None and job.done():
            self._job = None
            if job.result is None:  # it failed: the tree so far stays, relearned at the next
                log.error("relearning the person's tree failed: %r", job.error)  # growth
                self._whole = job.size
                clf = copy.deepcopy(self._clf)
            else:
                clf, self._whole, pending = job.result, job.size, job.since + pending
                log.info("took the tree learned again beside from %d vectors (%.1f s), "
                         "extended with %d changes since", job.size,
                         time.monotonic() - job.began, sum(len(x) + len(q) for x, q in pending))
        else:
            clf = copy.deepcopy(self._clf)  # (a tree handed out before stays as it was)
            if job is not None:
                job.since += pending
        if self._job is None and (stale or self._whole is None or len(labels)
                                  >= self._whole * (1.0 + self.rule.alignment.regrow)):
            tree = {"default_label": names[0], **self.tree_params}
            self._job = _Beside(_relearned(lambda: HypersphereClassifier(**tree), rows.copy(),
                                           names[labels], self._orders(len(labels))),
                                size=len(labels), began=time.monotonic(), since=[])
        return self._extended(clf, rows, labels, pending)

    @property
    def relearning(self) -> bool:
        """Work beside (``background``: the votes at a new lag, or the tree learned again) is
        under way, or done and not taken yet."""
        return self._job is not None or self._revote is not None

    def wait_relearned(self, timeout: float | None = None) -> bool:
        """Wait until the work beside under way (if any) is done; True when none is under way
        now (the next build takes it; a new lag's votes taken begin a relearn)."""
        return all(j is None or j.wait(timeout) for j in (self._revote, self._job))

    def __getstate__(self) -> dict:  # a copy has nothing under way beside: it begins its own
        state = dict(self.__dict__)
        state["_job"] = state["_revote"] = None
        return state

    def metadata(self) -> dict:
        meta = super().metadata()
        lag = (self._edited.lag if self.background and self._edited is not None
               else self.estimated_lag)  # (a new lag's votes beside: the tree's lag)
        meta["learning"] = {**self.rule.to_dict(), "estimated_lag": lag}
        return meta

    @classmethod
    def from_metadata(cls, meta: Mapping, features: FeatureSpec, actions: ActionSet,
                      parent: str | None = None, background: bool = False) -> PersonLearner:
        """An empty learner by the rule ``meta`` records (a snapshot's or a journal header's:
        ``LearningRule.of``): its labels are learned again from the journal."""
        rule = LearningRule.of(meta)
        if not rule.person:
            raise ValueError(f"not a person's tree: learning rule {rule.name!r}")
        return cls(features, actions, rule=rule, task=meta.get("task"), parent=parent,
                   background=background)

    def compact(self, *args, **kw):
        raise ValueError("a PersonLearner's tree is rebuilt from its labels: compact the "
                         "saved snapshot instead (rhbl compact)")
