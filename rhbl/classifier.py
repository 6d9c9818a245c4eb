"""The hypersphere tree of Recursive, Hyperspherical Behavioral Learning (RHBL).

The paper's algorithm (sections 3-5), in its default configuration:

* Inputs are vectors in ``[0, 1]^n``. A sphere ``(c, r)`` encloses ``x`` iff ``d(x, c) <= r``,
  where ``d`` is the *squared* Euclidean distance by default (``distance="euclidean"`` uses the
  plain Euclidean distance, the variant section 5 compares against). The root has centre
  ``[0.5] * n``, radius ``n / 4`` (``sqrt(n) / 2`` for the Euclidean variant: the distance to
  the furthest corner) and the default label.
* Training on ``(x, a)``: descend from the root through every sphere that encloses ``x``; a
  sphere that encloses ``x`` but none of whose children do (a *candidate*) and whose label
  differs from ``a`` spawns a child with centre ``x``, radius ``r_parent - d(x, c_parent)``
  and label ``a``. One vector can spawn several children.
* Classification: among the spheres that enclose ``x`` and whose ancestors all enclose ``x``,
  the smallest radius wins; ties go to the deepest, then to the earliest created.

A variant beside the paper's radius (``radius="margin"``, docs/rhbl.md): a child's radius is
also at most the distance from its centre to the nearest vector of another label among the
vectors it is trained on (the radius rule of restricted Coulomb energy networks and of
data-dependent balls: a sphere reaches up to where the labels change, not as far as its parent
allows); a vector that no sphere but the root encloses then takes the label of the sphere with
the nearest centre (a nearest-prototype rule), in training as in classification.

The spheres, spawning and the winner searches live in :class:`rhbl.tree.SphereTree` (the
estimator's ``tree_``); this module holds the parameters, input checks and labels.

Decisions where the paper is silent (see ``docs/rhbl.md``):

* One inclusive test ``d <= r + eps`` everywhere; a child's radius is clamped at 0 (a sphere of
  radius 0 encloses only its centre, within ``eps``).
* A vector within ``eps`` of the centre of the sphere that would spawn, with a conflicting
  label, relabels that sphere in place instead of spawning an identical copy (this bounds a
  vector repeated with alternating labels to a fixed number of spheres).
* NaN or infinite values raise ``ValueError``; values outside ``[0, 1]`` raise ``ValueError``
  unless ``clip=True``, which clips them into the cube.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from . import snapshot
from ._errors import NotFittedError, SnapshotError
from .compaction import compact
from .tree import _F64, ALGORITHMS, DISTANCES, SphereTree, Totals, load_kernels, margins

_NDARRAY = np.ndarray  # (_F64: builtin dtypes are singletons; another float64 takes the checks)

__all__ = ["HypersphereClassifier", "load", "loads"]

_SPAWNS = ("all", "winner")
_RADII = ("parent", "margin")
_PARAMS = (
    "default_label",
    "distance",
    "spawn",
    "radius",
    "min_radius",
    "max_nodes",
    "max_depth",
    "clip",
    "eps",
    "algorithm",
    "compiled",
)
# the parameters that shape the tree (saved in snapshots, compared by ``tree_equal``);
# ``algorithm`` and ``compiled`` only choose how the same answers are computed
_TREE_PARAMS = snapshot.PARAMS


def _uncovered(radius: str) -> str:
    """The tree's rule for vectors no sphere but the root encloses, for ``radius``."""
    return "nearest" if radius == "margin" else "root"


def _plain_label(label: Any) -> Any:
    """A label as a plain Python ``str`` or ``int`` (numpy scalars are converted)."""
    if isinstance(label, np.generic):
        label = label.item()
    if isinstance(label, str | int):
        return label
    raise ValueError(f"labels must be str or int, got {label!r} of type {type(label).__name__}")


def _plain_labels(y: Any) -> np.ndarray | None:
    """``y`` when it is a one-dimensional numpy array of str or int labels (not bool), whose
    labels need no check one by one; else None."""
    if isinstance(y, np.ndarray) and y.ndim == 1 and y.dtype.kind in "Uiu":
        return y
    return None


def _label_array(labels: list[Any]) -> np.ndarray:
    """A numpy array of labels that keeps their type (str array, int array, else object)."""
    if labels and all(isinstance(v, str) for v in labels):
        return np.array(labels, dtype=str)
    if labels and all(isinstance(v, int) and not isinstance(v, bool) for v in labels):
        try:
            return np.array(labels, dtype=np.int64)
        except OverflowError:
            pass
    out = np.empty(len(labels), dtype=object)
    out[:] = labels
    return out


class HypersphereClassifier:
    """A tree of labelled hyperspheres grown one demonstration at a time (RHBL).

    Follows scikit-learn's estimator contract: ``__init__`` only stores parameters, learned
    attributes end in ``_``, ``fit``/``partial_fit`` return ``self``.

    Parameters
    ----------
    default_label:
        The root's label (the paper's default behaviour). ``None`` uses the first training label.
    distance:
        ``"squared"`` (the paper: squared Euclidean distance for radii and enclosure) or
        ``"euclidean"`` (the variant of section 5, for ablation). Fixed once a tree exists.
    spawn:
        ``"all"`` (the paper, literal): every candidate with a conflicting label spawns a child.
        ``"winner"``: only the candidate that classification would choose spawns, when its
        label differs (much smaller trees).
    radius:
        ``"parent"`` (the paper): a child's radius is ``r_parent - d(x, c_parent)``, as large
        as its parent allows. ``"margin"``: in ``fit``, also at most the distance from ``x`` to
        the nearest vector of another label in the data set fitted (``partial_fit`` and
        ``learn_one`` extend a tree with the parent's bound alone); and a vector that no sphere
        but the root encloses takes the label of the sphere whose centre is nearest, in
        training as in classification (answered wrongly so, it spawns a child of the root).
        Fixed once a tree exists.
    min_radius:
        Do not spawn spheres whose radius would be smaller than this (0 = no limit). A vector
        whose spawn is suppressed is counted in ``n_skipped_``.
    max_nodes:
        Cap on the number of spheres (root included); ``None`` = no cap. Once reached, the tree
        stops growing (relabelling in place still happens) and suppressed spawns are counted.
    max_depth:
        Do not spawn spheres deeper than this (root depth 0); ``None`` = no limit.
    clip:
        ``False`` (default): values outside ``[0, 1]`` raise ``ValueError``. ``True``: clip them.
    eps:
        Tolerance of the inclusive enclosure test ``d <= r + eps`` and of "coincides with a
        centre" (``d <= eps``). Fixed once a tree exists.
    algorithm:
        How ``predict`` and ``score`` find the winning sphere of several rows (like
        ``algorithm=`` of scikit-learn's ``KNeighborsClassifier``): ``"brute"`` tests every
        sphere; ``"descent"`` walks down the tree from the root, testing only the children of
        spheres that enclose the query (a subtree whose sphere does not is skipped);
        ``"auto"`` (default) is ``"descent"`` (with ``compiled=False``: ``"brute"`` for trees
        of at most 64 spheres). Every choice gives exactly the same answers; only the speed
        differs. Single queries (``predict_one``, ``predict`` of one row, ``decision_path``)
        always descend (with ``compiled=False``: test every sphere in one vectorised pass).
        Not saved in snapshots (a loaded classifier has ``"auto"``).
    compiled:
        ``True`` (default): training and every search run compiled kernels (numba; compiled
        once per machine and cached, loaded once per process by the first classifier made).
        ``False``: the pure numpy code that preceded them, kept as the reference the tests
        compare the kernels with; the same trees and answers, bit for bit, only slower. Not
        saved in snapshots (a loaded classifier has ``True``).

    Learned attributes: ``tree_`` (the :class:`rhbl.tree.SphereTree`), ``n_features_in_``,
    ``classes_`` (labels in order of first appearance, the default label first),
    ``node_count_``, ``height_`` (edges; a lone root has height 0), ``n_seen_`` (vectors
    trained on), ``n_skipped_`` (vectors with a spawn suppressed by
    ``min_radius``/``max_nodes``/``max_depth``), ``n_relabelled_`` (in-place relabels).
    ``metadata`` is a free dict saved in snapshots.
    """

    def __init__(
        self,
        default_label: str | int | None = None,
        *,
        distance: str = "squared",
        spawn: str = "all",
        radius: str = "parent",
        min_radius: float = 0.0,
        max_nodes: int | None = None,
        max_depth: int | None = None,
        clip: bool = False,
        eps: float = 1e-9,
        algorithm: str = "auto",
        compiled: bool = True,
    ) -> None:
        self.default_label = default_label
        self.distance = distance
        self.spawn = spawn
        self.radius = radius
        self.min_radius = min_radius
        self.max_nodes = max_nodes
        self.max_depth = max_depth
        self.clip = clip
        self.eps = eps
        self.algorithm = algorithm
        self.compiled = compiled
        self.metadata: dict[str, Any] = {}
        if compiled is True:
            # once per process: a learner or controller pays it when it makes its classifier
            # (at start), not in its first training call or prediction
            load_kernels()

    # ------------------------------------------------------------------ parameters
    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor parameters (scikit-learn contract)."""
        return {name: getattr(self, name) for name in _PARAMS}

    def set_params(self, **params: Any) -> HypersphereClassifier:
        """Set constructor parameters; growth limits apply from the next ``partial_fit``."""
        for name, value in params.items():
            if name not in _PARAMS:
                raise ValueError(f"invalid parameter {name!r}; allowed: {', '.join(_PARAMS)}")
            setattr(self, name, value)
        return self

    def _check_params(self) -> None:
        if self.distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {self.distance!r}")
        if self.spawn not in _SPAWNS:
            raise ValueError(f"spawn must be one of {_SPAWNS}, got {self.spawn!r}")
        if self.radius not in _RADII:
            raise ValueError(f"radius must be one of {_RADII}, got {self.radius!r}")
        if not (isinstance(self.min_radius, int | float) and self.min_radius >= 0):
            raise ValueError(f"min_radius must be a number >= 0, got {self.min_radius!r}")
        if self.max_nodes is not None and (
            not isinstance(self.max_nodes, int | np.integer) or self.max_nodes < 1
        ):
            raise ValueError(f"max_nodes must be None or an int >= 1, got {self.max_nodes!r}")
        if self.max_depth is not None and (
            not isinstance(self.max_depth, int | np.integer) or self.max_depth < 0
        ):
            raise ValueError(f"max_depth must be None or an int >= 0, got {self.max_depth!r}")
        if not (isinstance(self.eps, int | float) and 0 <= self.eps < 0.5):
            raise ValueError(f"eps must be a number in [0, 0.5), got {self.eps!r}")
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if not isinstance(self.compiled, bool | np.bool_):
            raise ValueError(f"compiled must be True or False, got {self.compiled!r}")
        if self.default_label is not None:
            _plain_label(self.default_label)

    def _check_tree_params(self) -> None:
        """The parameters are valid and agree with the existing tree's distance and eps."""
        self._check_params()
        tree = self.tree_
        for name in ("distance", "eps"):
            if getattr(self, name) != getattr(tree, name):
                raise ValueError(
                    f"{name}={getattr(self, name)!r} but the tree was grown with "
                    f"{getattr(tree, name)!r}"
                )
        if _uncovered(self.radius) != tree.uncovered:
            raise ValueError(f"radius={self.radius!r} but the tree answers uncovered vectors "
                             f"by {tree.uncovered!r}")

    # ------------------------------------------------------------------ state
    def _is_fitted(self) -> bool:
        return getattr(self, "tree_", None) is not None

    def _check_fitted(self) -> None:
        if not self._is_fitted():
            raise NotFittedError(
                "this HypersphereClassifier is not fitted yet: call fit or partial_fit first"
            )

    def _init_tree(self, n_features: int, root_label: Any) -> None:
        self._check_params()
        self._labels: list[Any] = []
        self._label_index: dict[Any, int] = {}
        root = self._intern(root_label)
        self.tree_ = SphereTree(n_features, root, distance=self.distance, eps=self.eps,
                                uncovered=_uncovered(self.radius))
        self.n_features_in_ = int(n_features)
        self.n_seen_ = 0
        self.n_skipped_ = 0
        self.n_relabelled_ = 0

    @classmethod
    def from_tree(
        cls,
        tree: SphereTree,
        classes: Iterable[Any],
        *,
        n_seen: int = 0,
        n_skipped: int = 0,
        n_relabelled: int = 0,
        metadata: dict[str, Any] | None = None,
        **params: Any,
    ) -> HypersphereClassifier:
        """A fitted classifier around an existing tree (what loading a snapshot does).

        ``classes`` maps the tree's label indices to labels (str or int, no duplicates);
        ``params`` are constructor parameters, ``distance`` and ``eps`` defaulting to the
        tree's (others must agree with it). Raises ``ValueError`` naming what is wrong.
        """
        if not isinstance(tree, SphereTree):
            raise ValueError(f"tree must be a SphereTree, got {type(tree).__name__}")
        clf = cls(distance=tree.distance, eps=tree.eps,
                  radius="margin" if tree.uncovered == "nearest" else "parent")
        try:
            clf.set_params(**params)
            clf._check_params()
        except ValueError as exc:
            raise ValueError(f"invalid parameters: {exc}") from None
        labels = list(classes)
        if not labels or not all(isinstance(v, str | int) for v in labels):
            raise ValueError("labels must be a non-empty list of str or int")
        if len(set(labels)) != len(labels):
            raise ValueError("duplicate labels")
        if int(tree.label.max()) >= len(labels):
            raise ValueError("label index out of range")
        clf._labels = [_plain_label(v) for v in labels]
        clf._label_index = {v: i for i, v in enumerate(clf._labels)}
        clf._label_values = _label_array(clf._labels)
        clf.tree_ = tree
        clf._check_tree_params()
        clf.n_features_in_ = tree.n_features
        clf.n_seen_, clf.n_skipped_, clf.n_relabelled_ = n_seen, n_skipped, n_relabelled
        clf.metadata = {} if metadata is None else metadata
        return clf

    def _intern(self, label: Any) -> int:
        label = _plain_label(label)
        idx = self._label_index.get(label)
        if idx is None:
            idx = len(self._labels)
            self._labels.append(label)
            self._label_index[label] = idx
            self._label_values = _label_array(self._labels)
        return idx

    @property
    def node_count_(self) -> int:
        """Number of spheres, root included."""
        self._check_fitted()
        return self.tree_.node_count

    @property
    def height_(self) -> int:
        """Height of the tree in edges (a lone root has height 0)."""
        self._check_fitted()
        return self.tree_.height

    @property
    def classes_(self) -> np.ndarray:
        """Labels in order of first appearance (the root's label first)."""
        self._check_fitted()
        return self._label_values.copy()

    # ------------------------------------------------------------------ input checks
    def _check_X(self, X: Any, what: str = "X") -> np.ndarray:
        try:
            X = np.asarray(X, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{what} must be numeric: {exc}") from None
        if X.ndim != 2:
            raise ValueError(f"{what} must be 2-D (m, n_features), got shape {X.shape}")
        n = getattr(self, "n_features_in_", None)
        if self._is_fitted() and X.shape[1] != n:
            raise ValueError(f"{what} has {X.shape[1]} features, the tree expects {n}")
        if X.size == 0:
            return X
        if X.shape[0] == 1:  # one row (a learner's vector): cheaper in Python than in numpy
            xs = X[0].tolist()
            lo, hi, total = min(xs), max(xs), sum(xs)
        else:
            lo, hi = X.min(), X.max()  # NaN propagates
            total = 0.0
        if lo >= 0.0 and hi <= 1.0 and total == total:  # in the cube (NaN fails total == total)
            return X
        if not np.isfinite(X).all():
            row, col = np.argwhere(~np.isfinite(X))[0]
            raise ValueError(f"{what}[{row}, {col}] is {X[row, col]}: values must be finite")
        if self.clip:
            return np.clip(X, 0.0, 1.0)
        if X.min() < 0.0 or X.max() > 1.0:
            row, col = np.argwhere((X < 0.0) | (X > 1.0))[0]
            raise ValueError(
                f"{what}[{row}, {col}] = {X[row, col]!r} is outside [0, 1] "
                "(scale the features, or pass clip=True to clip)"
            )
        return X

    def _check_x(self, x: Any) -> np.ndarray:
        """One query vector: the fast path used by ``predict_one``."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_features_in_,):
            x = x.reshape(-1) if x.ndim == 2 and x.shape[0] == 1 else x
            if x.shape != (self.n_features_in_,):
                raise ValueError(
                    f"x must have shape ({self.n_features_in_},), got {np.shape(x)}"
                )
        xs = x.tolist()
        total = sum(xs)
        if min(xs) >= 0.0 and max(xs) <= 1.0 and total == total:  # NaN fails total == total
            return x
        if not np.isfinite(x).all():
            raise ValueError(f"x contains {x[~np.isfinite(x)][0]}: values must be finite")
        if self.clip:
            return np.clip(x, 0.0, 1.0)
        bad = int(np.argmax((x < 0.0) | (x > 1.0)))
        raise ValueError(
            f"x[{bad}] = {x[bad]!r} is outside [0, 1] (scale the features, or pass clip=True)"
        )

    # ------------------------------------------------------------------ training
    def fit(self, X: Any, y: Iterable[Any], classes: Iterable[Any] | None = None):
        """Grow a fresh tree on ``(X, y)``, vectors in order (``radius="margin"``: each sphere
        also bounded by its margin in ``(X, y)``). Returns ``self``."""
        self.tree_ = None
        return self._fit(X, y, classes, self.radius == "margin")

    def partial_fit(self, X: Any, y: Iterable[Any], classes: Iterable[Any] | None = None):
        """Extend the tree with ``(X, y)``, one vector at a time in order (each new sphere
        bounded by its parent only, whatever ``radius``: the same tree however the vectors are
        cut into calls). Returns ``self``.

        ``classes`` optionally registers labels up front (scikit-learn compatibility); unseen
        labels are added as they appear anyway.
        """
        return self._fit(X, y, classes, False)

    def _fit(self, X: Any, y: Iterable[Any], classes: Iterable[Any] | None, margin: bool):
        fitted = self._is_fitted()
        if fitted:
            self._check_tree_params()
        else:
            self._check_params()
        X = self._check_X(X)
        plain = _plain_labels(y)  # a numpy array of str or int labels, as it is
        if plain is None:
            y = list(np.asarray(y, dtype=object).reshape(-1)) if not isinstance(y, list) else y
            plain = [_plain_label(v) for v in y]
        if len(plain) != X.shape[0]:
            raise ValueError(f"X has {X.shape[0]} rows but y has {len(plain)} labels")
        if not fitted:
            root = self.default_label
            if root is None:
                if not len(plain):
                    raise ValueError("default_label=None needs at least one training label")
                root = _plain_label(plain[0])
            self._init_tree(X.shape[1], root)
        if classes is not None:
            for c in classes:
                self._intern(c)
        labels = self._intern_all(plain)
        self._learn(X, labels, margins(X, labels, self.distance) if margin else None)
        return self

    def _intern_all(self, labels) -> list[int]:
        """The label index of each of ``labels`` (plain labels), new ones interned in order
        of first appearance; a numpy array's in one pass over its distinct values."""
        if not isinstance(labels, np.ndarray):
            return [self._intern(label) for label in labels]
        if not len(labels):
            return []
        values, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
        index = np.empty(len(values), dtype=np.int64)
        for u in np.argsort(first, kind="stable"):
            index[u] = self._intern(values[u].item())
        return index[inverse.reshape(-1)].tolist()

    def learn_one(self, x: Any, label: Any) -> int:
        """Train on one vector. Returns the number of spheres spawned or relabelled (0 = no change).

        The tree must exist already (after a ``fit``/``partial_fit``, possibly on zero rows).
        """
        self._check_fitted()
        self._check_tree_params()
        X = self._check_X(np.asarray(x, dtype=np.float64).reshape(1, -1))
        totals = self._learn(X, [self._intern(label)])
        return totals.spawned + totals.relabelled

    def _learn(self, X: np.ndarray, labels: list[int], caps: np.ndarray | None = None) -> Totals:
        """Train the tree on checked rows with label indices, in order (a sphere spawned at row
        ``i`` at most ``caps[i]`` in radius); count them."""
        totals = self.tree_.learn_many(
            X,
            labels,
            spawn=self.spawn,
            min_radius=self.min_radius,
            max_nodes=self.max_nodes,
            max_depth=self.max_depth,
            caps=caps,
            compiled=self.compiled,
        )
        self.n_seen_ += X.shape[0]
        self.n_relabelled_ += totals.relabelled
        self.n_skipped_ += totals.skipped
        return totals

    # ------------------------------------------------------------------ prediction
    def predict_one(self, x: Any) -> Any:
        """The label of one vector (the fast path for controllers). Returns a plain str/int."""
        tree = getattr(self, "tree_", None)
        if (type(x) is _NDARRAY and x.dtype is _F64 and self.compiled and tree is not None
                and x.shape == (self.n_features_in_,)):
            label = tree.predict_one(x)  # the kernel checks that x is in the cube
            if label >= 0:
                return self._labels[label]
        self._check_fitted()
        x = self._check_x(x)
        return self._labels[self.tree_.predict_one(x, compiled=self.compiled)]

    def predict(self, X: Any) -> np.ndarray:
        """Labels of the rows of ``X`` as a numpy array."""
        self._check_fitted()
        if (
            type(X) is np.ndarray
            and X.shape == (1, self.n_features_in_)
            and X.dtype == np.float64
        ):
            # one row: the single-query path (only for valid rows; others get the full
            # checks and their error messages below)
            if self.compiled:
                label = self.tree_.predict_one(X[0])  # -1: outside the cube, checked below
                if label >= 0:
                    return self._label_values[[label]]
            xs = X[0].tolist()
            total = sum(xs)
            if min(xs) >= 0.0 and max(xs) <= 1.0 and total == total:
                return self._label_values[[self.tree_.predict_one(X[0], compiled=self.compiled)]]
        X = self._check_X(X)
        if X.shape[0] == 1:
            return self._label_values[[self.tree_.predict_one(X[0], compiled=self.compiled)]]
        return self._label_values[self.tree_.predict(X, self.algorithm, compiled=self.compiled)]

    def decision_path(self, x: Any) -> list[dict[str, Any]]:
        """The spheres from the root to the winning sphere for ``x``.

        Each entry: ``index`` (creation order, root 0), ``depth``, ``radius``, ``label``,
        ``center`` (list of floats) and ``distance`` (from ``x`` to the centre, in the tree's
        distance units). The last entry's label is ``predict_one(x)``.
        """
        self._check_fitted()
        x = self._check_x(x)
        tree = self.tree_
        return [
            {
                "index": node,
                "depth": int(tree.depth[node]),
                "radius": float(tree.radii[node]),
                "label": self._labels[tree.label[node]],
                "center": tree.centers[node].tolist(),
                "distance": tree.distance_to(node, x),
            }
            for node in tree.path(tree.apply_one(x, compiled=self.compiled))
        ]

    def label_counts(self) -> dict[Any, int]:
        """Number of spheres per label (every known label, root included)."""
        self._check_fitted()
        counts = np.bincount(self.tree_.label, minlength=len(self._labels))
        return {label: int(c) for label, c in zip(self._labels, counts, strict=True)}

    def score(self, X: Any, y: Iterable[Any]) -> float:
        """Mean accuracy of ``predict(X)`` against ``y``."""
        self._check_fitted()
        X = self._check_X(X)
        y = [_plain_label(v) for v in np.asarray(y, dtype=object).reshape(-1)]
        if len(y) != X.shape[0]:
            raise ValueError(f"X has {X.shape[0]} rows but y has {len(y)} labels")
        if not y:
            return float("nan")
        want = np.array([self._label_index.get(v, -1) for v in y], dtype=np.int64)
        return float(np.mean(self.tree_.predict(X, self.algorithm, compiled=self.compiled) == want))

    # ------------------------------------------------------------------ inspection
    def tree_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the sphere data in creation order: centers, radii, parent, depth, label."""
        self._check_fitted()
        return self.tree_.to_arrays()

    def tree_equal(self, other: Any, *, metadata: bool = False) -> bool:
        """True if ``other`` has the same parameters, labels and spheres (exactly).

        ``algorithm`` is not compared: it changes no answer.
        """
        if not isinstance(other, HypersphereClassifier):
            return False
        mine, theirs = self.get_params(), other.get_params()
        if any(mine[k] != theirs[k] for k in _TREE_PARAMS):
            return False
        if self._is_fitted() != other._is_fitted():
            return False
        if metadata and self.metadata != other.metadata:
            return False
        if not self._is_fitted():
            return True
        return (
            self.n_features_in_ == other.n_features_in_
            and self._labels == other._labels
            and [type(v) for v in self._labels] == [type(v) for v in other._labels]
            and (self.n_seen_, self.n_skipped_, self.n_relabelled_)
            == (other.n_seen_, other.n_skipped_, other.n_relabelled_)
            and self.tree_.equal(other.tree_)
        )

    def __repr__(self) -> str:
        params = self.get_params()
        defaults = HypersphereClassifier().get_params()
        shown = ", ".join(f"{k}={v!r}" for k, v in params.items() if v != defaults[k])
        return f"HypersphereClassifier({shown})"

    # ------------------------------------------------------------------ compaction
    def compact(self, X: Any, y: Iterable[Any] | None = None, *, method: str = "exact",
                max_error: float = 0.0, max_nodes: int | None = None,
                sample_weight: Any = None, class_weight: str | None = None,
                data: str | None = None) -> HypersphereClassifier:
        """A smaller copy of this tree that keeps its behaviour on ``X`` (see ``rhbl.compaction``):
        ``method="exact"`` keeps every prediction on ``X``; ``"prune"`` deletes the weakest
        spheres against the labels ``y`` (``max_error``, ``max_nodes``, ``sample_weight``,
        ``class_weight="balanced"``). The copy is an ordinary
        tree (``partial_fit``, ``save``); ``metadata["compaction"]`` records the step."""
        return compact(self, X, y, method=method, max_error=max_error, max_nodes=max_nodes,
                       sample_weight=sample_weight, class_weight=class_weight, data=data)

    # ------------------------------------------------------------------ snapshots
    def _snapshot(self, metadata: dict[str, Any] | None) -> snapshot.Snapshot:
        self._check_fitted()
        if metadata is not None:
            self.metadata.update(metadata)
        tree = self.tree_
        params = {name: getattr(self, name) for name in _TREE_PARAMS}
        params["distance"], params["eps"] = tree.distance, tree.eps
        if params["radius"] == "parent":  # the paper's: left out, as readers before it know
            del params["radius"]
        return snapshot.Snapshot(
            params=params,
            labels=list(self._labels),
            arrays=tree.to_arrays(),
            n_seen=self.n_seen_,
            n_skipped=self.n_skipped_,
            n_relabelled=self.n_relabelled_,
            metadata=self.metadata,
        )

    def save(self, path: Any, metadata: dict[str, Any] | None = None) -> None:
        """Write a msgpack snapshot atomically. ``metadata`` updates ``self.metadata`` first."""
        path = Path(path)
        snapshot.write(path, snapshot.encode(self._snapshot(metadata), source=str(path)))

    def to_bytes(self, metadata: dict[str, Any] | None = None) -> bytes:
        """The snapshot as bytes (what ``save`` writes)."""
        return snapshot.encode(self._snapshot(metadata))


def load(path: Any) -> HypersphereClassifier:
    """Read a snapshot file written by :meth:`HypersphereClassifier.save`."""
    return loads(snapshot.read(path), source=str(path))


def loads(data: bytes, *, source: str = "<bytes>") -> HypersphereClassifier:
    """Rebuild a classifier from snapshot bytes (``source`` names them in errors).

    Every problem raises :class:`SnapshotError` naming ``source`` and the problem.
    """
    snap = snapshot.decode(data, source=source)
    try:
        clf = HypersphereClassifier(**snap.params)
        clf._check_params()
    except (ValueError, TypeError, OverflowError) as exc:
        raise SnapshotError(source, f"invalid parameters: {exc}") from None
    try:
        tree = SphereTree.from_arrays(**snap.arrays, distance=clf.distance, eps=clf.eps,
                                      uncovered=_uncovered(clf.radius))
        return HypersphereClassifier.from_tree(
            tree,
            snap.labels,
            n_seen=snap.n_seen,
            n_skipped=snap.n_skipped,
            n_relabelled=snap.n_relabelled,
            metadata=snap.metadata,
            **snap.params,
        )
    except (ValueError, TypeError, OverflowError, IndexError, MemoryError) as exc:
        # whatever a hostile tree makes the checks raise: named, with the file
        raise SnapshotError(source, str(exc) or type(exc).__name__) from None
