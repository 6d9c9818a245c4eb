"""The sphere tree's compiled kernels (numba): the winner searches and the training scan.

The kernels work on the two node tables of :class:`rhbl.tree.SphereTree` (one row per sphere,
in creation order, the capacity's rows allocated):

* ``nodes_f`` (float64, ``(capacity, features + 1)``): the centre, then the radius;
* ``nodes_i`` (int64, ``(capacity, 6)``): the columns below: parent (-1 for the root), depth,
  label index and the children as a linked list in creation order (first child, next sibling,
  last child; -1 for none).

Few, wide tables keep a call cheap (numba unboxes each array argument, a few hundred
nanoseconds each) and each sphere's data together in memory. A per-sphere value added later is
one more column; a kernel reads only the columns it names.

The arithmetic is that of the numpy code in :mod:`rhbl._reference` (the tests compare them
array by array): the distance is ``sum((c - x)**2)`` accumulated in feature order (its square
root for ``euclidean``), a sphere encloses ``x`` iff ``d <= r + eps``, the winner is the
reachable sphere of smallest radius, then deepest, then earliest created. The root encloses
every vector of the unit cube, so the searches start from its children.

Each kernel is compiled on its first call, or loaded from numba's cache (next to this file, else
in the user's cache folder or ``NUMBA_CACHE_DIR``); :func:`load` does that once per process.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

__all__ = ["I_COLUMNS", "learn", "load", "winner", "winners"]

# the columns of ``nodes_i``
PARENT, DEPTH, LABEL, FIRST, NEXT, LAST = range(6)
I_COLUMNS = 6
# the entries of ``learn``'s totals
ROWS, NODES, HEIGHT, SPAWNED, RELABELLED, SKIPPED = range(6)


def _jit(func):
    """Compile ``func`` on its first call, cached on disk; without a writable cache folder
    (numba: "no locator available") it is compiled in each process."""
    try:
        return njit(cache=True, nogil=True, error_model="numpy")(func)
    except RuntimeError:
        return njit(nogil=True, error_model="numpy")(func)


@_jit
def _distance(nodes_f, i, x, euclidean):
    """``sum((c_i - x)**2)`` in feature order (its square root for ``euclidean``)."""
    d = 0.0
    for k in range(x.shape[0]):
        t = nodes_f[i, k] - x[k]
        d += t * t
    return math.sqrt(d) if euclidean else d


@_jit
def _better(nodes_f, nodes_i, a, b, radius_col):
    """True if sphere ``a`` wins over sphere ``b``: smaller radius, then deeper, then earlier."""
    ra, rb = nodes_f[a, radius_col], nodes_f[b, radius_col]
    if ra != rb:
        return ra < rb
    da, db = nodes_i[a, DEPTH], nodes_i[b, DEPTH]
    if da != db:
        return da > db
    return a < b


@_jit
def _descend(nodes_f, nodes_i, x, eps, euclidean, stack):
    """The winner for ``x`` and the number of spheres whose distance was computed: only the
    children of enclosing spheres are tested, so a subtree whose sphere does not enclose ``x``
    is never entered. ``stack``: scratch, one slot per sphere (each is pushed at most once)."""
    rc = x.shape[0]
    best = 0
    visited = 0
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        c = nodes_i[stack[top], FIRST]
        while c >= 0:
            visited += 1
            if _distance(nodes_f, c, x, euclidean) <= nodes_f[c, rc] + eps:
                if _better(nodes_f, nodes_i, c, best, rc):
                    best = c
                if nodes_i[c, FIRST] >= 0:
                    stack[top] = c
                    top += 1
            c = nodes_i[c, NEXT]
    return best, visited


@_jit
def _brute(nodes_f, nodes_i, n, x, eps, euclidean, reached):
    """The winner for ``x`` testing every sphere, in creation order: a sphere is reachable iff
    it encloses ``x`` and its parent is reachable (parents precede children). ``reached``:
    scratch, one slot per sphere."""
    rc = x.shape[0]
    best = 0
    reached[0] = True
    for i in range(1, n):
        inside = _distance(nodes_f, i, x, euclidean) <= nodes_f[i, rc] + eps
        reached[i] = inside and reached[nodes_i[i, PARENT]]
        if reached[i] and _better(nodes_f, nodes_i, i, best, rc):
            best = i
    return best


@_jit
def winner(nodes_f, nodes_i, n, x, eps, euclidean):
    """The winning sphere of one query among the first ``n`` spheres (the descent)."""
    return _descend(nodes_f, nodes_i, x, eps, euclidean, np.empty(n, dtype=np.int64))[0]


@_jit
def winners(nodes_f, nodes_i, n, X, eps, euclidean, brute, out, visited):
    """The winning sphere of each row of ``X`` into ``out``, and the number of spheres whose
    distance each search computed into ``visited`` (``brute``: every sphere, else descend)."""
    stack = np.empty(n, dtype=np.int64)
    reached = np.empty(n, dtype=np.bool_)
    for q in range(X.shape[0]):
        if brute:
            out[q] = _brute(nodes_f, nodes_i, n, X[q], eps, euclidean, reached)
            visited[q] = n - 1
        else:
            out[q], visited[q] = _descend(nodes_f, nodes_i, X[q], eps, euclidean, stack)


@_jit
def _candidates(nodes_f, nodes_i, x, eps, euclidean, stack, dstack, cand, cand_d):
    """The candidates for ``x`` (reachable spheres none of whose children is reachable) into
    ``cand``, their distances to ``x`` into ``cand_d``, in the order of the paper's depth-first
    traversal (children in creation order); returns how many. ``stack``, ``dstack``: scratch;
    every array has a slot per sphere."""
    rc = x.shape[0]
    stack[0] = 0
    dstack[0] = _distance(nodes_f, 0, x, euclidean)
    top = 1
    count = 0
    while top > 0:
        top -= 1
        p = stack[top]
        dp = dstack[top]
        first = top
        c = nodes_i[p, FIRST]
        while c >= 0:
            d = _distance(nodes_f, c, x, euclidean)
            if d <= nodes_f[c, rc] + eps:
                stack[top] = c
                dstack[top] = d
                top += 1
            c = nodes_i[c, NEXT]
        if top == first:
            cand[count] = p
            cand_d[count] = dp
            count += 1
        else:  # the first child on top: visited first
            i, j = first, top - 1
            while i < j:
                stack[i], stack[j] = stack[j], stack[i]
                dstack[i], dstack[j] = dstack[j], dstack[i]
                i += 1
                j -= 1
    return count


@_jit
def learn(nodes_f, nodes_i, centers_t, X, labels, start, n, height, eps, euclidean, winner_only,
          min_radius, max_nodes, max_depth, totals):
    """Train on the rows ``start ..`` of ``X`` with label indices ``labels``, in order, as
    :meth:`rhbl.tree.SphereTree.learn` does one vector (``winner_only``: ``spawn="winner"``).

    Stops before a row whose spawns might not fit in the tables' capacity. ``totals`` (int64,
    6): the rows trained on, the number of spheres and the height are set, the spheres spawned
    and relabelled and the rows with a suppressed spawn are added; returns the rows trained on.
    ``centers_t`` (features, capacity) is kept up to date too (the numpy reference's copy).
    """
    capacity = nodes_f.shape[0]
    rc = X.shape[1]
    stack = np.empty(capacity, dtype=np.int64)
    dstack = np.empty(capacity)
    cand = np.empty(capacity, dtype=np.int64)
    cand_d = np.empty(capacity)
    row = start
    while row < X.shape[0]:
        x = X[row]
        a = labels[row]
        count = _candidates(nodes_f, nodes_i, x, eps, euclidean, stack, dstack, cand, cand_d)
        if winner_only:
            w = 0
            for j in range(1, count):
                if _better(nodes_f, nodes_i, cand[j], cand[w], rc):
                    w = j
            cand[0], cand_d[0] = cand[w], cand_d[w]
            count = 1
        if n + count > capacity:
            break
        suppressed = False
        for j in range(count):
            p = cand[j]
            if nodes_i[p, LABEL] == a:
                continue
            d = cand_d[j]
            if d <= eps:  # coincides with the centre: relabel in place
                nodes_i[p, LABEL] = a
                totals[RELABELLED] += 1
                continue
            r = nodes_f[p, rc] - d
            if r < 0.0:
                r = 0.0
            depth = nodes_i[p, DEPTH] + 1
            if (min_radius > 0.0 and r < min_radius) or n >= max_nodes or depth > max_depth:
                suppressed = True
                continue
            for k in range(rc):
                nodes_f[n, k] = x[k]
                centers_t[k, n] = x[k]
            nodes_f[n, rc] = r
            nodes_i[n, :] = -1
            nodes_i[n, PARENT] = p
            nodes_i[n, DEPTH] = depth
            nodes_i[n, LABEL] = a
            if nodes_i[p, FIRST] < 0:
                nodes_i[p, FIRST] = n
            else:
                nodes_i[nodes_i[p, LAST], NEXT] = n
            nodes_i[p, LAST] = n
            if depth > height:
                height = depth
            n += 1
            totals[SPAWNED] += 1
        if suppressed:
            totals[SKIPPED] += 1
        row += 1
    totals[ROWS] = row - start
    totals[NODES] = n
    totals[HEIGHT] = height
    return row - start


_KERNELS = (_distance, _better, _descend, _brute, winner, winners, _candidates, learn)


def _warm_up() -> None:
    """Every entry kernel once, with the argument types :class:`rhbl.tree.SphereTree` passes."""
    nodes_f = np.array([[0.5, 0.25]])
    nodes_i = np.array([[-1, 0, 0, -1, -1, -1]], dtype=np.int64)
    x = np.full(1, 0.5)
    winner(nodes_f, nodes_i, 1, x, 1e-9, False)
    out = np.empty(1, dtype=np.int64)
    winners(nodes_f, nodes_i, 1, x[None, :], 1e-9, False, False, out, out.copy())
    totals = np.zeros(6, dtype=np.int64)
    learn(nodes_f, nodes_i, np.empty((1, 1)), x[None, :], np.zeros(1, dtype=np.int64), 0, 1, 0,
          1e-9, False, False, 0.0, 1, 1, totals)


def load() -> None:
    """Compile the kernels or load them from numba's cache (call once per process)."""
    try:
        _warm_up()
    except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
        log.warning("cannot cache the tree's compiled code (%s): compiled in this process", e)
        for kernel in _KERNELS:
            kernel._cache.disable()
        _warm_up()
