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

import logging
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from ._errors import NotFittedError

__all__ = ["HypersphereClassifier"]

log = logging.getLogger(__name__)

_DISTANCES = ("squared", "euclidean")
_SPAWNS = ("all", "winner")
_PARAMS = (
    "default_label",
    "distance",
    "spawn",
    "min_radius",
    "max_nodes",
    "max_depth",
    "clip",
    "eps",
)
# Above this many nodes the batch path descends the tree level by level instead of testing
# every (query, sphere) pair; the single-query path always tests every sphere at once.
_DENSE_BATCH_MAX_NODES = 64
_CHUNK_PAIRS = 1 << 21
# the batch descent tests a whole subtree at once when queries x subtree size is at most this.
# Off (0): measured with 20,000 queries it was 3-23% slower on literal trees of 400, 5,000 and
# 50,000 spheres than the filtered descent alone, and 16% faster only on a 1,550-sphere
# wall tree of `rhbl demo` (2026-11-28; the first three are bench_classifier.py trees); a knob
_DENSE_SUBTREE_PAIRS = 0


def _plain_label(label: Any) -> Any:
    """A label as a plain Python ``str`` or ``int`` (numpy scalars are converted)."""
    if isinstance(label, np.generic):
        label = label.item()
    if isinstance(label, str | int):
        return label
    raise ValueError(f"labels must be str or int, got {label!r} of type {type(label).__name__}")


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
        ``"euclidean"`` (the variant of section 5, for ablation).
    spawn:
        ``"all"`` (the paper, literal): every candidate with a conflicting label spawns a child.
        ``"winner"``: only the candidate that classification would choose spawns, when its
        label differs (much smaller trees).
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
        centre" (``d <= eps``).

    Learned attributes: ``n_features_in_``, ``classes_`` (labels in order of first appearance,
    the default label first), ``node_count_``, ``height_`` (edges; a lone root has height 0),
    ``n_seen_`` (vectors trained on), ``n_skipped_`` (vectors with a spawn suppressed by
    ``min_radius``/``max_nodes``/``max_depth``), ``n_relabelled_`` (in-place relabels).
    ``metadata`` is a free dict saved in snapshots.
    """

    def __init__(
        self,
        default_label: str | int | None = None,
        *,
        distance: str = "squared",
        spawn: str = "all",
        min_radius: float = 0.0,
        max_nodes: int | None = None,
        max_depth: int | None = None,
        clip: bool = False,
        eps: float = 1e-9,
    ) -> None:
        self.default_label = default_label
        self.distance = distance
        self.spawn = spawn
        self.min_radius = min_radius
        self.max_nodes = max_nodes
        self.max_depth = max_depth
        self.clip = clip
        self.eps = eps
        self.metadata: dict[str, Any] = {}

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
        if self.distance not in _DISTANCES:
            raise ValueError(f"distance must be one of {_DISTANCES}, got {self.distance!r}")
        if self.spawn not in _SPAWNS:
            raise ValueError(f"spawn must be one of {_SPAWNS}, got {self.spawn!r}")
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
        if self.default_label is not None:
            _plain_label(self.default_label)

    # ------------------------------------------------------------------ state
    def _is_fitted(self) -> bool:
        return getattr(self, "_n", 0) > 0

    def _check_fitted(self) -> None:
        if not self._is_fitted():
            raise NotFittedError(
                "this HypersphereClassifier is not fitted yet: call fit or partial_fit first"
            )

    def _init_tree(self, n_features: int, root_label: Any) -> None:
        self._check_params()
        if n_features < 1:
            raise ValueError(f"need at least one feature, got {n_features}")
        self.n_features_in_ = int(n_features)
        self._tree_distance = self.distance
        self._euclid = self.distance == "euclidean"
        self._labels: list[Any] = []
        self._label_index: dict[Any, int] = {}
        cap = 64
        self._centers = np.empty((cap, n_features), dtype=np.float64)
        self._radii = np.empty(cap, dtype=np.float64)
        self._parent = np.empty(cap, dtype=np.int64)
        self._depth = np.empty(cap, dtype=np.int64)
        self._label = np.empty(cap, dtype=np.int64)
        self._children: list[list[int]] = []
        self._ct: np.ndarray | None = None  # (features, capacity) centres for the training scan
        self._n = 0
        self.height_ = 0
        self.n_seen_ = 0
        self.n_skipped_ = 0
        self.n_relabelled_ = 0
        root_radius = math.sqrt(n_features) / 2 if self._euclid else n_features / 4
        self._add_node(np.full(n_features, 0.5), root_radius, -1, self._intern(root_label))

    def _intern(self, label: Any) -> int:
        label = _plain_label(label)
        idx = self._label_index.get(label)
        if idx is None:
            idx = len(self._labels)
            self._labels.append(label)
            self._label_index[label] = idx
            self._label_values = _label_array(self._labels)
        return idx

    def _add_node(self, center: np.ndarray, radius: float, parent: int, label: int) -> int:
        i = self._n
        if i == len(self._radii):
            cap = 2 * i
            for name in ("_centers", "_radii", "_parent", "_depth", "_label"):
                old = getattr(self, name)
                new = np.empty((cap,) + old.shape[1:], dtype=old.dtype)
                new[:i] = old[:i]
                setattr(self, name, new)
        self._centers[i] = center
        ct = self._ct
        if ct is not None:
            if ct.shape[1] <= i:
                new = np.empty((ct.shape[0], len(self._radii)), dtype=np.float64)
                new[:, :i] = ct[:, :i]
                self._ct = ct = new
            ct[:, i] = center
        self._radii[i] = radius
        self._parent[i] = parent
        depth = 0 if parent < 0 else int(self._depth[parent]) + 1
        self._depth[i] = depth
        self._label[i] = label
        self._children.append([])
        if parent >= 0:
            self._children[parent].append(i)
        self._n = i + 1
        if depth > self.height_:
            self.height_ = depth
        self._layout = None
        self._one = None
        return i

    @property
    def node_count_(self) -> int:
        """Number of spheres, root included."""
        self._check_fitted()
        return self._n

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
        """Grow a fresh tree on ``(X, y)``, vectors in order. Returns ``self``."""
        self._n = 0
        return self.partial_fit(X, y, classes=classes)

    def partial_fit(self, X: Any, y: Iterable[Any], classes: Iterable[Any] | None = None):
        """Extend the tree with ``(X, y)``, one vector at a time in order. Returns ``self``.

        ``classes`` optionally registers labels up front (scikit-learn compatibility); unseen
        labels are added as they appear anyway.
        """
        self._check_params()
        fitted = self._is_fitted()
        if fitted and self.distance != self._tree_distance:
            raise ValueError(
                f"distance={self.distance!r} but the tree was grown with {self._tree_distance!r}"
            )
        X = self._check_X(X)
        y = list(np.asarray(y, dtype=object).reshape(-1)) if not isinstance(y, list) else y
        if len(y) != X.shape[0]:
            raise ValueError(f"X has {X.shape[0]} rows but y has {len(y)} labels")
        y_idx_src = [_plain_label(v) for v in y]
        if not fitted:
            root = self.default_label
            if root is None:
                if not y_idx_src:
                    raise ValueError("default_label=None needs at least one training label")
                root = y_idx_src[0]
            self._init_tree(X.shape[1], root)
        if classes is not None:
            for c in classes:
                self._intern(c)
        for x, label in zip(X, y_idx_src, strict=True):
            self._learn(x, self._intern(label))
        return self

    def learn_one(self, x: Any, label: Any) -> int:
        """Train on one vector. Returns the number of spheres spawned or relabelled (0 = no change).

        The tree must exist already (after a ``fit``/``partial_fit``, possibly on zero rows).
        """
        self._check_fitted()
        self._check_params()
        x = self._check_X(np.asarray(x, dtype=np.float64).reshape(1, -1))[0]
        return self._learn(x, self._intern(label))

    def _dist_one(self, i: int, x: np.ndarray) -> float:
        diff = self._centers[i] - x
        d = float(np.dot(diff, diff))
        return math.sqrt(d) if self._euclid else d

    def _scan(self, x: np.ndarray) -> tuple[np.ndarray, list[int], list[int]]:
        """Distances from ``x`` to every centre, and the spheres reachable through enclosing
        ancestors, in creation order, with their parents.

        The arithmetic is exactly that of the single-query path (``_winner_one``): one
        ``sum((c - x)**2)`` over the features in feature order and the test ``d <= r + eps``,
        so training and prediction always agree on which spheres enclose a vector.
        """
        n = self._n
        ct = self._ct
        if ct is None:
            ct = self._ct = np.ascontiguousarray(self._centers.T)
        buf = np.subtract(ct[:, :n], x[:, None])
        np.multiply(buf, buf, out=buf)
        d = np.add.reduce(buf, axis=0)
        if self._euclid:
            np.sqrt(d, out=d)
        enc = np.flatnonzero(d <= self._radii[:n] + self.eps)
        ok = {-1}
        reach: list[int] = []
        parents: list[int] = []
        for i, p in zip(enc.tolist(), self._parent[enc].tolist(), strict=True):
            if p in ok:
                ok.add(i)
                reach.append(i)
                parents.append(p)
        return d, reach, parents

    def _candidates(self, reach: list[int], parents: list[int]) -> list[int]:
        """Reachable spheres none of whose children are reachable, in the order of a
        depth-first search that visits children in creation order (the paper's traversal)."""
        inner = set(parents)
        path: dict[int, tuple[int, ...]] = {-1: ()}
        for i, p in zip(reach, parents, strict=True):
            path[i] = path[p] + (i,)
        return sorted((i for i in reach if i not in inner), key=path.__getitem__)

    def _winner_of(self, nodes: list[int]) -> int:
        radii = self._radii
        depth = self._depth
        return min(nodes, key=lambda i: (radii[i], -depth[i], i))

    def _learn(self, x: np.ndarray, a: int) -> int:
        self.n_seen_ += 1
        d_all, reach, parents = self._scan(x)
        cands = self._candidates(reach, parents)
        if self.spawn == "winner":
            w = self._winner_of(cands)
            targets = [w] if self._label[w] != a else []
        else:
            targets = [c for c in cands if self._label[c] != a]
        if not targets:
            return 0
        eps = self.eps
        changes = 0
        skipped = False
        for p in targets:
            d = float(d_all[p])
            if d <= eps:
                self._label[p] = a  # coincides with the centre: relabel in place
                self.n_relabelled_ += 1
                self._layout = None
                self._one = None
                changes += 1
                continue
            r = max(float(self._radii[p]) - d, 0.0)
            if (
                (self.min_radius and r < self.min_radius)
                or (self.max_nodes is not None and self._n >= self.max_nodes)
                or (self.max_depth is not None and self._depth[p] + 1 > self.max_depth)
            ):
                skipped = True
                continue
            self._add_node(x, r, p, a)
            changes += 1
        if skipped:
            self.n_skipped_ += 1
        return changes

    # ------------------------------------------------------------------ inference layout
    def _build_layout(self) -> dict[str, Any]:
        """Pre-order arrays for vectorised classification (rebuilt lazily after a change)."""
        n = self._n
        order = np.empty(n, dtype=np.int64)
        end = np.empty(n, dtype=np.int64)
        children = self._children
        # iterative pre-order DFS, children in creation order
        pos = 0
        stack = [(0, False)]
        while stack:
            node, done = stack.pop()
            if done:
                end[node] = pos
                continue
            order[pos] = node
            pos += 1
            stack.append((node, True))
            for c in reversed(children[node]):
                stack.append((c, False))
        posof = np.empty(n, dtype=np.int64)
        posof[order] = np.arange(n)
        radii = self._radii[:n]
        depth = self._depth[:n]
        # tie-break rank: smallest radius, then deepest, then earliest created
        by_rank = np.lexsort((np.arange(n), -depth, radii))
        rank = np.empty(n, dtype=np.int64)
        rank[by_rank] = np.arange(n)
        lay: dict[str, Any] = {}
        lay["order"] = order
        lay["centers_t"] = np.ascontiguousarray(self._centers[order].T)
        lay["reach"] = radii[order] + self.eps
        lay["end"] = end[order]  # end position of each pre-order node's subtree
        lay["ar"] = np.arange(n)
        lay["rank"] = rank[order]
        lay["rank_pos"] = posof[by_rank]  # rank -> pre-order position
        lay["label"] = self._label[:n][order]
        lay["big"] = np.int64(n)
        # per pre-order position: children positions, their centres (transposed) and reach
        ct_all = lay["centers_t"]
        reach = lay["reach"]
        kids: list[np.ndarray | None] = []
        kids_ct: list[np.ndarray | None] = []
        kids_reach: list[np.ndarray | None] = []
        for i in order.tolist():
            if children[i]:
                k = posof[children[i]]
                kids.append(k)
                kids_ct.append(np.ascontiguousarray(ct_all[:, k]))
                kids_reach.append(reach[k])
            else:
                kids.append(None)
                kids_ct.append(None)
                kids_reach.append(None)
        lay["kids"] = kids
        lay["kids_ct"] = kids_ct
        lay["kids_reach"] = kids_reach
        # for the batch filter: centres row-major, their squared norms, and the band of
        # rounding error of the expanded squared distance around each child's reach
        n_feat = self.n_features_in_
        tol = 16 * 2.0**-53 * (n_feat * n_feat + 4 * n_feat)
        lay["kids_c"] = [None if k is None else np.ascontiguousarray(k.T) for k in kids_ct]
        lay["kids_cc"] = [None if k is None else np.einsum("ij,ij->j", k, k) for k in kids_ct]
        lo_l: list[np.ndarray | None] = []
        hi_l: list[np.ndarray | None] = []
        for r in kids_reach:
            if r is None:
                lo_l.append(None)
                hi_l.append(None)
                continue
            lim = r * r if self._euclid else r
            band = tol + (8 * 2.0**-53 * lim if self._euclid else 0.0)
            lo_l.append(lim - band)
            hi_l.append(lim + band)
        lay["kids_lo"] = lo_l
        lay["kids_hi"] = hi_l
        self._layout = lay
        return lay

    def _get_layout(self) -> dict[str, Any]:
        lay = self._layout
        return lay if lay is not None else self._build_layout()

    def _build_one(self) -> tuple:
        """Creation-order arrays for single queries (rebuilt lazily after a change).

        Creation order has every parent before its children, so no tree walk is needed.
        """
        n = self._n
        ct = np.ascontiguousarray(self._centers[:n].T)
        reach = self._radii[:n] + self.eps
        # tie-break rank: smallest radius, then deepest, then earliest created
        by_rank = np.lexsort((np.arange(n), -self._depth[:n], self._radii[:n]))
        rank = np.empty(n, dtype=np.int64)
        rank[by_rank] = np.arange(n)
        one = (
            ct,
            reach,
            np.empty_like(ct),  # scratch: differences
            np.empty(n),  # scratch: distances
            np.empty(n, dtype=bool),  # scratch: enclosure mask
            self._parent[:n].tolist(),
            rank.tolist(),
            by_rank.tolist(),  # rank -> node
            n,
            self._euclid,
        )
        self._one = one
        return one

    def _winner_one(self, x: np.ndarray) -> int:
        """The winning sphere (creation index) for one checked query vector.

        Every sphere is tested at once (one vectorised ``sum((x - c)**2)`` over the features,
        in feature order); the few enclosing spheres are then walked in creation order in
        Python: a sphere is reachable iff it encloses ``x`` and its parent is reachable.
        """
        one = self._one
        if one is None:
            one = self._build_one()
        ct, reach, buf, d, enc, parent, rank, by_rank, best, euclid = one
        np.subtract(ct, x[:, None], out=buf)
        np.multiply(buf, buf, out=buf)
        np.add.reduce(buf, axis=0, out=d)
        if euclid:
            np.sqrt(d, out=d)
        np.less_equal(d, reach, out=enc)
        ok = {-1}
        for i in np.flatnonzero(enc).tolist():
            if parent[i] in ok:
                ok.add(i)
                r = rank[i]
                if r < best:
                    best = r
        return by_rank[best]

    # ------------------------------------------------------------------ prediction
    def predict_one(self, x: Any) -> Any:
        """The label of one vector (the fast path for controllers). Returns a plain str/int."""
        self._check_fitted()
        x = self._check_x(x)
        return self._labels[self._label[self._winner_one(x)]]

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
            xs = X[0].tolist()
            total = sum(xs)
            if min(xs) >= 0.0 and max(xs) <= 1.0 and total == total:
                return self._label_values[[self._label[self._winner_one(X[0])]]]
        X = self._check_X(X)
        if X.shape[0] == 1:
            return self._label_values[[self._label[self._winner_one(X[0])]]]
        return self._label_values[self._predict_index(X)]

    def _predict_index(self, X: np.ndarray) -> np.ndarray:
        """Label indices of the rows of a checked ``X``."""
        lay = self._get_layout()
        pos = self._winner_pos_batch(X, lay)
        return lay["label"][pos]

    def _winner_pos_batch(self, X: np.ndarray, lay: dict[str, Any]) -> np.ndarray:
        m = X.shape[0]
        n_nodes = self._n
        if m == 0:
            return np.zeros(0, dtype=np.int64)
        if n_nodes <= _DENSE_BATCH_MAX_NODES:
            return self._winner_pos_dense(X, lay)
        return self._winner_pos_descent(X, lay)

    def _winner_pos_dense(self, X: np.ndarray, lay: dict[str, Any]) -> np.ndarray:
        """Every (query, sphere) pair at once, in chunks of queries."""
        n_nodes = self._n
        ct = lay["centers_t"]
        out = np.empty(X.shape[0], dtype=np.int64)
        step = max(1, _CHUNK_PAIRS // max(n_nodes, 1))
        for s in range(0, X.shape[0], step):
            Q = X[s : s + step]
            d = np.zeros((Q.shape[0], n_nodes))
            for k in range(ct.shape[0]):
                t = Q[:, k, None] - ct[k]
                t *= t
                d += t
            if self._euclid:
                np.sqrt(d, out=d)
            bad = d > lay["reach"]
            reach_end = np.maximum.accumulate(lay["end"] * bad, axis=1)
            key = np.where(reach_end > lay["ar"], lay["big"], lay["rank"])
            out[s : s + step] = lay["rank_pos"][key.min(axis=1)]
        return out

    def _winner_rank_dense(self, xt: np.ndarray, lay: dict[str, Any], lo: int, hi: int):
        """Best tie-break rank of each query (columns of ``xt``) within pre-order [lo, hi).

        The sphere at ``lo`` must enclose every query (it is their subtree's root).
        """
        ct = lay["centers_t"][:, lo:hi]
        d = np.subtract.outer(xt[0], ct[0])
        d *= d
        for k in range(1, ct.shape[0]):
            t = np.subtract.outer(xt[k], ct[k])
            t *= t
            d += t
        if self._euclid:
            np.sqrt(d, out=d)
        bad = d > lay["reach"][lo:hi]
        reach_end = np.maximum.accumulate(lay["end"][lo:hi] * bad, axis=1)
        key = np.where(reach_end > lay["ar"][lo:hi], lay["big"], lay["rank"][lo:hi])
        return key.min(axis=1)

    def _winner_pos_descent(self, X: np.ndarray, lay: dict[str, Any]) -> np.ndarray:
        """Descend sphere by sphere, carrying the queries each sphere encloses.

        Only the children of spheres that enclose some query are tested. Children are tested
        against many queries at once with a matrix product (the expanded form of the squared
        distance) as a *filter*: every (query, child) pair whose expanded distance lies within
        a rounding-error band of the radius is recomputed exactly as ``sum((x - c)**2)``, so
        the answers are exactly those of the direct form. Small subtrees with few queries are
        tested all at once with the direct form.
        """
        m = X.shape[0]
        rank = lay["rank"]
        kids_of = lay["kids"]
        kids_c = lay["kids_c"]
        kids_cc = lay["kids_cc"]
        kids_lo = lay["kids_lo"]
        kids_hi = lay["kids_hi"]
        kids_reach = lay["kids_reach"]
        end = lay["end"]
        euclid = self._euclid
        dense_pairs = _DENSE_SUBTREE_PAIRS
        XT = np.ascontiguousarray(X.T)
        XX = np.einsum("ij,ij->i", X, X)
        best = np.full(m, rank[0], dtype=np.int64)
        stack: list[tuple[int, np.ndarray | None]] = [(0, None)]
        while stack:
            node, q = stack.pop()
            if q is None:
                q = np.arange(m)
                xt, xx = XT, XX
            else:
                xt = XT[:, q]
                xx = XX[q]
            stop = int(end[node])
            if stop - node == 1:  # a leaf (only the root can get here)
                continue
            if q.size * (stop - node) <= dense_pairs:
                # few queries and a small subtree: test all of it at once
                sub = self._winner_rank_dense(xt, lay, node, stop)
                best[q] = np.minimum(best[q], sub)
                continue
            d = np.einsum("kn,nq->kq", kids_c[node], xt)  # (no BLAS threads)
            d *= -2.0
            d += kids_cc[node][:, None]
            d += xx
            enc = d <= kids_lo[node][:, None]
            maybe = d <= kids_hi[node][:, None]
            if not np.array_equal(enc, maybe):
                jj, ii = np.nonzero(maybe & ~enc)
                ct = lay["kids_ct"][node]
                exact = (ct[0][jj] - xt[0][ii]) ** 2
                for k in range(1, ct.shape[0]):
                    exact += (ct[k][jj] - xt[k][ii]) ** 2
                if euclid:
                    np.sqrt(exact, out=exact)
                ok = exact <= kids_reach[node][jj]
                enc[jj[ok], ii[ok]] = True
            kids = kids_of[node]
            for j in np.flatnonzero(enc.any(axis=1)).tolist():
                qj = q[enc[j]]
                c = int(kids[j])
                best[qj] = np.minimum(best[qj], rank[c])
                if kids_of[c] is not None:
                    stack.append((c, qj))
        return lay["rank_pos"][best]

    def decision_path(self, x: Any) -> list[dict[str, Any]]:
        """The spheres from the root to the winning sphere for ``x``.

        Each entry: ``index`` (creation order, root 0), ``depth``, ``radius``, ``label``,
        ``center`` (list of floats) and ``distance`` (from ``x`` to the centre, in the tree's
        distance units). The last entry's label is ``predict_one(x)``.
        """
        self._check_fitted()
        x = self._check_x(x)
        node = self._winner_one(x)
        path = []
        while node >= 0:
            path.append(
                {
                    "index": node,
                    "depth": int(self._depth[node]),
                    "radius": float(self._radii[node]),
                    "label": self._labels[self._label[node]],
                    "center": self._centers[node].tolist(),
                    "distance": self._dist_one(node, x),
                }
            )
            node = int(self._parent[node])
        return path[::-1]

    def label_counts(self) -> dict[Any, int]:
        """Number of spheres per label (every known label, root included)."""
        self._check_fitted()
        counts = np.bincount(self._label[: self._n], minlength=len(self._labels))
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
        return float(np.mean(self._predict_index(X) == want))

    # ------------------------------------------------------------------ inspection
    def tree_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the sphere data in creation order: centers, radii, parent, depth, label."""
        self._check_fitted()
        n = self._n
        return {
            "centers": self._centers[:n].copy(),
            "radii": self._radii[:n].copy(),
            "parent": self._parent[:n].copy(),
            "depth": self._depth[:n].copy(),
            "label": self._label[:n].copy(),
        }

    def tree_equal(self, other: Any, *, metadata: bool = False) -> bool:
        """True if ``other`` has the same parameters, labels and spheres (exactly)."""
        if not isinstance(other, HypersphereClassifier):
            return False
        if self.get_params() != other.get_params():
            return False
        if self._is_fitted() != other._is_fitted():
            return False
        if metadata and self.metadata != other.metadata:
            return False
        if not self._is_fitted():
            return True
        if (
            self.n_features_in_ != other.n_features_in_
            or self._n != other._n
            or self._labels != other._labels
            or [type(v) for v in self._labels] != [type(v) for v in other._labels]
            or (self.n_seen_, self.n_skipped_, self.n_relabelled_)
            != (other.n_seen_, other.n_skipped_, other.n_relabelled_)
        ):
            return False
        a, b = self.tree_arrays(), other.tree_arrays()
        return all(np.array_equal(a[k], b[k]) for k in a)

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
        """A smaller copy of this tree that keeps its behaviour on ``X`` (see ``rhbl.compact``):
        ``method="exact"`` keeps every prediction on ``X``; ``"prune"`` deletes the weakest
        spheres against the labels ``y`` (``max_error``, ``max_nodes``, ``sample_weight``,
        ``class_weight="balanced"``). The copy is an ordinary
        tree (``partial_fit``, ``save``); ``metadata["compaction"]`` records the step."""
        from .compact import compact

        return compact(self, X, y, method=method, max_error=max_error, max_nodes=max_nodes,
                       sample_weight=sample_weight, class_weight=class_weight, data=data)

    # ------------------------------------------------------------------ snapshots
    def save(self, path: Any, metadata: dict[str, Any] | None = None) -> None:
        """Write a msgpack snapshot atomically. ``metadata`` updates ``self.metadata`` first."""
        from .snapshot import save

        save(self, path, metadata=metadata)

    def to_bytes(self, metadata: dict[str, Any] | None = None) -> bytes:
        """The snapshot as bytes (what ``save`` writes)."""
        from .snapshot import dumps

        return dumps(self, metadata=metadata)
