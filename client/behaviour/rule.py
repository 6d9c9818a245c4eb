"""The learning rule: how a tree learns its labels, as one object, chosen in one place.

A ``LearningRule`` says everything between a teacher's labels and what the robot does with
the tree (docs/teaching.md has the study behind each part):

* ``alignment`` (``ReactionAlignment``; reaction-time alignment): a key given by a person
  answers the scan they saw a reaction time before the one displayed when it went out; the lag
  is fixed or estimated from the labels (``client.behaviour.teaching.estimate_lag``). None: a
  label answers the scan it names (a scripted teacher's).
* ``editing`` (``NeighbourEditing``; Wilson's edited nearest neighbour, as kNN smoothing):
  every label is kept as given and the tree learns, for each labelled vector, the action its
  ``k`` nearest labels vote for (``client.behaviour.teaching.sided_actions``), and for
  ``copies`` jittered copies of it the vote at their place. None: each label is learned as it
  arrives (the paper's rule).
* ``tree``: the hypersphere tree's parameters (``rhbl.HypersphereClassifier``: spawn, ...),
  learned from every edited vector ``passes`` times (epochs), each time in another order
  shuffled with ``seed`` (one pass leaves a share of the vectors answered otherwise than they
  were labelled: a sphere spawned later covers them); past ``extend_above`` vectors (about
  1,800 labels with their 10 copies: 3 minutes of teaching) the tree is extended with the
  vectors new or voted otherwise, and learned again at once when they grew by the
  alignment's ``regrow`` (None: always learned again at once).
* ``stride``, ``min_delta``: the paper's rule's sample selection (``DemonstrationLearner``).
* ``guard`` (``GuardSettings``): the controller's safety layer (``client.behaviour.guard``):
  a hysteresis on the direction of rotation (no rotation reversed at once) and a path check
  (no forward order into a laser return straight ahead). It is not the learning: ``rhbl
  evaluate`` judges the tree alone and reports what the guard did beside it.

Nothing in a rule knows which behaviour is taught or on which side a wall is. The rules are
chosen here (``rule_for``: ``PERSON`` for labels given by hand, ``SCRIPT`` for a scripted
teacher's), stored in the snapshot's metadata (``metadata["learning"]``: ``to_dict``) and read
back from it (``LearningRule.of``) by the controller, ``rhbl evaluate``, retraining from
recordings, the learner's recovery and the harness; a snapshot written before the rule was
stored this way gets the rule its metadata describes.

    rule = rule_for("person")                        # or "script"
    rule = rule.replace(lag=4)                       # a fixed reaction lag (--lag 4)
    meta["learning"] = rule.to_dict()                # what a learner writes
    LearningRule.of(meta).guard.clearance            # what the controller reads

Pure (no I/O).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["GuardSettings", "LearningRule", "NeighbourEditing", "PATH_CHECK", "PERSON",
           "ReactionAlignment", "SCRIPT", "for_goals", "rule_for"]

EDITING_METHOD = "wilson-edited-knn"  # the editing's name in the metadata


@dataclass(frozen=True)
class ReactionAlignment:
    """Reaction-time alignment: a person's key answers the scan ``lag`` scans before the one
    displayed when it went out. ``lag`` None: estimated from the labels (``estimate_lag``, at
    the lag 0..``max_lag`` at which the changes of key are best predicted from the scan that
    many before; ``default`` until there are ``min_labels`` labels; at most ``max_decisions``
    changes of key answered, each by the majority of its nearest labels of other ``folds``,
    the labels dealt into them in blocks of ``block``), re-estimated when the labels have grown
    by ``regrow`` (a share) since the last estimate. ``jump`` m: the robot moved farther
    between two scans, it was put there: the person saw another place (the label keeps its
    own scan)."""

    lag: int | None = None
    default: int = 3        # scans (0.3 s at 10 Hz)
    max_lag: int = 6        # scans (0.6 s at 10 Hz)
    min_labels: int = 200
    max_decisions: int = 2000
    folds: int = 5
    block: int = 50
    regrow: float = 0.125
    jump: float = 0.5

    def __post_init__(self):
        if self.lag is not None and not (isinstance(self.lag, int) and 0 <= self.lag <= self.max_lag):
            raise ValueError(f"lag must be None (estimated) or an integer 0..{self.max_lag}, got "
                             f"{self.lag!r}")
        for name in ("default", "max_lag", "min_labels", "max_decisions", "folds", "block"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= (0 if name == "default" else 1)):
                raise ValueError(f"alignment {name} must be an integer >= 1, got {v!r}")
        if not 0 <= self.default <= self.max_lag:
            raise ValueError(f"alignment default must be 0..{self.max_lag}, got {self.default!r}")
        if not (self.regrow >= 0 and self.jump > 0):
            raise ValueError(f"alignment regrow must be >= 0 and jump > 0, got {self.regrow!r}, "
                             f"{self.jump!r}")


@dataclass(frozen=True)
class NeighbourEditing:
    """Wilson's edited nearest neighbour, as kNN smoothing: each labelled vector is learned
    with the action nearest to the mean command of those of its ``k`` nearest labels (itself
    among them) that agree on the turning side (a side weighing less than ``side_share`` of
    the other's is taken for confusions and left out); ``copies`` jittered copies of each
    (normal noise of ``sigma`` per feature) are learned with the vote at their place. ``k``
    and ``copies`` were chosen by an ablation over every behaviour without goals and the
    development person models (``benchmarks/ablate_person_rule.py``; docs/teaching.md). The
    copies are the synthetic examples of model compression: the tree learns the neighbours'
    vote over the space around the labels as well as at them, where the robot driving the tree
    goes when it is a little off the person's path."""

    k: int = 15
    side_share: float = 2 / 3
    copies: int = 10
    sigma: float = 0.15

    def __post_init__(self):
        if not (isinstance(self.k, int) and not isinstance(self.k, bool) and self.k >= 1):
            raise ValueError(f"k must be an integer >= 1, got {self.k!r}")
        if not (isinstance(self.copies, int) and not isinstance(self.copies, bool)
                and self.copies >= 0):
            raise ValueError(f"copies must be an integer >= 0, got {self.copies!r}")
        if not (self.sigma >= 0 and self.sigma < float("inf")):
            raise ValueError(f"sigma must be a finite number >= 0, got {self.sigma!r}")
        if not 0 <= self.side_share <= 1:
            raise ValueError(f"side_share must be 0..1, got {self.side_share!r}")


@dataclass(frozen=True)
class GuardSettings:
    """The controller's guard (``client.behaviour.guard.RotationGuard``), a safety layer:
    ``on`` (False: the tree's answers are driven as they are); an order to reverse a rotation
    within ``memory`` scans of it is overruled for at most ``hold`` scans in a row (driven
    ``straight`` on while the path is clear); with ``clearance`` > 0 m a forward order while a
    laser return lies within ``lookahead`` m ahead and ``clearance`` m of the centre line
    becomes a rotation in place (0: no path check)."""

    on: bool = True
    hold: int = 30          # scans (3 s at 10 Hz)
    memory: int = 5         # scans
    clearance: float = 0.0  # m either side of the centre line (the robot's radius is 0.25)
    lookahead: float = 0.5  # m: two scans' travel at full speed and a margin
    straight: bool = True

    def __post_init__(self):
        if not (self.hold >= 0 and self.memory >= 0):
            raise ValueError(f"guard hold and memory must be >= 0 scans, got {self.hold}, "
                             f"{self.memory}")
        if not (self.clearance >= 0 and self.lookahead > 0):
            raise ValueError(f"guard clearance must be >= 0 and lookahead > 0 m, got "
                             f"{self.clearance}, {self.lookahead}")


@dataclass(frozen=True)
class LearningRule:
    """How a tree learns its labels and how the controller drives it (the module's
    docstring). ``name``: ``person`` (labels given by hand) or ``script``."""

    name: str
    alignment: ReactionAlignment | None = None
    editing: NeighbourEditing | None = None
    tree: Mapping[str, Any] = field(default_factory=lambda: {"spawn": "winner"})
    stride: int = 1
    min_delta: float = 0.0
    guard: GuardSettings = GuardSettings()
    seed: int = 0
    extend_above: int | None = None
    passes: int = 1

    def __post_init__(self):
        object.__setattr__(self, "tree", dict(self.tree))
        if not (isinstance(self.passes, int) and not isinstance(self.passes, bool)
                and self.passes >= 1):
            raise ValueError(f"passes must be an integer >= 1, got {self.passes!r}")
        if self.extend_above is not None and not (isinstance(self.extend_above, int)
                                                  and self.extend_above >= 0):
            raise ValueError(f"extend_above must be None or an integer >= 0 (vectors), got "
                             f"{self.extend_above!r}")
        if (self.editing is None) != (self.alignment is None):
            raise ValueError("a rule edits its labels by their neighbours and aligns them with "
                             "the reaction lag together, or neither")
        if self.editing is not None and (self.stride != 1 or self.min_delta):
            raise ValueError("a rule that edits its labels learns every one (stride 1, "
                             "min_delta 0)")
        if self.editing is None and self.passes != 1:
            raise ValueError("passes are the person rule's (a tree built from every label); "
                             "the script rule learns each label once, as it comes")

    def __hash__(self):
        return hash((self.name, self.alignment, self.editing, tuple(sorted(self.tree.items())),
                     self.stride, self.min_delta, self.guard, self.seed, self.extend_above,
                     self.passes))

    @property
    def person(self) -> bool:
        """The labels are edited (a person's rule): the tree is built from every label."""
        return self.editing is not None

    def replace(self, *, lag: int | None | str = "keep", guard: bool | None = None,
                **changes) -> LearningRule:
        """This rule with ``changes`` (fields), the alignment's ``lag`` (None: estimated) and
        the guard turned on or off (``guard``)."""
        rule = dataclasses.replace(self, **changes) if changes else self
        if lag != "keep":
            if rule.alignment is None:
                raise ValueError("a lag is the person rule's (its reaction-time alignment)")
            rule = dataclasses.replace(rule, alignment=dataclasses.replace(rule.alignment, lag=lag))
        if guard is not None:
            rule = dataclasses.replace(rule, guard=dataclasses.replace(rule.guard, on=bool(guard)))
        return rule

    def to_dict(self) -> dict:
        """The metadata's ``learning`` (the tree's parameters go in ``tree_params``)."""
        out: dict = {"rule": self.name, "seed": self.seed, "guard": dataclasses.asdict(self.guard)}
        if self.person:
            a, e = self.alignment, self.editing
            # the flat keys readers of the earlier metadata know (lag, k, copies, sigma, vote)
            out.update(lag=a.lag, k=e.k, copies=e.copies, sigma=e.sigma, vote="sided",
                       extend_above=self.extend_above, passes=self.passes,
                       alignment=dataclasses.asdict(a),
                       editing={"method": EDITING_METHOD, **dataclasses.asdict(e)})
        else:
            out.update(stride=self.stride, min_delta=self.min_delta)
        return out

    @classmethod
    def of(cls, meta: Mapping | None) -> LearningRule:
        """The rule a snapshot (or a journal header) was learned by, from its metadata: its
        ``learning`` as ``to_dict`` wrote it, or, written before, the rule its ``learning``
        describes (``rule: person`` with its lag, k, copies, sigma and seed: the person rule
        with those, its guard with the path check; else the script rule with its stride and
        min_delta). A tree with goals (``metadata["goals"]``): ``for_goals`` of it, whenever it
        was written."""
        meta = meta or {}
        return for_goals(cls._of(meta)) if meta.get("goals") is not None else cls._of(meta)

    @classmethod
    def _of(cls, meta: Mapping) -> LearningRule:
        learning = dict(meta.get("learning") or {})
        tree = dict(meta.get("tree_params") or {})
        person = learning.get("rule") == "person"
        base = PERSON if person else SCRIPT
        try:
            guard = (GuardSettings(**learning["guard"]) if isinstance(learning.get("guard"), Mapping)
                     else base.guard)
            seed = int(learning.get("seed", 0))
            if not person:
                return dataclasses.replace(base, tree=tree or base.tree, guard=guard, seed=seed,
                                           stride=int(learning.get("stride", 1)),
                                           min_delta=float(learning.get("min_delta", 0.0)))
            if isinstance(learning.get("alignment"), Mapping):
                alignment = ReactionAlignment(**learning["alignment"])
            else:
                alignment = dataclasses.replace(base.alignment, lag=learning.get("lag"))
            if isinstance(learning.get("editing"), Mapping):
                e = {k: v for k, v in learning["editing"].items() if k != "method"}
                editing = NeighbourEditing(**e)
            else:
                editing = dataclasses.replace(
                    base.editing, **{k: learning[k] for k in ("k", "copies", "sigma")
                                     if k in learning})
        except TypeError as exc:  # a field this version does not know
            raise ValueError(f"the metadata's learning rule is not one this version reads: "
                             f"{exc}") from None
        extend = learning.get("extend_above", base.extend_above)
        return dataclasses.replace(base, alignment=alignment, editing=editing,
                                   tree=tree or base.tree, guard=guard, seed=seed,
                                   extend_above=None if extend is None else int(extend),
                                   # a tree written before passes were stored: one
                                   passes=int(learning.get("passes", 1)))


# The guard with its path check: a person's trees' (and a goal behaviour's, docs/goals.md)
PATH_CHECK = GuardSettings(clearance=0.3)
# The rules, chosen here (docs/teaching.md, "The learning rule", has the study behind them).
PERSON = LearningRule("person", alignment=ReactionAlignment(), editing=NeighbourEditing(),
                      guard=PATH_CHECK, extend_above=20000, passes=4)
SCRIPT = LearningRule("script")  # the paper's: each label learned as it arrives; the loop guard


def for_goals(rule: LearningRule) -> LearningRule:
    """The rule a tree with goals learns and is driven by: ``rule`` with the guard's path check
    (``PATH_CHECK``; on or off as ``rule`` says). A goal behaviour's trees of twelve inputs
    graze a box they pass close by and bounce between rotations near corners they were not
    shown; the controller drives them, and ``rhbl evaluate`` reports them beside the trees
    alone, through this guard (docs/goals.md)."""
    return dataclasses.replace(rule, guard=dataclasses.replace(
        rule.guard, clearance=PATH_CHECK.clearance, lookahead=PATH_CHECK.lookahead))


def rule_for(teacher: str) -> LearningRule:
    """The rule for labels from ``teacher``: ``person`` (given by hand: ``PERSON``) or
    ``script`` (a scripted teacher's: ``SCRIPT``)."""
    if teacher == "person":
        return PERSON
    if teacher == "script":
        return SCRIPT
    raise ValueError(f"teacher must be 'person' or 'script', got {teacher!r}")
