"""The sphere tree's compiled kernels (numba): the winner searches and the training scan.

The kernels work on the node table of :class:`rhbl.tree.SphereTree`: one row per sphere, in
creation order (the capacity's rows allocated), of 8-byte cells (int64; the float columns are
read through a float64 view of the same memory):

* columns ``0 .. features - 1``: the centre (float), column ``features``: the radius (float);
* then the integer columns below, from ``features + 1`` on: parent (-1 for the root), depth,
  label index and the children as a linked list in creation order (first child, next sibling,
  last child; -1 for none).

One table keeps a call cheap (numba unboxes each array argument, a few hundred nanoseconds
each) and each sphere's data together in memory. A per-sphere value added later is one more
column (``INT_COLUMNS`` grows); a kernel reads only the columns it names.

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

__all__ = ["INT_COLUMNS", "learn", "load", "winner", "winners"]

# the integer columns, counted from ``features + 1``
PARENT, DEPTH, LABEL, FIRST, NEXT, LAST = range(6)
INT_COLUMNS = 6


def _jit(func):
    """Compile ``func`` on its first call, cached on disk; without a writable cache folder
    (numba: "no locator available") it is compiled in each process."""
    try:
        return njit(cache=True, nogil=True, error_model="numpy")(func)
    except RuntimeError:
        return njit(nogil=True, error_model="numpy")(func)


@_jit
def _distance(tf, i, x, euclidean):
    """``sum((c_i - x)**2)`` in feature order (its square root for ``euclidean``); ``tf``: the
    table's float view."""
    d = 0.0
    for k in range(x.shape[0]):
        t = tf[i, k] - x[k]
        d += t * t
    return math.sqrt(d) if euclidean else d


@_jit
def _better(tf, table, a, b, rc):
    """True if sphere ``a`` wins over sphere ``b``: smaller radius, then deeper, then earlier
    (``rc``: the radius column, the number of features)."""
    ra, rb = tf[a, rc], tf[b, rc]
    if ra != rb:
        return ra < rb
    da, db = table[a, rc + 1 + DEPTH], table[b, rc + 1 + DEPTH]
    if da != db:
        return da > db
    return a < b


@_jit
def _descend(table, x, eps, euclidean, stack):
    """The winner for ``x`` and the number of spheres whose distance was computed: only the
    children of enclosing spheres are tested, so a subtree whose sphere does not enclose ``x``
    is never entered. ``stack``: scratch, one slot per sphere (each is pushed at most once)."""
    tf = table.view(np.float64)
    rc = x.shape[0]
    first, after = rc + 1 + FIRST, rc + 1 + NEXT
    best = 0
    visited = 0
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        c = table[stack[top], first]
        while c >= 0:
            visited += 1
            if _distance(tf, c, x, euclidean) <= tf[c, rc] + eps:
                if _better(tf, table, c, best, rc):
                    best = c
                if table[c, first] >= 0:
                    stack[top] = c
                    top += 1
            c = table[c, after]
    return best, visited


@_jit
def _brute(table, n, x, eps, euclidean, reached):
    """The winner for ``x`` testing every sphere, in creation order: a sphere is reachable iff
    it encloses ``x`` and its parent is reachable (parents precede children). ``reached``:
    scratch, one slot per sphere."""
    tf = table.view(np.float64)
    rc = x.shape[0]
    best = 0
    reached[0] = True
    for i in range(1, n):
        inside = _distance(tf, i, x, euclidean) <= tf[i, rc] + eps
        reached[i] = inside and reached[table[i, rc + 1 + PARENT]]
        if reached[i] and _better(tf, table, i, best, rc):
            best = i
    return best


@_jit
def winner(table, n, x, eps, euclidean):
    """The winning sphere of one query among the first ``n`` spheres (the descent); -1 if a
    coordinate of ``x`` is outside [0, 1] or NaN (the caller checks its input only then)."""
    for k in range(x.shape[0]):
        if not (x[k] >= 0.0 and x[k] <= 1.0):
            return -1
    return _descend(table, x, eps, euclidean, np.empty(n, dtype=np.int64))[0]


@_jit
def winners(table, n, X, eps, euclidean, brute, out, visited):
    """The winning sphere of each row of ``X`` into ``out``, and the number of spheres whose
    distance each search computed into ``visited`` (``brute``: every sphere, else descend)."""
    stack = np.empty(n, dtype=np.int64)
    reached = np.empty(n, dtype=np.bool_)
    for q in range(X.shape[0]):
        if brute:
            out[q] = _brute(table, n, X[q], eps, euclidean, reached)
            visited[q] = n - 1
        else:
            out[q], visited[q] = _descend(table, X[q], eps, euclidean, stack)


@_jit
def _candidates(table, x, eps, euclidean, stack, dstack, cand, cand_d):
    """The candidates for ``x`` (reachable spheres none of whose children is reachable) into
    ``cand``, their distances to ``x`` into ``cand_d``, in the order of the paper's depth-first
    traversal (children in creation order); returns how many. ``stack``, ``dstack``: scratch;
    every array has a slot per sphere."""
    tf = table.view(np.float64)
    rc = x.shape[0]
    first, after = rc + 1 + FIRST, rc + 1 + NEXT
    stack[0] = 0
    dstack[0] = _distance(tf, 0, x, euclidean)
    top = 1
    count = 0
    while top > 0:
        top -= 1
        p = stack[top]
        dp = dstack[top]
        bottom = top
        c = table[p, first]
        while c >= 0:
            d = _distance(tf, c, x, euclidean)
            if d <= tf[c, rc] + eps:
                stack[top] = c
                dstack[top] = d
                top += 1
            c = table[c, after]
        if top == bottom:
            cand[count] = p
            cand_d[count] = dp
            count += 1
        else:  # the first child on top: visited first
            i, j = bottom, top - 1
            while i < j:
                stack[i], stack[j] = stack[j], stack[i]
                dstack[i], dstack[j] = dstack[j], dstack[i]
                i += 1
                j -= 1
    return count


@_jit
def learn(table, X, labels, start, n, height, eps, euclidean, winner_only, min_radius,
          max_nodes, max_depth):
    """Train on the rows ``start ..`` of ``X`` with label indices ``labels``, in order, as
    :meth:`rhbl.tree.SphereTree.learn` does one vector (``winner_only``: ``spawn="winner"``),
    on a tree of ``n`` spheres and height ``height``.

    Stops before a row whose spawns might not fit in the table's capacity. Returns the rows
    trained on, the number of spheres and the height after them, the spheres spawned and
    relabelled and the rows with a suppressed spawn.
    """
    tf = table.view(np.float64)
    capacity = table.shape[0]
    rc = X.shape[1]
    c_parent, c_depth, c_label = rc + 1 + PARENT, rc + 1 + DEPTH, rc + 1 + LABEL
    c_first, c_next, c_last = rc + 1 + FIRST, rc + 1 + NEXT, rc + 1 + LAST
    stack = np.empty(capacity, dtype=np.int64)
    dstack = np.empty(capacity)
    cand = np.empty(capacity, dtype=np.int64)
    cand_d = np.empty(capacity)
    spawned = relabelled = skipped = 0
    row = start
    while row < X.shape[0]:
        x = X[row]
        a = labels[row]
        count = _candidates(table, x, eps, euclidean, stack, dstack, cand, cand_d)
        if winner_only:
            w = 0
            for j in range(1, count):
                if _better(tf, table, cand[j], cand[w], rc):
                    w = j
            cand[0], cand_d[0] = cand[w], cand_d[w]
            count = 1
        if n + count > capacity:
            break
        suppressed = False
        for j in range(count):
            p = cand[j]
            if table[p, c_label] == a:
                continue
            d = cand_d[j]
            if d <= eps:  # coincides with the centre: relabel in place
                table[p, c_label] = a
                relabelled += 1
                continue
            r = tf[p, rc] - d
            if r < 0.0:
                r = 0.0
            depth = table[p, c_depth] + 1
            if (min_radius > 0.0 and r < min_radius) or n >= max_nodes or depth > max_depth:
                suppressed = True
                continue
            for k in range(rc):
                tf[n, k] = x[k]
            tf[n, rc] = r
            table[n, rc + 1:] = -1
            table[n, c_parent] = p
            table[n, c_depth] = depth
            table[n, c_label] = a
            if table[p, c_first] < 0:
                table[p, c_first] = n
            else:
                table[table[p, c_last], c_next] = n
            table[p, c_last] = n
            if depth > height:
                height = depth
            n += 1
            spawned += 1
        skipped += suppressed
        row += 1
    return row - start, n, height, spawned, relabelled, skipped


_KERNELS = (_distance, _better, _descend, _brute, winner, winners, _candidates, learn)


def _warm_up() -> None:
    """Every entry kernel once, with the argument types :class:`rhbl.tree.SphereTree` passes."""
    table = np.array([[0, 0, -1, 0, 0, -1, -1, -1]], dtype=np.int64)
    table.view(np.float64)[0, :2] = (0.5, 0.25)
    x = np.full(1, 0.5)
    winner(table, 1, x, 1e-9, False)
    out = np.empty(1, dtype=np.int64)
    winners(table, 1, x[None, :], 1e-9, False, False, out, out.copy())
    learn(table, x[None, :], np.zeros(1, dtype=np.int64), 0, 1, 0, 1e-9, False, False, 0.0, 1, 1)


def load() -> None:
    """Compile the kernels or load them from numba's cache (call once per process)."""
    try:
        _warm_up()
    except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
        log.warning("cannot cache the tree's compiled code (%s): compiled in this process", e)
        for kernel in _KERNELS:
            kernel._cache.disable()
        _warm_up()
