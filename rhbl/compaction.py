"""Compaction: delete spheres from a trained tree while keeping what it does on given data.

The paper's rule (``HypersphereClassifier.partial_fit``) never deletes a sphere. Compaction is a
separate, named step on a finished tree; it never changes the training rule, and the tree it
returns is an ordinary tree (it can be trained further with ``partial_fit``, saved and loaded).

Deleting a sphere ``s`` (never the root) gives its children to its parent ``p`` (the children keep
their centres, radii and labels; their radii never exceed ``p``'s, since they do not exceed
``s``'s). Because classification only requires every *ancestor* to enclose a vector, a deletion
never makes any other sphere unreachable: vectors that reached ``s`` lose ``s`` only, and vectors
that reached ``p`` but not ``s`` may now reach ``s``'s descendants. So the effect of one deletion
is local and is computed exactly on the given vectors (the same arithmetic as prediction:
``sum((c - x)**2)`` in feature order and ``d <= r + eps``).

Methods (``compact(clf, X, y, method=...)``):

* ``"exact"``: delete every sphere whose deletion changes no prediction on ``X`` (passes in reverse
  creation order until a pass deletes nothing). ``predict(X)`` is the same before and after.
* ``"prune"``: the exact step, then reduced-error pruning, weakest link first: repeatedly delete
  the sphere whose deletion adds the fewest errors against the labels ``y`` (weighted by
  ``sample_weight`` / ``class_weight``; ties: the latest created), while the errors added in
  total stay within ``max_error`` (a fraction of the total weight) or, with ``max_nodes``, until
  the tree has at most that many spheres. ``X``/``y`` are typically the states the learned robot
  visited, labelled by the teacher (its training data, and held-out states of other runs).

A sphere whose radius equals another sphere's radius exactly is never deleted (deleting it
could reorder a tie of the winner rule, which depends on depth); such ties are rare.

Every compaction appends a record to ``metadata["compaction"]`` of the returned tree: method,
settings, nodes and height before and after, and what data it used (rows, ``data`` note).
"""

from __future__ import annotations

import heapq
from typing import Any

import numpy as np

from .tree import SphereTree

# an rhbl.HypersphereClassifier: this module sits below classifier.py (tree <- compact <-
# classifier, whose ``compact`` method delegates here), so it names the class, never imports it
HypersphereClassifier = Any

__all__ = ["METHODS", "compact", "removal_curve", "without"]

METHODS = ("exact", "prune")


class _Tree:
    """A tree being compacted: the original spheres, which are alive, and per vector the spheres
    it reaches and the one that wins."""

    def __init__(self, clf: HypersphereClassifier, X: np.ndarray):
        arr = clf.tree_arrays()
        self.centers = arr["centers"]
        self.radii = arr["radii"]
        self.parent = arr["parent"].copy()
        self.depth = arr["depth"].copy()
        self.label = arr["label"]
        self.eps = float(clf.tree_.eps)
        self.euclid = clf.tree_.distance == "euclidean"
        n = len(self.radii)
        self.n = n
        self.alive = np.ones(n, dtype=bool)
        self.children: list[list[int]] = [[] for _ in range(n)]
        for i in range(1, n):
            self.children[int(self.parent[i])].append(i)
        self.X = X
        # winner order: smallest radius, then deepest, then earliest (fixed: see _tied)
        by_rank = np.lexsort((np.arange(n), -self.depth, self.radii))
        self.rank = np.empty(n, dtype=np.int64)
        self.rank[by_rank] = np.arange(n)
        _, inv, counts = np.unique(self.radii, return_inverse=True, return_counts=True)
        self.tied = counts[inv] > 1
        self.tied[0] = True  # the root is never deleted
        # reach sets, top-down in creation order (parents precede children)
        m = X.shape[0]
        self.reach: list[np.ndarray | None] = [None] * n
        self.reach[0] = np.flatnonzero(self._enc(np.arange(m), 0))
        best = np.full(m, n, dtype=np.int64)
        best[self.reach[0]] = self.rank[0]
        for t in range(1, n):
            cand = self.reach[int(self.parent[t])]
            r = cand[self._enc(cand, t)] if cand.size else cand
            self.reach[t] = r
            if r.size:
                best[r] = np.minimum(best[r], self.rank[t])
        by = np.empty(n + 1, dtype=np.int64)
        by[:n] = by_rank
        by[n] = -1
        self.by_rank = by
        self.win = by[best]

    # -- geometry, exactly as the classifier computes it
    def _dist(self, rows: np.ndarray, node: int) -> np.ndarray:
        c = self.centers[node]
        X = self.X
        d = (c[0] - X[rows, 0]) ** 2
        for k in range(1, X.shape[1]):
            d += (c[k] - X[rows, k]) ** 2
        if self.euclid:
            np.sqrt(d, out=d)
        return d

    def _enc(self, rows: np.ndarray, node: int) -> np.ndarray:
        return self._dist(rows, node) <= self.radii[node] + self.eps

    def height(self) -> int:
        return int(self.depth[self.alive].max())

    def subtree(self, s: int) -> list[int]:
        out, stack = [], [s]
        while stack:
            i = stack.pop()
            out.append(i)
            stack.extend(self.children[i])
        return out

    def _best_without(self, rows: np.ndarray, s: int) -> np.ndarray:
        """The winner of each vector of ``rows`` among the spheres it reaches now, except ``s``:
        a descent from the root carrying the rows each sphere encloses (children tested all at
        once per sphere, with the arithmetic of ``_dist``)."""
        X = self.X
        rank = self.rank
        best = np.full(rows.size, self.n, dtype=np.int64)  # best rank so far
        stack = [(0, np.arange(rows.size))]
        while stack:
            node, idx = stack.pop()
            if node != s:
                best[idx] = np.minimum(best[idx], rank[node])
            kids = self.children[node]
            if not kids:
                continue
            C = self.centers[kids]
            Q = X[rows[idx]]
            d = (C[None, :, 0] - Q[:, 0, None]) ** 2
            for k in range(1, Q.shape[1]):
                d += (C[None, :, k] - Q[:, k, None]) ** 2
            if self.euclid:
                np.sqrt(d, out=d)
            enc = d <= self.radii[kids] + self.eps
            for j in np.flatnonzero(enc.any(axis=0)).tolist():
                stack.append((kids[j], idx[enc[:, j]]))
        return self.by_rank[best]

    # -- one deletion, evaluated without changing anything
    def evaluate(self, s: int):
        """What deleting ``s`` does: None if it must be kept, else (rows whose winner changes or
        may change, their new winners, the subtree of ``s`` and the rows each of its spheres
        gains).

        Rows that reach ``s`` keep reaching everything they reach now but ``s``; only those
        that ``s`` wins need a new winner (among all spheres they reach, but ``s``). Rows that
        reach the parent but not ``s`` may gain spheres of the subtree (tested top-down, each
        sphere on the rows its new parent gained); their winner can only get better."""
        if s == 0 or not self.alive[s]:
            return None
        sub = self.subtree(s)
        if self.tied[sub].any():
            return None
        p = int(self.parent[s])
        rs = self.reach[s]
        lost = rs[self.win[rs] == s]
        outside = np.setdiff1d(self.reach[p], rs, assume_unique=True)
        gain: dict[int, np.ndarray] = {}
        for t in sub[1:]:  # parents before children in this DFS order
            q = int(self.parent[t])
            cand = outside if q == s else gain.get(q)
            if cand is None or not cand.size:
                continue
            r = cand[self._enc(cand, t)]
            if r.size:
                gain[t] = r
        parts = [lost, *gain.values()]
        rows = np.unique(np.concatenate(parts)) if gain else lost
        if rows.size == 0:
            return rows, rows, sub, gain
        cur = self.win[rows].copy()
        if lost.size:
            cur[np.searchsorted(rows, lost)] = self._best_without(lost, s)
        for t, r in gain.items():
            idx = np.searchsorted(rows, r)
            better = self.rank[t] < self.rank[cur[idx]]
            cur[idx[better]] = t
        return rows, cur, sub, gain

    def apply(self, s: int, result) -> None:
        rows, new_win, sub, gain = result
        p = int(self.parent[s])
        self.alive[s] = False
        kids = self.children[s]
        self.children[p] = sorted([c for c in self.children[p] if c != s] + kids)
        for c in kids:
            self.parent[c] = p
        self.children[s] = []
        self.depth[sub[1:]] -= 1
        for t, r in gain.items():
            self.reach[t] = np.union1d(self.reach[t], r)
        self.reach[s] = None
        self.win[rows] = new_win


def _check(clf: HypersphereClassifier, X: Any, y: Any, need_y: bool):
    """``X`` as the classifier checks it (through its public ``predict``, which raises
    ``ValueError`` naming the bad input), and ``y`` as label indices (-1: a label the tree does
    not know)."""
    if not (hasattr(type(clf), "from_tree") and hasattr(clf, "tree_arrays")):
        raise TypeError(f"compact needs a HypersphereClassifier, got {type(clf).__name__}")
    clf.predict(X)  # fitted, numeric, 2-D, the tree's features, finite, in [0, 1] unless clip
    X = np.asarray(X, dtype=np.float64)
    if clf.clip:
        X = np.clip(X, 0.0, 1.0)
    if y is None:
        if need_y:
            raise ValueError("this method needs the labels y of X")
        return X, None
    y = np.asarray(y, dtype=object).reshape(-1).tolist()
    if len(y) != X.shape[0]:
        raise ValueError(f"X has {X.shape[0]} rows but y has {len(y)} labels")
    index = {v: i for i, v in enumerate(clf.classes_.tolist())}
    return X, np.array([index.get(v, -1) for v in y], dtype=np.int64)


def _build(clf: HypersphereClassifier, tree: _Tree, record: dict) -> HypersphereClassifier:
    """A new classifier with only the alive spheres (creation order kept, parents remapped),
    built through ``SphereTree.from_arrays`` and ``HypersphereClassifier.from_tree``."""
    keep = np.flatnonzero(tree.alive)
    new_index = np.full(tree.n, -1, dtype=np.int64)
    new_index[keep] = np.arange(keep.size)
    parent = np.where(tree.parent[keep] >= 0, new_index[tree.parent[keep]], -1)
    arr = clf.tree_arrays()
    spheres = SphereTree.from_arrays(arr["centers"][keep], arr["radii"][keep], parent,
                                     arr["label"][keep], distance=clf.tree_.distance,
                                     eps=clf.tree_.eps)
    meta = dict(clf.metadata)
    meta["compaction"] = [*list(meta.get("compaction", [])), record]
    return type(clf).from_tree(
        spheres, clf.classes_.tolist(), n_seen=clf.n_seen_, n_skipped=clf.n_skipped_,
        n_relabelled=clf.n_relabelled_, metadata=meta, **clf.get_params())


def _weights(yi: np.ndarray, sample_weight: Any, class_weight: str | None) -> np.ndarray:
    """Per-row weight of an error: ``sample_weight`` times the class weight ("balanced": every
    label's rows weigh as much in total, ``m / (labels * count)``, as in scikit-learn)."""
    m = yi.shape[0]
    if sample_weight is None:
        w = np.ones(m)
    else:
        w = np.asarray(sample_weight, dtype=np.float64).reshape(-1)
        if w.shape[0] != m or not np.isfinite(w).all() or (w < 0).any():
            raise ValueError(f"sample_weight must be {m} finite numbers >= 0, got shape "
                             f"{w.shape}")
        w = w.copy()
    if class_weight == "balanced" and m:
        _, inv, counts = np.unique(yi, return_inverse=True, return_counts=True)
        w *= m / (len(counts) * counts[inv])
    elif class_weight is not None:
        raise ValueError(f"class_weight must be None or 'balanced', got {class_weight!r}")
    return w


def compact(clf: HypersphereClassifier, X: Any, y: Any = None, *, method: str = "exact",
            max_error: float = 0.0, max_nodes: int | None = None,
            sample_weight: Any = None, class_weight: str | None = None,
            data: str | None = None) -> HypersphereClassifier:
    """A compacted copy of ``clf`` (``clf`` itself is not changed). See the module docstring.

    ``X`` (and ``y``, needed by ``"prune"``): the vectors (and labels) the compaction keeps the
    tree's behaviour on. ``max_error`` (``"prune"``): the fraction of the rows of ``X`` whose
    errors the pruning may add in total (0 = no row may become wrong unless another becomes
    right). ``max_nodes`` (``"prune"``): keep deleting the weakest sphere until at most this many
    are left, whatever it costs (``max_error`` is then ignored). ``sample_weight`` /
    ``class_weight="balanced"`` (``"prune"``): what an error on each row costs (scikit-learn's
    conventions; "balanced" keeps rare labels, such as a turn in place before a wall, from being
    pruned away as cheap). ``max_error`` is then a fraction of the total weight. ``data``: a note
    of where ``X`` came from, kept in the provenance record.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if not (isinstance(max_error, int | float) and 0.0 <= max_error <= 1.0):
        raise ValueError(f"max_error must be a number in [0, 1], got {max_error!r}")
    if max_nodes is not None and (not isinstance(max_nodes, int | np.integer) or max_nodes < 1):
        raise ValueError(f"max_nodes must be None or an int >= 1, got {max_nodes!r}")
    X, yi = _check(clf, X, y, need_y=method == "prune")
    if clf.tree_.uncovered != "root":
        raise ValueError("compaction keeps a tree's answers by the paper's rule (the smallest "
                         "enclosing sphere); a tree with radius='margin' answers the vectors no "
                         "sphere but the root encloses by the nearest centre, which it does not "
                         "model")
    tree = _Tree(clf, X)
    before = (tree.n, tree.height())
    settings: dict[str, Any] = {}
    if method == "exact":
        if sample_weight is not None or class_weight is not None:
            raise ValueError("sample_weight/class_weight apply to method='prune' only")
        _exact(tree)
    else:
        settings = {"max_error": float(max_error), "max_nodes": max_nodes,
                    "class_weight": class_weight,
                    "sample_weight": None if sample_weight is None else "given"}
        w = _weights(yi, sample_weight, class_weight)
        budget = max_error * float(w.sum()) + 1e-9 if max_nodes is None else None
        _exact(tree)  # free deletions first (they change no prediction, so cost nothing)
        _prune(tree, yi, w, budget=budget, max_nodes=max_nodes)
    record = {"method": method, "settings": settings,
              "nodes_before": before[0], "height_before": before[1],
              "nodes_after": int(tree.alive.sum()), "height_after": tree.height(),
              "data": {"rows": int(X.shape[0]), "labelled": yi is not None,
                       "source": data}}
    if yi is not None:
        lab = tree.label
        record["data"]["errors_before"] = int((_predict_index(clf, X) != yi).sum()) \
            if X.shape[0] else 0
        record["data"]["errors_after"] = int((lab[tree.win] != yi).sum())
    out = _build(clf, tree, record)
    if method == "exact" and X.shape[0] and not np.array_equal(
            out.predict(X), clf.predict(X)):  # pragma: no cover
        raise RuntimeError("exact compaction changed a prediction (a bug; please report)")
    return out


def _predict_index(clf: HypersphereClassifier, X: np.ndarray) -> np.ndarray:
    """The label index each row of a checked ``X`` gets (the tree's own batch prediction)."""
    return clf.tree_.predict(X, clf.algorithm, compiled=clf.compiled)


def _exact(tree: _Tree, deleted: list | None = None) -> None:
    """Delete every sphere whose deletion changes no prediction (passes in reverse creation
    order until one deletes nothing); ``deleted`` receives ``(sphere, height after)`` in the
    order of deletion (each changed no prediction *at its turn*, so only prefixes of that
    order keep every prediction)."""
    lab = tree.label
    changed = True
    while changed:
        changed = False
        for s in range(tree.n - 1, 0, -1):
            res = tree.evaluate(s)
            if res is None:
                continue
            rows, new_win = res[0], res[1]
            if np.array_equal(lab[new_win], lab[tree.win[rows]]):
                tree.apply(s, res)
                changed = True
                if deleted is not None:
                    deleted.append((s, tree.height()))


def _cost(tree: _Tree, res, yi: np.ndarray, w: np.ndarray) -> float:
    rows, new_win = res[0], res[1]
    lab = tree.label
    t = yi[rows]
    return float(w[rows] @ ((lab[new_win] != t).astype(np.float64)
                            - (lab[tree.win[rows]] != t)))


def _prune(tree: _Tree, yi: np.ndarray, w: np.ndarray, budget: float | None,
           max_nodes: int | None, curve: list | None = None) -> None:
    """Weakest link first (lazy greedy: a popped cost is recomputed before it is used)."""
    heap = []
    for s in range(1, tree.n):
        res = tree.evaluate(s)
        if res is not None:
            heap.append((_cost(tree, res, yi, w), -s))
    heapq.heapify(heap)
    spent = 0
    alive = int(tree.alive.sum())
    errors = float(w @ (tree.label[tree.win] != yi))
    while heap:
        if max_nodes is not None and alive <= max_nodes:
            break
        stale, neg = heapq.heappop(heap)
        s = -neg
        res = tree.evaluate(s)
        if res is None:
            continue
        c = _cost(tree, res, yi, w)
        if heap and (c, neg) > heap[0]:
            heapq.heappush(heap, (c, neg))
            continue
        if budget is not None and c > 1e-12 and spent + c > budget:
            break
        tree.apply(s, res)
        spent += c
        errors += c
        alive -= 1
        if curve is not None:
            curve.append((s, alive, tree.height(), round(errors, 6)))


def removal_curve(clf: HypersphereClassifier, X: Any, y: Any, *, exact_first: bool = True,
                  sample_weight: Any = None, class_weight: str | None = None):
    """The whole weakest-link pruning sequence of ``clf`` on ``(X, y)``, for trade-off studies:
    a list of ``(sphere, nodes, height, errors)``, one per deletion in order (``sphere``: its
    creation index in ``clf``; then the tree's nodes, height and errors against ``y`` on ``X``).
    ``errors`` are weighted as in ``compact``'s ``sample_weight``/``class_weight``.
    ``exact_first``: the exact compaction's deletions come first. ``without(clf, spheres)``
    builds the tree after any prefix of the sequence."""
    X, yi = _check(clf, X, y, need_y=True)
    w = _weights(yi, sample_weight, class_weight)
    tree = _Tree(clf, X)
    curve: list = []
    if exact_first:
        dead: list[tuple[int, int]] = []
        _exact(tree, dead)
        errs = round(float(w @ (tree.label[tree.win] != yi)), 6)
        curve += [(s, tree.n - k - 1, height, errs) for k, (s, height) in enumerate(dead)]
    _prune(tree, yi, w, budget=None, max_nodes=1, curve=curve)
    return curve


def without(clf: HypersphereClassifier, spheres: Any, record: dict | None = None
            ) -> HypersphereClassifier:
    """``clf`` with the given spheres (creation indices, never the root) deleted, each one's
    children given to its nearest kept ancestor. ``record`` is appended to
    ``metadata["compaction"]`` (default: method "without", nodes before and after)."""
    if not (hasattr(type(clf), "from_tree") and hasattr(clf, "tree_arrays")):
        raise TypeError(f"without needs a HypersphereClassifier, got {type(clf).__name__}")
    arr = clf.tree_arrays()  # raises NotFittedError for an unfitted classifier
    n = len(arr["radii"])
    gone = np.zeros(n, dtype=bool)
    idx = np.asarray(list(spheres), dtype=np.int64)
    if idx.size and (idx.min() < 1 or idx.max() >= n):
        raise ValueError(f"spheres must be creation indices in 1..{n - 1} (the root stays)")
    gone[idx] = True
    tree = _Tree.__new__(_Tree)
    parent = arr["parent"].copy()
    for i in range(1, n):  # parents precede children: a parent's own parent is final already
        p = int(parent[i])
        if gone[p]:
            parent[i] = parent[p]
    depth = np.zeros(n, dtype=np.int64)
    for i in range(1, n):
        depth[i] = depth[int(parent[i])] + 1
    tree.n, tree.alive, tree.parent, tree.depth = n, ~gone, parent, depth
    rec = record if record is not None else {"method": "without", "settings": {}}
    rec = dict(rec, nodes_before=n, height_before=int(arr["depth"].max()),
               nodes_after=int((~gone).sum()), height_after=int(depth[~gone].max()))
    return _build(clf, tree, rec)
