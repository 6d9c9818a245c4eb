"""The votes the teaching studies compared, kept for them (the product has one: the person
rule's sided vote, ``client.behaviour.teaching.sided_actions``).

``StudyLearner`` is a ``PersonLearner`` that edits its labels by another of them
(``vote=``): ``"majority"`` (the label most of the ``k`` nearest carry; a tie keeps the own),
``"mean"`` (the action nearest to their mean command), ``"median"`` (their median forward and
turning speeds), ``"median-turn"`` (their median turning and mean forward speed),
``"trimmed"`` (their interquartile mean command) or ``"sided"`` (the product's). The
benchmarks take them by name (``bench_teach_study.make_method``: ``person:vote=median``);
docs/studies/teaching-in-process.md and teaching-at-the-page.md measured them.
"""

from __future__ import annotations

import numpy as np

from client.behaviour.actions import ActionSet
from client.behaviour.teaching import (
    PersonLearner,
    _commands,
    _mean_commands,
    _nearest_action,
    nearest_votes,
    sided_actions,
)

__all__ = ["StudyLearner", "VOTES", "majority_labels", "mean_actions", "median_actions",
           "median_turn_actions", "trimmed_actions"]


def majority_labels(X: np.ndarray, y: np.ndarray, k: int, n_labels: int) -> np.ndarray:
    """The label index most of each row's ``k`` nearest rows of ``X`` carry (the row itself
    among them); a tie keeps the row's own label."""
    votes = nearest_votes(X, X, y, k, n_labels)
    rows = np.arange(len(y))
    best = votes.argmax(axis=1)
    return np.where(votes[rows, y] >= votes[rows, best], y, best)


def mean_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` the index of the action nearest to the votes' mean command."""
    v = _commands(actions)
    return _nearest_action(_mean_commands(votes, v), v)


def _median_commands(votes: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(len(votes), 2): per row the median of each column of ``v`` weighted by the counts (a
    count split exactly in half takes the midpoint of the two middle values)."""
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
    """Per row of ``votes`` the index of the action nearest to the votes' median command (the
    forward and the turning speeds each taken apart)."""
    v = _commands(actions)
    return _nearest_action(_median_commands(votes, v), v)


def median_turn_actions(votes: np.ndarray, actions: ActionSet) -> np.ndarray:
    """Per row of ``votes`` the index of the action nearest to the median turning speed and
    the mean forward speed."""
    v = _commands(actions)
    cmd = _median_commands(votes, v)
    cmd[:, 0] = _mean_commands(votes, v)[:, 0]
    return _nearest_action(cmd, v)


def _trimmed_commands(votes: np.ndarray, v: np.ndarray, trim: float) -> np.ndarray:
    """(len(votes), 2): per row the mean of each column of ``v`` weighted by the counts, the
    lowest and the highest ``trim`` of the counts left out."""
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
    command (each speed's lowest and highest quarter left out)."""
    v = _commands(actions)
    return _nearest_action(_trimmed_commands(votes, v, 0.25), v)


_VOTES = {"mean": mean_actions, "median": median_actions, "median-turn": median_turn_actions,
          "trimmed": trimmed_actions, "sided": sided_actions,
          "majority": lambda votes, actions: votes.argmax(axis=1)}
VOTES = ("majority", "mean", "median", "median-turn", "trimmed", "sided")


class StudyLearner(PersonLearner):
    """A ``PersonLearner`` whose labels are edited by the study vote ``vote`` (one of
    ``VOTES``) instead of the rule's. The majority's tie keeping the row's own label is not
    kept (a copy has none): the label most of the neighbours carry, the first on a tie."""

    def __init__(self, *args, vote: str = "sided", **kw):
        if vote not in _VOTES:
            raise ValueError("vote must be one of " + ", ".join(map(repr, VOTES))
                             + f", got {vote!r}")
        self.vote = vote
        super().__init__(*args, **kw)

    def _edit(self, votes: np.ndarray) -> np.ndarray:
        return _VOTES[self.vote](votes, self.actions)

    def metadata(self) -> dict:
        meta = super().metadata()
        meta["learning"]["vote"] = self.vote
        return meta
