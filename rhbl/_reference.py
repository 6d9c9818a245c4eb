"""The sphere tree's searches and training scan in numpy: the reference the kernels are checked
against (``compiled=False`` of :class:`rhbl.tree.SphereTree` and
:class:`rhbl.HypersphereClassifier`).

This is the tree's code from before the compiled kernels (:mod:`rhbl._kernels`), unchanged but
for being functions of the tree rather than its methods: the tests compare the kernels with it
array by array, and ``benchmarks/bench_classifier.py`` measures it beside them. Each function
takes a :class:`rhbl.tree.SphereTree` and uses its tables; the layouts it builds are cached on
the tree (``tree._creation``, ``tree._preorder``) until the tree changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

# an rhbl.tree.SphereTree: tree.py imports this module, so it is named here, never imported
SphereTree = Any

__all__ = ["apply", "apply_one", "learn", "nearest"]

# "auto" tests every (query, sphere) pair at once for trees of at most this many spheres and
# descends the tree for larger ones
BRUTE_MAX_NODES = 64
# the brute search works in chunks of queries of about this many (query, sphere) pairs
_CHUNK_PAIRS = 1 << 21


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


def _scan(tree: SphereTree, x: np.ndarray) -> tuple[np.ndarray, list[int], list[int]]:
    """Distances from ``x`` to every centre, and the spheres reachable through enclosing
    ancestors, in creation order, with their parents.

    The arithmetic is exactly that of :func:`apply_one`: one ``sum((c - x)**2)`` over the
    features in feature order and the test ``d <= r + eps``, so training and prediction
    always agree on which spheres enclose a vector.
    """
    n = tree.node_count
    buf = np.subtract(tree.centers_t(), x[:, None])
    np.multiply(buf, buf, out=buf)
    d = np.add.reduce(buf, axis=0)
    if tree._euclidean:
        np.sqrt(d, out=d)
    enc = np.flatnonzero(d <= tree._radii[:n] + tree.eps)
    ok = {-1}
    reach: list[int] = []
    parents: list[int] = []
    for i, p in zip(enc.tolist(), tree._parent[enc].tolist(), strict=True):
        if p in ok:
            ok.add(i)
            reach.append(i)
            parents.append(p)
    return d, reach, parents


def _candidates(reach: list[int], parents: list[int]) -> list[int]:
    """Reachable spheres none of whose children are reachable, in the order of a
    depth-first search that visits children in creation order (the paper's traversal)."""
    inner = set(parents)
    path: dict[int, tuple[int, ...]] = {-1: ()}
    for i, p in zip(reach, parents, strict=True):
        path[i] = path[p] + (i,)
    return sorted((i for i in reach if i not in inner), key=path.__getitem__)


def learn(
    tree: SphereTree,
    x: np.ndarray,
    label: int,
    *,
    spawn: str = "all",
    min_radius: float = 0.0,
    max_nodes: int | None = None,
    max_depth: int | None = None,
    max_radius: float = math.inf,
) -> tuple[int, int, bool]:
    """:meth:`rhbl.tree.SphereTree.learn` in numpy (the same rule); returns the spheres spawned
    and relabelled, and whether a growth limit suppressed a spawn."""
    d_all, reach, parents = _scan(tree, x)
    cands = _candidates(reach, parents)
    if spawn == "winner":
        radii, depth = tree._radii, tree._depth
        cands = [min(cands, key=lambda i: (radii[i], -depth[i], i))]
    n = tree.node_count
    if tree.uncovered == "nearest" and n > 1 and cands == [0]:
        # only the root encloses x: the nearest centre answers (the first of equals, as the
        # kernel), and a wrong answer spawns a child of the root
        answer = tree._label[nearest(tree, x)]
        targets = [0] if answer != label else []
    else:
        targets = [c for c in cands if tree._label[c] != label]
    spawned = relabelled = 0
    suppressed = False
    eps = tree.eps
    for p in targets:
        d = float(d_all[p])
        if d <= eps:
            tree._label[p] = label  # coincides with the centre: relabel in place
            tree._changed()
            relabelled += 1
            continue
        r = max(min(float(tree._radii[p]) - d, max_radius), 0.0)
        if (
            (min_radius and r < min_radius)
            or (max_nodes is not None and tree.node_count >= max_nodes)
            or (max_depth is not None and tree._depth[p] + 1 > max_depth)
        ):
            suppressed = True
            continue
        tree._add(x, r, p, label)
        spawned += 1
    return spawned, relabelled, suppressed


def nearest(tree: SphereTree, x: np.ndarray) -> int:
    """The sphere (the root left out) whose centre is nearest to ``x``, the first of equals:
    ``sum((c - x)**2)`` over the features in feature order, as the kernel sums it (a tree of
    at least two spheres)."""
    n = tree.node_count
    sq = np.add.reduce(np.square(np.subtract(tree.centers_t()[:, 1:n], x[:, None])), axis=0)
    return int(np.argmin(sq)) + 1


def _build_creation(tree: SphereTree) -> _CreationLayout:
    n = tree.node_count
    ct = np.ascontiguousarray(tree._centers[:n].T)
    by_rank = _tie_break_order(tree._radii[:n], tree._depth[:n])
    rank = np.empty(n, dtype=np.int64)
    rank[by_rank] = np.arange(n)
    tree._creation = _CreationLayout(
        centers_t=ct,
        reach=tree._radii[:n] + tree.eps,
        diff=np.empty_like(ct),
        dist=np.empty(n),
        enclosed=np.empty(n, dtype=bool),
        parent=tree._parent[:n].tolist(),
        rank=rank.tolist(),
        node_of_rank=by_rank.tolist(),
    )
    return tree._creation


def apply_one(tree: SphereTree, x: np.ndarray) -> int:
    """The winning sphere (creation index) for one checked query vector.

    Every sphere is tested at once (one vectorised ``sum((x - c)**2)`` over the features,
    in feature order); the few enclosing spheres are then walked in creation order in
    Python: a sphere is reachable iff it encloses ``x`` and its parent is reachable.
    """
    lay = tree._creation
    if lay is None:
        lay = _build_creation(tree)
    buf, d, enc = lay.diff, lay.dist, lay.enclosed
    np.subtract(lay.centers_t, x[:, None], out=buf)
    np.multiply(buf, buf, out=buf)
    np.add.reduce(buf, axis=0, out=d)
    if tree._euclidean:
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


def apply(tree: SphereTree, X: np.ndarray, algorithm: str) -> np.ndarray:
    """The winning sphere (creation index) of each row of a checked ``X`` (m, features).

    ``algorithm``: ``"brute"`` tests every (query, sphere) pair at once; ``"descent"``
    walks down the tree carrying the queries each sphere encloses and tests only the
    children of enclosing spheres; ``"auto"`` uses ``"brute"`` for trees of at most
    64 spheres, else ``"descent"``. All give exactly the same answers.
    """
    if X.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    if algorithm == "auto":
        algorithm = "brute" if tree.node_count <= BRUTE_MAX_NODES else "descent"
    lay = tree._preorder
    if lay is None:
        lay = _build_preorder(tree)
    if algorithm == "brute":
        return _apply_brute(tree, X, lay)
    return _apply_descent(tree, X, lay)


def _build_preorder(tree: SphereTree) -> _PreorderLayout:
    n = tree.node_count
    order = np.empty(n, dtype=np.int64)
    end = np.empty(n, dtype=np.int64)
    children = tree.children
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
    position_of = np.empty(n, dtype=np.int64)
    position_of[order] = np.arange(n)
    radii = tree._radii[:n]
    by_rank = _tie_break_order(radii, tree._depth[:n])
    rank = np.empty(n, dtype=np.int64)
    rank[by_rank] = np.arange(n)
    centers_t = np.ascontiguousarray(tree._centers[order].T)
    reach = radii[order] + tree.eps
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
    # the band of rounding error of the expanded squared distance around each child's reach
    n_feat = tree.n_features
    tol = 16 * 2.0**-53 * (n_feat * n_feat + 4 * n_feat)
    sure: list[np.ndarray | None] = []
    maybe: list[np.ndarray | None] = []
    for r in kids_reach:
        if r is None:
            sure.append(None)
            maybe.append(None)
            continue
        lim = r * r if tree._euclidean else r
        band = tol + (8 * 2.0**-53 * lim if tree._euclidean else 0.0)
        sure.append(lim - band)
        maybe.append(lim + band)
    tree._preorder = _PreorderLayout(
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
    return tree._preorder


def _apply_brute(tree: SphereTree, X: np.ndarray, lay: _PreorderLayout) -> np.ndarray:
    """Every (query, sphere) pair at once, in chunks of queries."""
    n_nodes = tree.node_count
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
        if tree._euclidean:
            np.sqrt(d, out=d)
        # a sphere is unreachable if it or an ancestor does not enclose the query: the
        # running maximum of the subtree ends of non-enclosing spheres covers exactly those
        bad = d > lay.reach
        reach_end = np.maximum.accumulate(lay.subtree_end * bad, axis=1)
        key = np.where(reach_end > lay.position, lay.no_rank, lay.rank)
        out[s : s + step] = lay.node_of_rank[key.min(axis=1)]
    return out


def _apply_descent(tree: SphereTree, X: np.ndarray, lay: _PreorderLayout) -> np.ndarray:
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
    euclidean = tree._euclidean
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
