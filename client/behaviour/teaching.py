"""Learning from a person: what to do with labels given by hand at the console.

People react 200-450 ms after what they see, press wrong keys, over-steer and correct
themselves; the scripted teachers do none of that. Learning every label as it arrives (the
paper's rule, ``DemonstrationLearner``) carves a sphere for every late or wrong key, and the
tree copies the noise. These pieces cope with it (docs/teaching.md has the study behind them):

* **the reaction lag** (``answered_scan``, on the console's side): a key held while scan ``n``
  is displayed answers what the person saw ``lag`` scans earlier, so the label is tied to scan
  ``n - lag`` (the scan displayed when the key went out, as today, if that one is unknown or the
  robot was moved since).
* **the lag estimated from the data** (``PersonLearner(lag=None)``, the default; ``rhbl learner
  --lag auto``; ``estimate_lag``): each label also carries the scans shown up to ``MAX_LAG`` scans before its
  own; the lag is the shift at which the labels agree best with the features of the scan that
  many scans earlier, held out in blocks of time (a person's key is most predictable from what
  they saw a reaction time ago), re-estimated from every label at each build.
* **the vote** (``PersonLearner``, on the learner's side): every label is kept as given; the
  tree is built from all of them at once, each labelled vector taking the action nearest to the
  mean command of those of its ``k`` nearest labelled vectors that agree on the side
  (``vote="sided"``, the default: ``sided_actions``), to their interquartile mean command
  (``"trimmed"``), to their mean command (``"mean"``), to their
  median forward and turning speeds (``"median"``), to their median turning and mean forward
  speed (``"median-turn"``) or the label most of them carry
  (``"majority"``): a wrong key or a late release is outvoted by the labels
  around it.
* **jittered copies** (``copies``, 1 by default): each labelled vector also gives the tree a
  copy moved by normal noise of ``sigma`` (0.06: 12 cm of range), labelled by the same vote at
  that place. A tree answers the states nobody showed with whichever sphere came first there;
  the copies make it answer the states around the labels as their neighbours vote, whatever
  the order it learned them in.

    shown = 812                                         # the scan the page displayed
    answered = answered_scan(shown, scans, lag=LAG)     # scans: id -> scan (with .pose)
    learner = PersonLearner(FEATURES["around"], DEFAULT_ACTIONS)
    learner.observe(ranges, yaw, "fwd-left")            # the label, tied to the answered scan
    learner.classifier                                  # the tree of every label so far (rebuilt
                                                        # when labels came since it was last asked)

Pure (no zenoh, no I/O): the processes and the in-process study run this same code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from process import arguments

from .actions import DEFAULT_ACTIONS, ActionSet
from .features import FeatureSpec
from .learning import DemonstrationLearner

__all__ = [
    "JUMP",
    "PERSON_RULE",
    "LAG",
    "MAX_LAG",
    "estimate_lag",
    "parse_lag",
    "PERSON_DEFAULTS",
    "PersonLearner",
    "VOTES",
    "answered_scan",
    "majority_labels",
    "mean_actions",
    "median_actions",
    "median_turn_actions",
    "trimmed_actions",
    "sided_actions",
    "nearest_votes",
]

LAG = 3  # scans (0.3 s at 10 Hz) between what a person saw and the scan shown when the key went out
MAX_LAG = 6  # scans: the longest lag estimated (0.6 s at 10 Hz)
MIN_ESTIMATE = 200  # labels: fewer, and the lag is not estimated (LAG is used)
MAX_DECISIONS = 2000  # the lag estimate answers at most this many changes of key
JUMP = 0.5  # m: the robot moved farther than this between two scans: it was put there (set_pose)
_CHUNK = 1 << 22  # distances computed per block (query rows x references)


def answered_scan(shown: int, scans: Mapping[int, object], lag: int = LAG,
                  pose: Callable[[object], tuple] = lambda s: s.pose,
                  jump: float = JUMP) -> int:
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


def nearest_votes(Q: np.ndarray, X: np.ndarray, y: np.ndarray, k: int,
                  n_labels: int) -> np.ndarray:
    """(len(Q), n_labels): for each row of ``Q`` the count of each label index of ``y`` among
    its ``k`` nearest rows of ``X`` (squared Euclidean distance; ties broken by numpy's
    partition)."""
    n = len(X)
    k = max(1, min(int(k), n))
    out = np.zeros((len(Q), n_labels))
    xx = np.einsum("ij,ij->i", X, X)
    step = max(1, _CHUNK // max(1, n))
    for s in range(0, len(Q), step):
        q = Q[s:s + step]
        d = np.einsum("ij,ij->i", q, q)[:, None] + xx[None, :] - 2.0 * q @ X.T
        nn = (np.argpartition(d, k - 1, axis=1)[:, :k] if k < n
              else np.broadcast_to(np.arange(n), (len(q), n)))
        flat = np.repeat(np.arange(len(q)) * n_labels, nn.shape[1]) + y[nn].ravel()
        out[s:s + step] = np.bincount(flat, minlength=len(q) * n_labels).reshape(len(q),
                                                                                 n_labels)
    return out


def majority_labels(X: np.ndarray, y: np.ndarray, k: int, n_labels: int) -> np.ndarray:
    """The label index most of each row's ``k`` nearest rows of ``X`` carry (the row itself
    among them); a tie keeps the row's own label."""
    votes = nearest_votes(X, X, y, k, n_labels)
    rows = np.arange(len(y))
    best = votes.argmax(axis=1)
    return np.where(votes[rows, y] >= votes[rows, best], y, best)


def _commands(actions: ActionSet) -> np.ndarray:
    """(actions, 2): each action's (vx, va), each scaled by the largest of the set."""
    v = np.array([actions[n] for n in actions.names], dtype=np.float64)
    return v / np.maximum(np.abs(v).max(axis=0), 1e-12)


def _nearest_action(points: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per row of ``points`` (scaled commands) the index of the nearest row of ``v``."""
    return ((points[:, None, :] - v[None, :, :]) ** 2).sum(axis=2).argmin(axis=1)


def mean_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` (counts per action index) the index of the action nearest to the
    votes' mean command ((vx, va) averaged, each scaled by the largest of the set): a person
    steering left, right, left along a wall means forward."""
    v = _commands(actions)
    return _nearest_action(_mean_commands(votes, v), v)


def _mean_commands(votes: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(len(votes), 2): per row the mean of the scaled commands ``v`` weighted by the counts."""
    return votes @ v / np.maximum(votes.sum(axis=1, keepdims=True), 1e-12)


def _median_commands(votes: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(len(votes), 2): per row the median of each column of the scaled commands ``v``
    weighted by the counts (a count split exactly in half takes the midpoint of the two middle
    values)."""
    half = votes.sum(axis=1, keepdims=True) / 2.0
    med = np.empty((len(votes), v.shape[1]))
    for c in range(v.shape[1]):
        order = np.argsort(v[:, c], kind="stable")
        cum = np.cumsum(votes[:, order], axis=1)
        lo = v[order, c][np.argmax(cum >= half - 1e-9, axis=1)]
        hi = v[order, c][np.argmax(cum > half + 1e-9, axis=1)]
        med[:, c] = 0.5 * (lo + hi)
    return med


def median_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` (counts per action index) the index of the action nearest to the
    votes' median command: the median of the forward speeds and the median of the turning
    speeds, each taken apart (scaled as in ``mean_actions``). Unlike the mean, a minority of
    keys on the other side (left and right confused) does not pull a turn towards forward."""
    v = _commands(actions)
    return _nearest_action(_median_commands(votes, v), v)


def median_turn_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` the index of the action nearest to the median turning speed and
    the mean forward speed (scaled as in ``mean_actions``): the turn is kept from a minority
    on the other side as by ``median_actions``, the pace is the mean's (a median of the
    forward speeds drops to a rotation on the spot as soon as half the keys were one)."""
    v = _commands(actions)
    cmd = _median_commands(votes, v)
    cmd[:, 0] = _mean_commands(votes, v)[:, 0]
    return _nearest_action(cmd, v)


def _trimmed_commands(votes: np.ndarray, v: np.ndarray, trim: float) -> np.ndarray:
    """(len(votes), 2): per row the mean of each column of the scaled commands ``v`` weighted
    by the counts, the lowest and the highest ``trim`` of the counts left out (0: the mean;
    towards 0.5: the median)."""
    total = votes.sum(axis=1, keepdims=True)
    lo, hi = trim * total, (1.0 - trim) * total
    out = np.empty((len(votes), v.shape[1]))
    for c in range(v.shape[1]):
        order = np.argsort(v[:, c], kind="stable")
        cum = np.cumsum(votes[:, order], axis=1)
        kept = np.clip(np.minimum(cum, hi) - np.maximum(cum - votes[:, order], lo), 0.0, None)
        out[:, c] = kept @ v[order, c] / np.maximum(hi - lo, 1e-12)[:, 0]
    return out


def trimmed_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` the index of the action nearest to the votes' interquartile mean
    command: the forward and the turning speeds each taken apart, their lowest and highest
    quarter left out, the middle half averaged (scaled as in ``mean_actions``). Between the
    mean and the median: a zig-zag of left and right keys in like numbers still averages to
    forward, and a quarter of keys on the other side (left and right confused) does not pull a
    turn towards forward."""
    v = _commands(actions)
    return _nearest_action(_trimmed_commands(votes, v, 0.25), v)


SIDED = 2 / 3  # "sided": a turning side with less than this share of the other's is dropped


def _sided_commands(votes: np.ndarray, v: np.ndarray, share: float = SIDED) -> np.ndarray:
    """(len(votes), 2): per row the mean of the scaled commands ``v`` weighted by the counts,
    the keys turning to one side left out when they weigh less than ``share`` of those turning
    to the other (forward keys always count)."""
    left, right = v[:, 1] > 0, v[:, 1] < 0
    wl, wr = votes[:, left].sum(axis=1), votes[:, right].sum(axis=1)
    keep = np.ones_like(votes)
    keep[:, right] = (wr >= share * wl)[:, None]
    keep[:, left] = (wl >= share * wr)[:, None]
    return _mean_commands(votes * keep, v)


def sided_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` the index of the action nearest to the mean command of the keys
    that agree on the side: turning keys to one side weighing less than two thirds of those
    to the other are taken for confusions (left and right, or a turn let go of late) and left
    out, the rest averaged (scaled as in ``mean_actions``). A zig-zag of left and right in like
    numbers averages to forward, as with the mean; forward keys with a minority of turns to
    one side (a person who steers by tapping a rotation between forward presses, never an
    arc) keep that turn's weight, as with the mean and unlike the trimmed mean; a minority on
    the other side does not pull a turn towards forward, as with the median."""
    v = _commands(actions)
    return _nearest_action(_sided_commands(votes, v), v)


_VOTES = {"mean": mean_actions, "median": median_actions, "median-turn": median_turn_actions,
          "trimmed": trimmed_actions, "sided": sided_actions}
VOTES = ("majority", *_VOTES)  # PersonLearner's vote= and --vote


def parse_lag(text: str) -> int | None:
    """A ``--lag`` value: ``auto`` (None: estimated from the labels) or an integer 0..MAX_LAG
    (ValueError naming what is wrong otherwise)."""
    if text.strip() == "auto":
        return None
    try:
        lag = int(text.strip())
    except ValueError:
        lag = -1
    if not 0 <= lag <= MAX_LAG:
        raise ValueError(f"must be 'auto' or an integer 0..{MAX_LAG} (scans), got {text!r}")
    return lag


def add_person_arguments(parser) -> None:
    """``--lag SCANS|auto`` (``parse_lag``; None: estimated) and ``--vote`` (None: the
    default, ``PERSON_DEFAULTS``) as ``rhbl learner`` and ``rhbl train --from-recording``
    take them."""
    parser.add_argument("--lag", type=arguments.Checked("lag", parse_lag), default=None,
                        metavar="SCANS|auto",
                        help="with the person rule: a label answers the scan this many scans "
                             f"(0..{MAX_LAG}) before the one it names; 'auto' (default): "
                             "estimated from the labels, re-estimated as they accumulate "
                             f"({LAG} until there are enough; docs/teaching.md)")
    parser.add_argument("--vote", choices=VOTES, default=None,
                        help="with the person rule, a new tree's vote of the nearest labels: "
                             "the action nearest to the mean command of those that agree on the "
                             "side (sided), their interquartile mean command (trimmed), their "
                             "mean command, their median command, their median turning and mean "
                             "forward speed (median-turn) or "
                             f"the label most of them carry (default {PERSON_DEFAULTS['vote']}; "
                             "docs/teaching.md)")


def estimate_lag(W: np.ndarray, y: np.ndarray, k: int, n_labels: int, block: int = 50,
                 folds: int = 5, decisions: int = MAX_DECISIONS) -> tuple[int, list[float]]:
    """The lag (0 .. ``W.shape[1] - 1`` scans) at which the person's decisions are best
    predicted from the features ``W[:, lag]`` of the scan that many scans before each label's
    own, and the agreement at every lag. ``W``: (labels, lags, dim) in the order given.

    The decisions are the labels on either side of a change of key (the last label of a key
    and the first of the next): while a key is held every lag sees nearly the same place, so
    only the changes tell when the person reacted; at the right lag the last label before a
    change still sees the old side of the person's boundary and the first after it the new
    side (a shorter lag sees the new side already before the change, a longer one the old side
    still after it). Each is answered by the majority of its ``k``
    nearest labels held out by time (the labels cut in blocks of ``block`` consecutive ones,
    dealt round-robin into ``folds`` folds; the references are the other folds: consecutive
    labels are near copies of each other). The agreement is smoothed over neighbouring lags
    (weights 1/4, 1/2, 1/4: a few hundred decisions are noisy) and ties go to the shorter lag.
    More than ``decisions`` decisions (a session of tens of minutes): that many of them, evenly
    spread over the session, are answered (each against every other fold's label as before),
    so the estimate's cost grows with the labels, not with their square.
    Deterministic: a function of ``W`` and ``y`` only."""
    n = len(y)
    fold = (np.arange(n) // block) % folds
    change = y[1:] != y[:-1]
    q = np.flatnonzero(np.r_[True, change] | np.r_[change, False])
    if len(q) > decisions:
        q = q[np.linspace(0, len(q) - 1, decisions).round().astype(np.int64)]
    raw = []
    for lag in range(W.shape[1]):
        X = W[:, lag]
        hit = 0
        for f in range(folds):
            qi, ri = q[fold[q] == f], np.flatnonzero(fold != f)
            if not len(qi) or not len(ri):
                continue
            votes = nearest_votes(X[qi], X[ri], y[ri], k, n_labels)
            hit += int((votes.argmax(axis=1) == y[qi]).sum())
        raw.append(hit / max(1, len(q)))
    a = np.array(raw)
    smooth = 0.5 * a + 0.25 * np.r_[a[:1], a[:-1]] + 0.25 * np.r_[a[1:], a[-1:]]
    return int(np.argmax(smooth)), [float(v) for v in smooth]


PERSON_RULE = "person"  # the snapshot metadata's learning rule of a PersonLearner

# the defaults docs/teaching.md chose on the teaching study
PERSON_DEFAULTS = {"k": 50, "copies": 1, "sigma": 0.06, "vote": "sided", "passes": 1,
                   "build": "batch"}


class PersonLearner(DemonstrationLearner):
    """A ``DemonstrationLearner`` for labels given by a person (see the module's docstring).

    Every label offered (``observe``, ``observe_vector``) is kept; ``classifier`` is the tree
    built from all of them (spawn rule and other ``**tree_params`` as for
    ``DemonstrationLearner``, default ``spawn="winner"``), rebuilt when labels came since it
    was last asked for, in up to ``passes`` shuffled passes (``_build``). ``k``: neighbours of the vote. ``vote``: ``"majority"`` (the label most
    of them carry), ``"mean"`` (the action nearest to their mean command), ``"median"``
    (nearest to their median command: ``median_actions``), ``"median-turn"`` (their median
    turning and mean forward speed: ``median_turn_actions``), ``"trimmed"`` (their
    interquartile mean command: ``trimmed_actions``) or ``"sided"`` (the mean command of those
    that agree on the side: ``sided_actions``; the default, also for None). ``copies``,
    ``sigma``: jittered copies of each vector (normal noise of ``sigma`` in feature units,
    seeded with ``seed``) the tree also learns the vote's answer at (0: none; 1 by default). Sample
    selection (``stride``, ``min_delta``) does not apply: the vote needs every label."""

    def __init__(self, features: FeatureSpec, actions: ActionSet = DEFAULT_ACTIONS, *,
                 k: int = PERSON_DEFAULTS["k"], copies: int = PERSON_DEFAULTS["copies"],
                 sigma: float = PERSON_DEFAULTS["sigma"], vote: str | None = PERSON_DEFAULTS["vote"],
                 passes: int = PERSON_DEFAULTS["passes"], build: str = PERSON_DEFAULTS["build"],
                 seed: int = 0, lag: int | None = None, task: str | None = None,
                 parent: str | None = None, provenance: Mapping | None = None, **tree_params):
        if not (isinstance(k, int) and k >= 1):
            raise ValueError(f"k must be an integer >= 1, got {k!r}")
        if not (isinstance(copies, int) and copies >= 0):
            raise ValueError(f"copies must be an integer >= 0, got {copies!r}")
        if not (sigma >= 0 and math.isfinite(sigma)):
            raise ValueError(f"sigma must be a finite number >= 0, got {sigma!r}")
        vote = PERSON_DEFAULTS["vote"] if vote is None else vote
        if vote not in VOTES:
            raise ValueError("vote must be one of " + ", ".join(map(repr, VOTES))
                             + f", got {vote!r}")
        if not (isinstance(passes, int) and passes >= 1):
            raise ValueError(f"passes must be an integer >= 1, got {passes!r}")
        if build not in ("batch", "repair"):
            raise ValueError(f"build must be 'batch' or 'repair', got {build!r}")
        if build == "repair" and copies:
            raise ValueError("build 'repair' learns the labelled vectors only (copies=0)")
        if lag is not None and not (isinstance(lag, int) and 0 <= lag <= MAX_LAG):
            raise ValueError(f"lag must be None (estimated) or an integer 0..{MAX_LAG}, got "
                             f"{lag!r}")
        self.build = build
        # None: estimated from the labels (each keeps the scans before its own: ``observe``'s
        # ``earlier``); an integer: fixed, the scans the labels were shifted by when paired
        self.lag = lag
        self._ws: list[np.ndarray] = []  # lag None: per label its features at lags 0..MAX_LAG
        self._estimate: tuple[int, int, list[float]] | None = None  # (labels, lag, agreement)
        self.k, self.copies, self.sigma, self.vote = k, copies, float(sigma), vote
        self.passes, self.seed = passes, seed
        self._xs: list[np.ndarray] = []
        self._ys: list[int] = []
        self._clf = None
        self._built = -1
        tree_params.setdefault("spawn", "winner")
        super().__init__(features, actions, task=task, parent=parent, provenance=provenance,
                         **tree_params)

    # the tree: built from every label when asked for
    @property
    def classifier(self):
        if self._built != len(self._ys):
            self._clf = self._build()
            self._built = len(self._ys)
        return self._clf

    @classifier.setter
    def classifier(self, clf) -> None:  # DemonstrationLearner's __init__: the empty tree
        self._clf = clf
        self._built = len(self._ys)

    def _learn(self, x: np.ndarray, label: str, earlier=None) -> None:
        self._xs.append(np.asarray(x, dtype=np.float64).reshape(-1))
        self._ys.append(self.actions.names.index(label))
        if self.lag is None:  # lags 0..MAX_LAG; those not held: the label's own scan
            w = np.repeat(self._xs[-1][None, :], MAX_LAG + 1, axis=0)
            if earlier is not None and len(earlier):
                e = np.asarray(earlier, dtype=np.float64).reshape(-1, self.features.dim)
                w[1:1 + min(len(e), MAX_LAG)] = e[:MAX_LAG]
            self._ws.append(w)
        self.vectors += 1
        if self._rec_x is not None:
            self._rec_x.append(self._xs[-1])
            self._rec_y.append(label)

    def observe(self, ranges, yaw: float, label: str, earlier=None) -> bool:
        """Keep one labelled observation (every one is kept: True). ``earlier``: with the lag
        estimated (``lag=None``), the feature vectors of the scans shown 1, 2, ... scans before
        this one (nearest first, at most ``MAX_LAG``; fewer when they are not known or the
        robot was put elsewhere: the lags beyond take this scan)."""
        return self.observe_vector(self.features.extract(ranges, yaw), label, earlier)

    def observe_vector(self, x: np.ndarray, label: str, earlier=None) -> bool:
        self._check_label(label)
        self.seen += 1
        self._learn(x, label, earlier)
        return True

    @property
    def estimated_lag(self) -> int:
        """The lag the tree is built with: fixed, or estimated from every label so far
        (``estimate_lag`` over lags 0..MAX_LAG; ``LAG`` below ``MIN_ESTIMATE`` labels)."""
        if self.lag is not None:
            return self.lag
        n = len(self._ys)
        if self._estimate is None or self._estimate[0] != n:
            if n < MIN_ESTIMATE:
                self._estimate = (n, LAG, [])
            else:
                lag, agree = estimate_lag(np.stack(self._ws), np.array(self._ys, np.int64),
                                          self.k, len(self.actions))
                self._estimate = (n, lag, agree)
        return self._estimate[1]

    @property
    def lag_agreement(self) -> list[float]:
        """The held-out agreement at each lag 0..MAX_LAG behind ``estimated_lag`` (empty when
        the lag is fixed or not estimated yet)."""
        _ = self.estimated_lag
        return list(self._estimate[2]) if self.lag is None else []

    def _vectors(self) -> np.ndarray:
        """The labelled vectors at the lag the tree is built with."""
        if self.lag is None and self._ws:
            return np.stack(self._ws)[:, self.estimated_lag]
        return np.array(self._xs, dtype=np.float64).reshape(-1, self.features.dim)

    def labelled(self) -> tuple[np.ndarray, list[str]]:
        """The labels as given, in order: per label its features at lags 0..``MAX_LAG`` (the
        scan it names, then the scans shown before it; with a fixed lag, one column: the scan
        it was paired with), (labels, lags, dim), and its action's name."""
        W = (np.stack(self._ws) if self.lag is None and self._ws
             else np.array(self._xs, dtype=np.float64).reshape(-1, 1, self.features.dim))
        return W, [self.actions.names[i] for i in self._ys]

    def observe_vectors(self, X: np.ndarray, labels) -> int:
        X, labels = self._checked(X, labels)
        for x, label in zip(X, labels, strict=True):  # (no earlier scans: lag 0 if estimated)
            self.seen += 1
            self._learn(x, label)
        return len(X)

    def training_set(self) -> tuple[np.ndarray, np.ndarray]:
        """``(X, y)`` the tree is built from: the labelled vectors with the vote's labels (and
        the jittered copies), label indices into ``actions.names``, in the order the tree
        learns them (shuffled with ``seed``)."""
        X = self._vectors()
        y = np.array(self._ys, dtype=np.int64)
        if len(y) == 0:
            return X, y
        n = len(self.actions)
        if self.vote in _VOTES:
            ym = _VOTES[self.vote](nearest_votes(X, X, y, self.k, n), self.actions)
        else:
            ym = majority_labels(X, y, self.k, n)
        rng = np.random.default_rng(self.seed)
        if self.copies == 0:
            order = rng.permutation(len(ym))
            return X[order], ym[order]
        Q = np.clip(np.repeat(X, self.copies, axis=0)
                    + rng.normal(0.0, self.sigma, (len(X) * self.copies, X.shape[1])), 0.0, 1.0)
        votes = nearest_votes(Q, X, y, self.k, n)
        yq = (_VOTES[self.vote](votes, self.actions) if self.vote in _VOTES
              else votes.argmax(axis=1))
        XA, yA = np.concatenate([X, Q]), np.concatenate([ym, yq])
        order = rng.permutation(len(yA))
        return XA[order], yA[order]

    def _build(self):
        """The tree of ``training_set``, learned in passes over it until it answers every
        vector with its label (at most ``passes``): presented in the order taught, a run along
        one wall carves one big sphere that hides what came before; shuffled and repeated, the
        spheres follow the labels."""
        from rhbl import HypersphereClassifier

        if self.build == "repair" and getattr(self._clf, "tree_", None) is not None:
            clf = self._clf  # the tree so far, repaired where it disagrees with the vote
            X = self._vectors()
            y = np.array(self._ys, dtype=np.int64)
            y = majority_labels(X, y, self.k, len(self.actions))
        else:
            params = {"default_label": self.actions.names[0], **self.tree_params}
            clf = HypersphereClassifier(**params)
            X, y = self.training_set()
        if len(y):
            labels = np.array(self.actions.names)[y]
            todo = np.arange(len(y)) if clf is not self._clf else None
            for _ in range(self.passes):
                if todo is None:  # repair: only where the tree disagrees with the vote
                    todo = np.flatnonzero(clf.predict(X) != labels)
                if len(todo):
                    clf.partial_fit(X[todo], labels[todo])
                todo = np.flatnonzero(clf.predict(X) != labels)
                if not len(todo):
                    break
        return clf

    def metadata(self) -> dict:
        meta = super().metadata()
        meta["learning"] = {"rule": PERSON_RULE, "lag": self.lag,
                            "estimated_lag": self.estimated_lag, "k": self.k, "copies": self.copies,
                            "sigma": self.sigma, "vote": self.vote, "passes": self.passes,
                            "build": self.build,
                            "seed": self.seed}
        return meta

    @classmethod
    def from_metadata(cls, meta: Mapping, features: FeatureSpec, actions: ActionSet,
                      parent: str | None = None) -> PersonLearner:
        """An empty learner with the settings ``metadata()`` recorded in ``meta`` (a snapshot's
        or a journal header's): its labels are learned again from the journal."""
        learning = dict(meta.get("learning") or {})
        if learning.get("rule") != PERSON_RULE:
            raise ValueError(f"not a person's tree: learning rule {learning.get('rule')!r}")
        opts = {k: learning[k] for k in ("k", "copies", "sigma", "vote", "passes", "build",
                                         "seed", "lag") if k in learning}
        return cls(features, actions, task=meta.get("task"), parent=parent,
                   **opts, **(meta.get("tree_params") or {}))

    def compact(self, *args, **kw):
        raise ValueError("a PersonLearner's tree is rebuilt from its labels: compact the "
                         "saved snapshot instead (rhbl compact)")
