"""Learning from demonstration: features + labels -> a hypersphere tree, with its metadata.

The zenoh learner process and the in-process harness both use exactly this code path.

    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following",
                                   spawn="winner")           # **tree_params go to the classifier
    learned = learner.observe(ranges, yaw, label)            # -> bool (learned or skipped)
    learner.classifier                                        # rhbl.HypersphereClassifier
    learner.predict(ranges, yaw) -> action name               # what a controller drives
    learner.metadata() -> {"features", "actions", "task", "provenance", "tree_params", "learning"}
    learner.save(path)
    learner = DemonstrationLearner.resume(path)               # continue training a snapshot
    controller = Policy-like: TreePolicy.load(path, features=None) (checks compatibility)
    check_compatible(meta, features, actions=None)            # IncompatibleSnapshotError if not

Sample selection (``stride``, ``min_delta``) decides which observations are offered to the tree;
the tree itself spawns only on a label conflict (the paper's rule).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .actions import DEFAULT_ACTIONS, ActionSet
from .features import FeatureSpec
from .rule import SCRIPT, LearningRule

__all__ = [
    "DemonstrationLearner",
    "IncompatibleSnapshotError",
    "TreePolicy",
    "check_compatible",
    "load_snapshot",
]

# vectors :meth:`DemonstrationLearner.observe` queues at most before learning them in one call
LEARN_BATCH = 256

log = logging.getLogger(__name__)


class IncompatibleSnapshotError(ValueError):
    """A snapshot was trained with other features or actions than the ones in use."""


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def check_compatible(meta: Mapping | None, features: FeatureSpec | Mapping | None = None,
                     actions: ActionSet | Mapping | None = None) -> None:
    """Raise ``IncompatibleSnapshotError`` naming the difference when ``meta`` (a snapshot's
    metadata) was trained with other features or actions than ``features`` / ``actions``."""
    if not meta or "features" not in meta or "actions" not in meta:
        raise IncompatibleSnapshotError(
            "snapshot has no 'features'/'actions' metadata: it was not written by "
            "DemonstrationLearner, so its inputs are unknown")
    if features is not None:
        want = features.to_dict() if isinstance(features, FeatureSpec) else dict(features)
        have = FeatureSpec.from_dict(meta["features"]).to_dict()
        want = FeatureSpec.from_dict(want).to_dict()
        if have != want:
            diff = {k: (have.get(k), want.get(k)) for k in set(have) | set(want)
                    if have.get(k) != want.get(k)}
            raise IncompatibleSnapshotError(
                "snapshot was trained with other features: "
                + "; ".join(f"{k}: snapshot {a!r} != requested {b!r}" for k, (a, b) in sorted(diff.items())))
    if actions is not None:
        want_a = actions if isinstance(actions, ActionSet) else ActionSet.from_dict(actions)
        have_a = ActionSet.from_dict(meta["actions"])
        if have_a != want_a:
            raise IncompatibleSnapshotError(
                f"snapshot was trained with other actions: snapshot {have_a!r} != requested {want_a!r}")


def load_snapshot(path: str | Path):
    """(classifier, features, actions, metadata) of a snapshot written by this module. Every
    error names the file: ``rhbl.SnapshotError`` (a malformed file, or metadata that names no
    valid features or actions) or ``IncompatibleSnapshotError`` (no features or actions)."""
    from rhbl import SnapshotError, load

    clf = load(path)
    meta = dict(clf.metadata or {})
    with naming(path):
        check_compatible(meta)
    try:
        features, actions = FeatureSpec.from_dict(meta["features"]), ActionSet.from_dict(meta["actions"])
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise SnapshotError(str(path), f"invalid metadata: {exc}") from None
    return clf, features, actions, meta


@contextlib.contextmanager
def naming(path: str | Path):
    """An ``IncompatibleSnapshotError`` raised inside names the file ``path``."""
    try:
        yield
    except IncompatibleSnapshotError as exc:
        raise IncompatibleSnapshotError(f"{path}: {exc}") from None


class DemonstrationLearner:
    """Turns (scan, yaw, teacher label) triples into a hypersphere tree.

    ``stride``: offer every n-th observation (1 = all, the paper's dense stream).
    ``min_delta``: skip an observation whose features moved less than this (max-norm) from the
    last offered one while its label is unchanged (a robot standing still adds nothing).
    ``record``: keep every vector offered to the tree (``recorded()`` returns them as ``(X, y)``),
    the data a compaction step (``compact``) needs to preserve what the tree learned.
    ``**tree_params`` go to ``rhbl.HypersphereClassifier`` (spawn, distance, min_radius, max_nodes...).
    ``rule``: the learning rule (``client.behaviour.rule``) recorded in the metadata, default
    ``SCRIPT`` (the paper's: each label learned as it arrives) with this stride, min_delta and
    tree parameters; its guard is what the controller drives the tree through.
    """

    def __init__(self, features: FeatureSpec, actions: ActionSet = DEFAULT_ACTIONS, *,
                 task: str | None = None, stride: int = 1, min_delta: float = 0.0,
                 classifier=None, parent: str | None = None, provenance: Mapping | None = None,
                 record: bool = False, rule: LearningRule | None = None, **tree_params):
        from rhbl import HypersphereClassifier

        if stride < 1:
            raise ValueError(f"stride must be >= 1, got {stride}")
        rule = SCRIPT if rule is None else rule
        if not rule.person:  # (a person's rule sets its own: ``PersonLearner``)
            rule = rule.replace(stride=int(stride), min_delta=float(min_delta),
                                tree=dict(tree_params))
        self.rule = rule
        self.features = features
        self.actions = actions
        self.task = task
        self.stride = int(stride)
        self.min_delta = float(min_delta)
        self.tree_params = dict(tree_params)
        if classifier is None:
            tree_params.setdefault("default_label", actions.names[0])
            classifier = HypersphereClassifier(**tree_params)
        # vectors offered but not yet learned (see ``classifier``)
        self._pending_x: list[np.ndarray] = []
        self._pending_y: list[str] = []
        self._classifier = classifier
        prov = dict(provenance or {})
        self.vectors = int(prov.get("vectors", 0))        # observations offered to the tree
        self.seen = int(prov.get("seen", 0))              # observations received
        self.sessions = list(prov.get("sessions", []))
        self.parent = parent if parent is not None else prov.get("parent")
        self.created = prov.get("created", _now())
        # the refinements (``rhbl refine``) of the tree this one extends, kept: their lineage,
        # and the places practice could not fix (the console's "show me here")
        self.refinement: list | None = None
        self._count = 0
        self._last_x: np.ndarray | None = None
        self._last_label: str | None = None
        self.session: dict = {}
        self._rec_x: list[np.ndarray] | None = [] if record else None
        self._rec_y: list[str] = []

    # -- learning --
    def _check_label(self, label: str) -> None:
        if label not in self.actions:
            raise ValueError(f"label {label!r} is not an action of this learner: {self.actions.names}")

    def vector(self, ranges, yaw: float, step=None) -> np.ndarray:
        """The features of one scan (``step``: what a goal behaviour's label says beside it,
        ``client.behaviour.goals.GoalLearner``; not used here)."""
        return self.features.extract(ranges, yaw)

    def observe(self, ranges, yaw: float, label: str, step=None) -> bool:
        """Offer one labelled observation; True when it reached the tree."""
        self._check_label(label)
        return self._offer(self.vector(ranges, yaw, step), label)

    def _offer(self, x: np.ndarray, label: str) -> bool:
        """Sample selection (``stride``, ``min_delta``) of one labelled vector, then the tree."""
        self.seen += 1
        self._count += 1
        if (self._count - 1) % self.stride:
            return False
        if (self.min_delta > 0 and self._last_x is not None and label == self._last_label
                and float(np.max(np.abs(x - self._last_x))) < self.min_delta):
            return False
        self._last_x, self._last_label = x, label
        self._learn(x, label)
        return True

    @property
    def classifier(self):
        """The tree (``rhbl.HypersphereClassifier``), with every vector offered so far learned:
        :meth:`observe` queues its vectors (up to ``LEARN_BATCH``) and they are learned in one
        ``partial_fit`` when the tree is read (a prediction, its size, a save, ...) or the
        queue is full, in the order offered: the same tree as one ``partial_fit`` per vector,
        without the cost of a call per vector."""
        self._flush()
        return self._classifier

    @classifier.setter
    def classifier(self, clf) -> None:
        self._flush()  # the queued vectors belong to the tree they were offered to
        self._classifier = clf

    def _flush(self) -> None:
        if self._pending_x:
            X = np.array(self._pending_x, dtype=np.float64).reshape(len(self._pending_x), -1)
            y = self._pending_y
            self._pending_x, self._pending_y = [], []
            self._classifier.partial_fit(X, y)

    def _learn(self, x: np.ndarray, label: str) -> None:
        self._pending_x.append(x)
        self._pending_y.append(label)
        self.vectors += 1
        if self._rec_x is not None:
            self._rec_x.append(x)
            self._rec_y.append(label)
        if len(self._pending_x) >= LEARN_BATCH:
            self._flush()

    @property
    def recording(self) -> bool:
        """True when this learner keeps the vectors it offers (``record=True``)."""
        return self._rec_x is not None

    def recorded(self) -> tuple[np.ndarray, np.ndarray]:
        """``(X, y)``: every vector offered to the tree since this learner was made with
        ``record=True`` (ValueError otherwise), in the order offered."""
        if self._rec_x is None:
            raise ValueError("this learner was made without record=True: it kept no vectors")
        X = np.array(self._rec_x, dtype=np.float64).reshape(-1, self.features.dim)
        return X, np.array(self._rec_y, dtype=str)

    def observe_vector(self, x: np.ndarray, label: str) -> bool:
        """Offer an already extracted feature vector (no sample selection), learned at once (a
        bad vector raises here, not when the tree is next read)."""
        self._learn(np.asarray(x, dtype=np.float64).reshape(-1), label)
        self._flush()
        self.seen += 1
        return True

    def _checked(self, X, labels) -> tuple[np.ndarray, list[str]]:
        """``X`` as rows of this learner's features and ``labels`` as checked action names."""
        X = np.asarray(X, dtype=np.float64).reshape(-1, self.features.dim)
        labels = [str(v) for v in labels]
        if len(labels) != len(X):
            raise ValueError(f"{len(X)} vectors but {len(labels)} labels")
        for label in set(labels):
            self._check_label(label)
        return X, labels

    def observe_vectors(self, X: np.ndarray, labels) -> int:
        """Offer already extracted feature vectors in order (no sample selection), in one call
        to the tree; returns how many."""
        X, labels = self._checked(X, labels)
        if len(X):
            self.classifier.partial_fit(X, labels)
        self.vectors += len(X)
        self.seen += len(X)
        if self._rec_x is not None:
            self._rec_x.extend(X)
            self._rec_y.extend(labels)
        return len(X)

    def relearn(self) -> bool:
        """The tree learned again, fresh, from every vector this learner recorded, in order, in
        one ``fit`` (with ``radius="margin"``, each sphere bounded by its margin among all of
        them; its metadata kept). False, the tree kept, when it holds more than the recorded
        vectors (a tree this learner extends) or none were recorded."""
        clf = self.classifier
        if self._rec_x is None or not self._rec_x or clf.n_seen_ != len(self._rec_x):
            return False
        X, y = self.recorded()
        fresh = type(clf)(**clf.get_params())
        fresh.fit(X, y)
        fresh.metadata = clf.metadata
        self.classifier = fresh
        return True

    def compact(self, method: str = "exact", *, data: str | None = None, **options) -> dict:
        """Replace the tree by its compaction (``rhbl.compaction``) on the recorded vectors (the
        learner must have been made with ``record=True``); ``options`` go to
        ``HypersphereClassifier.compact`` (``max_error``, ``max_nodes``), ``data`` is added to
        the record's note of the data (such as "after round 2"). Returns the step's provenance
        record (also in the snapshot's ``metadata["compaction"]``). Learning goes on as before
        on the compacted tree."""
        X, y = self.recorded()
        note = "the vectors this learner was trained on" + (f", {data}" if data else "")
        self.classifier = self.classifier.compact(X, y, method=method, data=note, **options)
        return self.classifier.metadata["compaction"][-1]

    # -- using --
    def predict(self, ranges, yaw: float = 0.0) -> str:
        if self.vectors == 0:
            return self.actions.names[0]
        return str(self.classifier.predict_one(self.features.extract(ranges, yaw)))

    @property
    def nodes(self) -> int:
        return int(getattr(self.classifier, "node_count_", 0) or 0) if self.vectors else 1

    @property
    def height(self) -> int:
        return int(getattr(self.classifier, "height_", 0) or 0) if self.vectors else 0

    def metadata(self) -> dict:
        prov = {
            "vectors": self.vectors,
            "seen": self.seen,
            "created": self.created,
            "saved": _now(),
            "parent": self.parent,
            "sessions": self.sessions + ([self.session] if self.session else []),
        }
        meta = {
            "features": self.features.to_dict(),
            "actions": self.actions.to_dict(),
            "task": self.task,
            "provenance": prov,
            "tree_params": {k: v for k, v in self.tree_params.items()
                            if isinstance(v, str | int | float | bool | type(None))},
            "learning": self.rule.to_dict(),
        }
        if self.refinement:
            meta["refinement"] = self.refinement
        return meta

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        if path.parent and not path.parent.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
        self.classifier.save(str(path), metadata=self.metadata())
        return path

    @classmethod
    def resume(cls, path: str | Path, features: FeatureSpec | None = None,
               actions: ActionSet | None = None) -> DemonstrationLearner:
        """Continue training a snapshot (features/actions come from its metadata; if given they
        must match it)."""
        clf, feats, acts, meta = load_snapshot(path)
        with naming(path):
            check_compatible(meta, features, actions)
        try:
            rule = LearningRule.of(meta)  # (a person's tree goes on by the script rule)
            tree_params = meta.get("tree_params", {}) or {}
            learner = cls(feats, actions=acts, task=meta.get("task"), classifier=clf,
                          stride=rule.stride, min_delta=rule.min_delta,
                          rule=None if rule.person else rule,
                          parent=str(path), provenance=meta.get("provenance"),
                          **cls._snapshot_parts(clf, meta, path), **tree_params)
        except (ValueError, TypeError, AttributeError) as exc:
            from rhbl import SnapshotError

            raise SnapshotError(str(path), f"invalid metadata: {exc}") from None
        learner.parent = str(path)
        if isinstance(meta.get("refinement"), list):
            learner.refinement = meta["refinement"]
        return learner

    from_snapshot = resume

    @classmethod
    def _snapshot_parts(cls, clf, meta: Mapping, path) -> dict:
        """What a subclass's constructor takes from a snapshot being resumed besides the tree."""
        return {}


class TreePolicy:
    """A learned controller: ``act(ranges, pose) -> action name`` from a tree and its features."""

    def __init__(self, classifier, features: FeatureSpec, actions: ActionSet,
                 metadata: Mapping | None = None):
        self._classifier = classifier
        self._learner: DemonstrationLearner | None = None
        self.features = features
        self.actions = actions
        self.metadata = dict(metadata or {})

    @property
    def classifier(self):
        """The tree; that of a learner (:meth:`from_learner`) as it is now, every vector it was
        offered learned (the learner may have replaced its tree, by a compaction)."""
        return self._classifier if self._learner is None else self._learner.classifier

    @classmethod
    def load(cls, path: str | Path, features: FeatureSpec | None = None,
             actions: ActionSet | None = None) -> TreePolicy:
        clf, feats, acts, meta = load_snapshot(path)
        with naming(path):
            check_compatible(meta, features, actions)
        return cls(clf, feats, acts, meta)

    @classmethod
    def from_learner(cls, learner: DemonstrationLearner) -> TreePolicy:
        """The learner's tree as it grows (what drives a corrective round)."""
        policy = cls(None, learner.features, learner.actions, learner.metadata())
        policy._learner = learner
        return policy

    def reset(self) -> None:
        pass

    def vector(self, ranges, yaw: float) -> np.ndarray:
        """The features of one scan: what ``act`` asks the tree about."""
        return self.features.extract(ranges, yaw)

    def act(self, ranges, pose) -> str:
        yaw = float(pose[2]) if pose is not None else 0.0
        return str(self.classifier.predict_one(self.vector(ranges, yaw)))

    def act_many(self, ranges, yaws=None) -> list[str]:
        """``act`` for many scans of one beam count at once (``ranges`` (scans, beams), a
        heading per scan): their features together and one batched tree query (a controller
        serving a fleet answers a tick's scans so); the same actions as ``act`` one by one."""
        x = self.features.extract_many(ranges, yaws)
        if not len(x):
            return []
        return [str(a) for a in self.classifier.predict(x).tolist()]
