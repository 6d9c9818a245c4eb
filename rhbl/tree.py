"""The sphere tree of RHBL, apart from the estimator: its arrays, spawning and winner searches.

:class:`SphereTree` holds the spheres in creation order (centres, radii, parents, depths, label
indices, children lists), grows them one training vector at a time (:meth:`SphereTree.learn`)
and finds the winning sphere of query vectors (:meth:`SphereTree.apply_one`,
:meth:`SphereTree.apply`). It knows labels only as indices; parameters, input checks and label
values belong to :class:`rhbl.HypersphereClassifier`, which keeps its tree in ``tree_`` (as
scikit-learn keeps ``Tree`` apart from ``DecisionTreeClassifier``).

Inputs are checked vectors in ``[0, 1]^n``: this module does no input validation of its own
except in :meth:`SphereTree.from_arrays`, which rebuilds a tree from untrusted arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

__all__ = ["ALGORITHMS", "DISTANCES", "Growth", "SphereTree"]

DISTANCES = ("squared", "euclidean")
ALGORITHMS = ("auto", "brute", "descent")
# "auto" tests every (query, sphere) pair at once for trees of at most this many spheres and
# descends the tree for larger ones
_BRUTE_MAX_NODES = 64
# the brute search works in chunks of queries of about this many (query, sphere) pairs
_CHUNK_PAIRS = 1 << 21


class Growth(NamedTuple):
    """What one training vector changed (:meth:`SphereTree.learn`)."""

    spawned: int  # spheres added
    relabelled: int  # spheres relabelled in place (the vector sat on their centre)
    suppressed: bool  # a growth limit suppressed at least one spawn


@dataclass(slots=True)
class _CreationLayout:
    """Creation-order arrays for single queries (rebuilt lazily after a change)."""

    centers_t: np.ndarray  # (features, nodes) centres
    reach: np.ndarray  # radius + eps per sphere
    diff: np.ndarray  # scratch (features, nodes): differences to the query
    dist: np.ndarray  # scratch (nodes,): distances to the query
    enclosed: np.ndarray  # scratch (nodes,): the enclosure test
    parent: list[int]
    rank: list[int]  # tie-break rank per sphere: 0 wins over 1 wins over 2 ...
    node_of_rank: list[int]


@dataclass(slots=True)
class _PreorderLayout:
    """Pre-order arrays for the batch searches (rebuilt lazily after a change).

    Position ``p`` is a sphere's place in a depth-first pre-order walk (children in creation
    order); the subtree of the sphere at ``p`` covers positions ``p .. subtree_end[p] - 1``.
    Per-position lists of the children are ``None`` for leaves.
    """

    centers_t: np.ndarray  # (features, nodes) centres in pre-order
    reach: np.ndarray  # radius + eps
    subtree_end: np.ndarray
    position: np.ndarray  # 0, 1, ..., nodes - 1
    rank: np.ndarray  # tie-break rank
    no_rank: np.int64  # a rank worse than every sphere's (the number of spheres)
    node_of_rank: np.ndarray  # rank -> creation index
    child_positions: list[np.ndarray | None]
    child_centers_t: list[np.ndarray | None]  # (features, children): for the exact recheck
    child_centers: list[np.ndarray | None]  # (children, features): for the matrix product
    child_sq_norms: list[np.ndarray | None]  # squared norms of the children's centres
    child_reach: list[np.ndarray | None]
    # bounds on the expanded squared distance: at or below ``child_sure`` the child surely
    # encloses the query; above ``child_maybe`` it surely does not; in between, recheck exactly
    child_sure: list[np.ndarray | None]
    child_maybe: list[np.ndarray | None]


def _tie_break_order(radii: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Creation indices from best to worst: smallest radius, then deepest, then earliest."""
    return np.lexsort((np.arange(len(radii)), -depth, radii))


def _preorder(children: list[list[int]], n: int) -> tuple[np.ndarray, np.ndarray]:
    """The nodes in pre-order (children in creation order) and, per node, the pre-order
    position just after its subtree (an iterative depth-first walk)."""
    order = np.empty(n, dtype=np.int64)
    end = np.empty(n, dtype=np.int64)
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
    return order, end


def _reach_bands(kids_reach: list, n_feat: int, euclidean: bool
                 ) -> tuple[list[np.ndarray | None], list[np.ndarray | None]]:
    """Per node, the (sure, maybe) bounds of its children's reach: the band of rounding error
    of the expanded squared distance around each reach (None for a leaf)."""
    tol = 16 * 2.0**-53 * (n_feat * n_feat + 4 * n_feat)
    sure: list[np.ndarray | None] = []
    maybe: list[np.ndarray | None] = []
    for r in kids_reach:
        if r is None:
            sure.append(None)
            maybe.append(None)
            continue
        lim = r * r if euclidean else r
        band = tol + (8 * 2.0**-53 * lim if euclidean else 0.0)
        sure.append(lim - band)
        maybe.append(lim + band)
    return sure, maybe


class SphereTree:
    """The spheres of one RHBL tree, in creation order (root 0; every parent precedes its child).

    Parameters
    ----------
    n_features:
        Length of the vectors (at least 1).
    root_label:
        Label index of the root.
    distance:
        ``"squared"`` or ``"euclidean"``: the distance used for radii and enclosure.
    eps:
        Tolerance of the enclosure test ``d <= r + eps`` and of "coincides with a centre".

    ``distance`` and ``eps`` are fixed for the life of the tree. The arrays ``centers``,
    ``radii``, ``parent``, ``depth`` and ``label`` are read-only views of the first
    ``node_count`` spheres; ``children[i]`` lists the children of sphere ``i`` in creation order.
    """

    def __init__(self, n_features: int, root_label: int, *, distance: str, eps: float) -> None:
        if distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {distance!r}")
        if not (isinstance(n_features, int | np.integer) and n_features >= 1):
            raise ValueError(f"need at least one feature, got {n_features}")
        self.n_features = int(n_features)
        self.distance = distance
        self.eps = eps
        self._euclidean = distance == "euclidean"
        self._allocate(64)
        self.children: list[list[int]] = []
        self.node_count = 0
        self.height = 0
        self._creation: _CreationLayout | None = None
        self._preorder: _PreorderLayout | None = None
        root_radius = math.sqrt(n_features) / 2 if self._euclidean else n_features / 4
        self._add(np.full(n_features, 0.5), root_radius, -1, root_label)

    def _allocate(self, capacity: int) -> None:
        self._centers = np.empty((capacity, self.n_features), dtype=np.float64)
        # (features, capacity) copy of the centres, kept up to date for the training scan
        self._centers_t = np.empty((self.n_features, capacity), dtype=np.float64)
        self._radii = np.empty(capacity, dtype=np.float64)
        self._parent = np.empty(capacity, dtype=np.int64)
        self._depth = np.empty(capacity, dtype=np.int64)
        self._label = np.empty(capacity, dtype=np.int64)

    # ------------------------------------------------------------------ the arrays
    @property
    def centers(self) -> np.ndarray:
        return self._view(self._centers)

    @property
    def radii(self) -> np.ndarray:
        return self._view(self._radii)

    @property
    def parent(self) -> np.ndarray:
        return self._view(self._parent)

    @property
    def depth(self) -> np.ndarray:
        return self._view(self._depth)

    @property
    def label(self) -> np.ndarray:
        return self._view(self._label)

    def _view(self, a: np.ndarray) -> np.ndarray:
        v = a[: self.node_count]
        v.flags.writeable = False
        return v

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Copies of the sphere data in creation order: centers, radii, parent, depth, label."""
        n = self.node_count
        return {
            "centers": self._centers[:n].copy(),
            "radii": self._radii[:n].copy(),
            "parent": self._parent[:n].copy(),
            "depth": self._depth[:n].copy(),
            "label": self._label[:n].copy(),
        }

    @classmethod
    def from_arrays(
        cls,
        centers: Any,
        radii: Any,
        parent: Any,
        label: Any,
        depth: Any = None,
        *,
        distance: str,
        eps: float,
    ) -> SphereTree:
        """A tree rebuilt from the arrays of :meth:`to_arrays` (``depth`` optional), checked.

        Raises ``ValueError`` naming the problem: shapes, non-finite values, a negative radius,
        parents that do not precede their children, a child's radius above its parent's, a
        negative label index, or a ``depth`` that does not follow from ``parent``.
        """
        centers = np.asarray(centers, dtype=np.float64)
        if centers.ndim != 2 or centers.shape[0] < 1 or centers.shape[1] < 1:
            raise ValueError(f"centers must have shape (nodes >= 1, features >= 1), got {centers.shape}")
        n = centers.shape[0]
        radii = np.asarray(radii, dtype=np.float64)
        parent = np.asarray(parent)
        label = np.asarray(label)
        for name, a in (("radii", radii), ("parent", parent), ("label", label)):
            if a.shape != (n,):
                raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
        for name, a in (("parent", parent), ("label", label)):
            if a.dtype.kind not in "iu":
                raise ValueError(f"{name} must hold integers, got dtype {a.dtype}")
        if not (np.isfinite(centers).all() and np.isfinite(radii).all()):
            raise ValueError("non-finite sphere data")
        if (radii < 0).any():
            raise ValueError("negative radius")
        if parent[0] != -1 or (n > 1 and ((parent[1:] < 0) | (parent[1:] >= np.arange(1, n))).any()):
            raise ValueError("inconsistent parent indices (each parent must precede its child)")
        if (label < 0).any():
            raise ValueError("label index out of range")
        if n > 1 and (radii[1:] > radii[parent[1:]]).any():
            raise ValueError("a child's radius exceeds its parent's")
        tree = cls(centers.shape[1], int(label[0]), distance=distance, eps=eps)
        tree._allocate(max(64, n))
        tree._centers[:n] = centers
        tree._centers_t[:, :n] = centers.T
        tree._radii[:n] = radii
        tree._parent[:n] = parent
        tree._label[:n] = label
        tree._depth[0] = 0
        tree.children = [[] for _ in range(n)]
        for i, p in enumerate(parent[1:].tolist(), start=1):
            tree._depth[i] = tree._depth[p] + 1
            tree.children[p].append(i)
        tree.node_count = n
        if depth is not None and not np.array_equal(np.asarray(depth), tree._depth[:n]):
            raise ValueError("depth does not follow from parent")
        tree.height = int(tree._depth[:n].max())
        return tree

    def equal(self, other: SphereTree) -> bool:
        """True if ``other`` has the same distance, eps and spheres (exactly)."""
        if (self.distance, self.eps, self.node_count) != (other.distance, other.eps, other.node_count):
            return False
        a, b = self.to_arrays(), other.to_arrays()
        return all(np.array_equal(a[k], b[k]) for k in a)

    # ------------------------------------------------------------------ growth
    def _add(self, center: np.ndarray, radius: float, parent: int, label: int) -> int:
        i = self.node_count
        if i == len(self._radii):  # full: double the capacity
            centers, centers_t = self._centers, self._centers_t
            rows = (self._radii, self._parent, self._depth, self._label)
            self._allocate(2 * i)
            self._centers[:i] = centers
            self._centers_t[:, :i] = centers_t
            for old, new in zip(rows, (self._radii, self._parent, self._depth, self._label),
                                strict=True):
                new[:i] = old
        self._centers[i] = center
        self._centers_t[:, i] = center
        self._radii[i] = radius
        self._parent[i] = parent
        depth = 0 if parent < 0 else int(self._depth[parent]) + 1
        self._depth[i] = depth
        self._label[i] = label
        self.children.append([])
        if parent >= 0:
            self.children[parent].append(i)
        self.node_count = i + 1
        if depth > self.height:
            self.height = depth
        self._changed()
        return i

    def _changed(self) -> None:
        self._creation = None
        self._preorder = None

    def _scan(self, x: np.ndarray) -> tuple[np.ndarray, list[int], list[int]]:
        """Distances from ``x`` to every centre, and the spheres reachable through enclosing
        ancestors, in creation order, with their parents.

        The arithmetic is exactly that of :meth:`apply_one`: one ``sum((c - x)**2)`` over the
        features in feature order and the test ``d <= r + eps``, so training and prediction
        always agree on which spheres enclose a vector.
        """
        n = self.node_count
        buf = np.subtract(self._centers_t[:, :n], x[:, None])
        np.multiply(buf, buf, out=buf)
        d = np.add.reduce(buf, axis=0)
        if self._euclidean:
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

    @staticmethod
    def _candidates(reach: list[int], parents: list[int]) -> list[int]:
        """Reachable spheres none of whose children are reachable, in the order of a
        depth-first search that visits children in creation order (the paper's traversal)."""
        inner = set(parents)
        path: dict[int, tuple[int, ...]] = {-1: ()}
        for i, p in zip(reach, parents, strict=True):
            path[i] = path[p] + (i,)
        return sorted((i for i in reach if i not in inner), key=path.__getitem__)

    def learn(
        self,
        x: np.ndarray,
        label: int,
        *,
        spawn: str = "all",
        min_radius: float = 0.0,
        max_nodes: int | None = None,
        max_depth: int | None = None,
    ) -> Growth:
        """Train on one checked vector ``x`` with label index ``label``.

        Every candidate (``spawn="all"``) or only the winning candidate (``spawn="winner"``)
        whose label differs spawns a child, unless a limit suppresses it: the child's radius
        below ``min_radius`` (0 = none), ``max_nodes`` spheres reached, or the child deeper than
        ``max_depth``. A candidate whose centre is within ``eps`` of ``x`` is relabelled instead.
        """
        d_all, reach, parents = self._scan(x)
        cands = self._candidates(reach, parents)
        if spawn == "winner":
            radii, depth = self._radii, self._depth
            w = min(cands, key=lambda i: (radii[i], -depth[i], i))
            targets = [w] if self._label[w] != label else []
        else:
            targets = [c for c in cands if self._label[c] != label]
        spawned = relabelled = 0
        suppressed = False
        eps = self.eps
        for p in targets:
            d = float(d_all[p])
            if d <= eps:
                self._label[p] = label  # coincides with the centre: relabel in place
                self._changed()
                relabelled += 1
                continue
            r = max(float(self._radii[p]) - d, 0.0)
            if (
                (min_radius and r < min_radius)
                or (max_nodes is not None and self.node_count >= max_nodes)
                or (max_depth is not None and self._depth[p] + 1 > max_depth)
            ):
                suppressed = True
                continue
            self._add(x, r, p, label)
            spawned += 1
        return Growth(spawned, relabelled, suppressed)

    # ------------------------------------------------------------------ single queries
    def distance_to(self, node: int, x: np.ndarray) -> float:
        """The distance from ``x`` to the centre of sphere ``node`` (in the tree's units)."""
        diff = self._centers[node] - x
        d = float(np.dot(diff, diff))
        return math.sqrt(d) if self._euclidean else d

    def _build_creation(self) -> _CreationLayout:
        n = self.node_count
        ct = np.ascontiguousarray(self._centers[:n].T)
        by_rank = _tie_break_order(self._radii[:n], self._depth[:n])
        rank = np.empty(n, dtype=np.int64)
        rank[by_rank] = np.arange(n)
        self._creation = _CreationLayout(
            centers_t=ct,
            reach=self._radii[:n] + self.eps,
            diff=np.empty_like(ct),
            dist=np.empty(n),
            enclosed=np.empty(n, dtype=bool),
            parent=self._parent[:n].tolist(),
            rank=rank.tolist(),
            node_of_rank=by_rank.tolist(),
        )
        return self._creation

    def apply_one(self, x: np.ndarray) -> int:
        """The winning sphere (creation index) for one checked query vector.

        Every sphere is tested at once (one vectorised ``sum((x - c)**2)`` over the features,
        in feature order); the few enclosing spheres are then walked in creation order in
        Python: a sphere is reachable iff it encloses ``x`` and its parent is reachable.
        """
        lay = self._creation
        if lay is None:
            lay = self._build_creation()
        buf, d, enc = lay.diff, lay.dist, lay.enclosed
        np.subtract(lay.centers_t, x[:, None], out=buf)
        np.multiply(buf, buf, out=buf)
        np.add.reduce(buf, axis=0, out=d)
        if self._euclidean:
            np.sqrt(d, out=d)
        np.less_equal(d, lay.reach, out=enc)
        parent, rank = lay.parent, lay.rank
        best = len(rank)
        ok = {-1}
        for i in np.flatnonzero(enc).tolist():
            if parent[i] in ok:
                ok.add(i)
                r = rank[i]
                if r < best:
                    best = r
        return lay.node_of_rank[best]

    def predict_one(self, x: np.ndarray) -> int:
        """The label index of the winning sphere for one checked query vector."""
        return int(self._label[self.apply_one(x)])

    def path(self, node: int) -> list[int]:
        """Creation indices from the root down to ``node``."""
        out = []
        while node >= 0:
            out.append(node)
            node = int(self._parent[node])
        return out[::-1]

    # ------------------------------------------------------------------ batch queries
    def apply(self, X: np.ndarray, algorithm: str = "auto") -> np.ndarray:
        """The winning sphere (creation index) of each row of a checked ``X`` (m, features).

        ``algorithm``: ``"brute"`` tests every (query, sphere) pair at once; ``"descent"``
        walks down the tree carrying the queries each sphere encloses and tests only the
        children of enclosing spheres; ``"auto"`` uses ``"brute"`` for trees of at most
        64 spheres, else ``"descent"``. All give exactly the same answers.
        """
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
        if X.shape[0] == 0:
            return np.zeros(0, dtype=np.int64)
        if algorithm == "auto":
            algorithm = "brute" if self.node_count <= _BRUTE_MAX_NODES else "descent"
        lay = self._preorder
        if lay is None:
            lay = self._build_preorder()
        if algorithm == "brute":
            return self._apply_brute(X, lay)
        return self._apply_descent(X, lay)

    def predict(self, X: np.ndarray, algorithm: str = "auto") -> np.ndarray:
        """The label index of the winning sphere of each row of a checked ``X``."""
        return self._label[self.apply(X, algorithm)]

    def _build_preorder(self) -> _PreorderLayout:
        n = self.node_count
        children = self.children
        order, end = _preorder(children, n)
        position_of = np.empty(n, dtype=np.int64)
        position_of[order] = np.arange(n)
        radii = self._radii[:n]
        by_rank = _tie_break_order(radii, self._depth[:n])
        rank = np.empty(n, dtype=np.int64)
        rank[by_rank] = np.arange(n)
        centers_t = np.ascontiguousarray(self._centers[order].T)
        reach = radii[order] + self.eps
        # per pre-order position: the children's positions, centres and reach
        kids: list[np.ndarray | None] = []
        kids_ct: list[np.ndarray | None] = []
        kids_reach: list[np.ndarray | None] = []
        for i in order.tolist():
            if children[i]:
                k = position_of[children[i]]
                kids.append(k)
                kids_ct.append(np.ascontiguousarray(centers_t[:, k]))
                kids_reach.append(reach[k])
            else:
                kids.append(None)
                kids_ct.append(None)
                kids_reach.append(None)
        sure, maybe = _reach_bands(kids_reach, self.n_features, self._euclidean)
        self._preorder = _PreorderLayout(
            centers_t=centers_t,
            reach=reach,
            subtree_end=end[order],
            position=np.arange(n),
            rank=rank[order],
            no_rank=np.int64(n),
            node_of_rank=by_rank,
            child_positions=kids,
            child_centers_t=kids_ct,
            child_centers=[None if k is None else np.ascontiguousarray(k.T) for k in kids_ct],
            child_sq_norms=[None if k is None else np.einsum("ij,ij->j", k, k) for k in kids_ct],
            child_reach=kids_reach,
            child_sure=sure,
            child_maybe=maybe,
        )
        return self._preorder

    def _apply_brute(self, X: np.ndarray, lay: _PreorderLayout) -> np.ndarray:
        """Every (query, sphere) pair at once, in chunks of queries."""
        n_nodes = self.node_count
        ct = lay.centers_t
        out = np.empty(X.shape[0], dtype=np.int64)
        step = max(1, _CHUNK_PAIRS // max(n_nodes, 1))
        for s in range(0, X.shape[0], step):
            Q = X[s : s + step]
            d = np.zeros((Q.shape[0], n_nodes))
            for k in range(ct.shape[0]):
                t = Q[:, k, None] - ct[k]
                t *= t
                d += t
            if self._euclidean:
                np.sqrt(d, out=d)
            # a sphere is unreachable if it or an ancestor does not enclose the query: the
            # running maximum of the subtree ends of non-enclosing spheres covers exactly those
            bad = d > lay.reach
            reach_end = np.maximum.accumulate(lay.subtree_end * bad, axis=1)
            key = np.where(reach_end > lay.position, lay.no_rank, lay.rank)
            out[s : s + step] = lay.node_of_rank[key.min(axis=1)]
        return out

    def _apply_descent(self, X: np.ndarray, lay: _PreorderLayout) -> np.ndarray:
        """Descend sphere by sphere, carrying the queries each sphere encloses.

        Only the children of spheres that enclose some query are tested. Children are tested
        against many queries at once with a matrix product (the expanded form of the squared
        distance) as a *filter*: every (query, child) pair whose expanded distance lies within
        a rounding-error band of the radius is recomputed exactly as ``sum((x - c)**2)``, so
        the answers are exactly those of the direct form.
        """
        m = X.shape[0]
        rank = lay.rank
        kids_of = lay.child_positions
        kids_c = lay.child_centers
        kids_cc = lay.child_sq_norms
        kids_sure = lay.child_sure
        kids_maybe = lay.child_maybe
        kids_reach = lay.child_reach
        euclidean = self._euclidean
        XT = np.ascontiguousarray(X.T)
        XX = np.einsum("ij,ij->i", X, X)
        best = np.full(m, rank[0], dtype=np.int64)
        stack: list[tuple[int, np.ndarray | None]] = [(0, None)]
        while stack:
            node, q = stack.pop()
            kids = kids_of[node]
            if kids is None:  # a leaf (only the root can get here)
                continue
            if q is None:
                q = np.arange(m)
                xt, xx = XT, XX
            else:
                xt = XT[:, q]
                xx = XX[q]
            d = np.einsum("kn,nq->kq", kids_c[node], xt)  # (no BLAS threads)
            d *= -2.0
            d += kids_cc[node][:, None]
            d += xx
            enc = d <= kids_sure[node][:, None]
            maybe = d <= kids_maybe[node][:, None]
            if not np.array_equal(enc, maybe):
                jj, ii = np.nonzero(maybe & ~enc)
                ct = lay.child_centers_t[node]
                exact = (ct[0][jj] - xt[0][ii]) ** 2
                for k in range(1, ct.shape[0]):
                    exact += (ct[k][jj] - xt[k][ii]) ** 2
                if euclidean:
                    np.sqrt(exact, out=exact)
                ok = exact <= kids_reach[node][jj]
                enc[jj[ok], ii[ok]] = True
            for j in np.flatnonzero(enc.any(axis=1)).tolist():
                qj = q[enc[j]]
                c = int(kids[j])
                best[qj] = np.minimum(best[qj], rank[c])
                if kids_of[c] is not None:
                    stack.append((c, qj))
        return lay.node_of_rank[best]
