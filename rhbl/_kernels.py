"""The sphere tree's compiled kernels (numba): the winner searches and the training scan.

The kernels work on the tables of :mod:`rhbl._layout`: the node table of
:class:`rhbl.tree.SphereTree` (creation order: training and the searches of a tree that has
just changed) and the search table built from it (:func:`layout`: depth-first pre-order, with
each sphere's rank in the winner order, the end of its subtree and the lowest rank in it, which
the searches of a tree that stays the same use: :func:`search_kernels`).

The arithmetic is that of the numpy code in :mod:`rhbl._reference` (the tests compare them
array by array): the distance is ``sum((c - x)**2)`` accumulated in feature order (its square
root for ``euclidean``), a sphere encloses ``x`` iff ``d <= r + eps``, the winner is the
reachable sphere of smallest radius, then deepest, then earliest created. The root encloses
every vector of the unit cube, so the searches start from its children.

Each kernel is compiled ahead of time when rhbl is installed (``setup.py``: an extension module,
``rhbl._kernels_aot``, that needs no numba, from the functions :func:`aot_exports` names), or
else on its first call, or loaded from numba's cache (next to this file, else in the user's
cache folder or ``NUMBA_CACHE_DIR``); :func:`load` does that once per process.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

from ._layout import (
    BOUND,
    DEPTH,
    FIRST,
    INT_COLUMNS,
    LABEL,
    LAST,
    NEXT,
    PARENT,
    RANK,
    SEARCH_INT_COLUMNS,
    SKIP,
    SPECIALISED,
)

log = logging.getLogger(__name__)

__all__ = ["aot_exports", "layout", "learn", "load", "nearest", "search_kernels", "winner",
           "winners"]


def _jit(func):
    """Compile ``func`` on its first call, cached on disk; without a writable cache folder
    (numba: "no locator available") it is compiled in each process. The ahead-of-time build
    compiles with the same options (no GIL, numpy's error model)."""
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
def _nearest(tf, n, x):
    """The sphere (the root left out) whose centre is nearest to ``x`` among the first ``n``,
    the first of equals (``uncovered="nearest"``); the root when it is alone."""
    best, node = np.inf, 0
    for i in range(1, n):
        d = _distance(tf, i, x, False)
        if d < best:
            best, node = d, i
    return node


@_jit
def _nearest_label(tf, table, n, x, c_label):
    """The label of the sphere (the root left out) whose centre is nearest to ``x``."""
    node = _nearest(tf, n, x)
    return table[node, c_label] if node > 0 else -1


@_jit
def nearest(table, n, x):
    """The sphere (the root left out) whose centre is nearest to one query among the first
    ``n`` spheres, the first of equals (the root when it is alone): one uncovered query of a
    tree with ``uncovered="nearest"``, as the training rule finds it."""
    return _nearest(table.view(np.float64), n, x)


@_jit
def learn(table, X, labels, start, n, height, eps, euclidean, winner_only, min_radius,
          max_nodes, max_depth, caps, nearest):
    """Train on the rows ``start ..`` of ``X`` with label indices ``labels``, in order, as
    :meth:`rhbl.tree.SphereTree.learn` does one vector (``winner_only``: ``spawn="winner"``),
    on a tree of ``n`` spheres and height ``height``; a sphere spawned at row ``i`` has a radius
    of at most ``caps[i]`` (``inf``: as large as its parent allows). ``nearest``
    (``uncovered="nearest"``): a row that only the root encloses is answered by the sphere with
    the nearest centre, and spawns a child of the root when that answer is not its label.

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
        # the answer for a row only the root encloses: the nearest centre's label (nearest)
        root_answer = (_nearest_label(tf, table, n, x, c_label)
                       if nearest and n > 1 and count == 1 and cand[0] == 0 else -1)
        suppressed = False
        for j in range(count):
            p = cand[j]
            if (root_answer if root_answer >= 0 else table[p, c_label]) == a:
                continue
            d = cand_d[j]
            if d <= eps:  # coincides with the centre: relabel in place
                table[p, c_label] = a
                relabelled += 1
                continue
            r = tf[p, rc] - d
            if r > caps[row]:
                r = caps[row]
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


@_jit
def layout(table, n, rank, search, nodes):
    """Fill the search table ``search`` (flat, ``n`` rows of the centre, the radius, ``SKIP``,
    ``RANK`` and ``BOUND``) and ``nodes`` (each position's creation index) from the first ``n`` spheres
    of the node table, in depth-first pre-order (children in creation order); ``rank``: each
    sphere's place in the winner order (by creation index)."""
    tf = table.view(np.float64)
    sf = search.view(np.float64)
    f = table.shape[1] - 1 - INT_COLUMNS
    w = f + 1 + SEARCH_INT_COLUMNS
    c_parent, c_first, c_next = f + 1 + PARENT, f + 1 + FIRST, f + 1 + NEXT
    size = np.ones(n, dtype=np.int64)  # of each subtree
    bound = rank[:n].copy()  # the lowest rank in each subtree
    for i in range(n - 1, 0, -1):  # parents precede their children
        p = table[i, c_parent]
        size[p] += size[i]
        if bound[i] < bound[p]:
            bound[p] = bound[i]
    stack = np.empty(n, dtype=np.int64)
    stack[0] = 0
    top = 1
    pos = 0
    while top > 0:
        top -= 1
        i = stack[top]
        b = pos * w
        for k in range(f + 1):  # the centre and the radius
            sf[b + k] = tf[i, k]
        search[b + f + 1 + SKIP] = pos + size[i]
        search[b + f + 1 + RANK] = rank[i]
        search[b + f + 1 + BOUND] = bound[i]
        nodes[pos] = i
        pos += 1
        bottom = top
        c = table[i, c_first]
        while c >= 0:
            stack[top] = c
            top += 1
            c = table[c, c_next]
        j = top - 1  # the first child on top: visited first
        while bottom < j:
            stack[bottom], stack[j] = stack[j], stack[bottom]
            bottom += 1
            j -= 1


@_jit
def _query_order(X):
    """The rows of ``X`` in Z order (Morton: the bits of the coordinates interleaved, 3 per
    coordinate, at most 24 bits in all), so that consecutive queries take similar paths down
    the tree (the branches and the cache see the same spheres again); sorted by an LSD radix
    sort, 8 bits a pass (linear time: a finer order gains no more than it costs to sort). Only
    the order changes, never an answer."""
    m, f = X.shape
    bits = min(3, 24 // f)
    if bits == 0:
        return np.arange(m)
    top = (1 << bits) - 1
    cells = np.empty(f, dtype=np.int64)
    keys = np.empty(m, dtype=np.int64)
    for q in range(m):
        for k in range(f):
            cells[k] = min(int(X[q, k] * (top + 1)), top)
        key = 0
        for b in range(bits - 1, -1, -1):
            for k in range(f):
                key = (key << 1) | ((cells[k] >> b) & 1)
        keys[q] = key
    order = np.arange(m)
    spare = np.empty(m, dtype=np.int64)
    count = np.empty(257, dtype=np.int64)
    for shift in range(0, bits * f, 8):
        count[:] = 0
        for q in range(m):
            count[((keys[order[q]] >> shift) & 255) + 1] += 1
        for v in range(1, 257):
            count[v] += count[v - 1]
        for q in range(m):
            v = (keys[order[q]] >> shift) & 255
            spare[count[v]] = order[q]
            count[v] += 1
        order, spare = spare, order
    return order


# batches of at least this many rows are searched in Z order
ORDERED_BATCH = 64


@_jit
def _descend_flat(search, x, f, eps, euclidean):
    """(the winner's position, the number of spheres whose distance was computed) for ``x``
    of ``f`` features: in pre-order, a sphere that encloses ``x`` is followed by its first
    child, any other by the position after its subtree (which is thereby skipped); so is a
    sphere whose subtree holds no rank below the best found so far, untested (nothing in it
    can win). Indices are unsigned (no check for negative indices in the loop)."""
    sf = search.view(np.float64)
    w = np.uint64(f + 1 + SEARCH_INT_COLUMNS)
    n = np.uint64(search.shape[0]) // w
    c_r = np.uint64(f)
    c_skip = np.uint64(f + 1 + SKIP)
    c_rank = np.uint64(f + 1 + RANK)
    c_bound = np.uint64(f + 1 + BOUND)
    one = np.uint64(1)
    best = np.uint64(0)
    best_rank = search[c_rank]
    visited = 0
    i = one
    while i < n:
        b = i * w
        if search[b + c_bound] >= best_rank:
            i = np.uint64(search[b + c_skip])
            continue
        d = 0.0
        for k in range(f):
            t = sf[b + np.uint64(k)] - x[k]
            d += t * t
        if euclidean:
            d = math.sqrt(d)
        visited += 1
        if d <= sf[b + c_r] + eps:
            r = search[b + c_rank]
            if r < best_rank:
                best_rank = r
                best = i
            i += one
        else:
            i = np.uint64(search[b + c_skip])
    return best, visited


@_jit
def _search_one(search, nodes, x, f, eps, euclidean):
    """The winning sphere (creation index) of one query; -1 if a coordinate of ``x`` is
    outside [0, 1] or NaN (the caller checks its input only then)."""
    for k in range(x.shape[0]):
        if not (x[k] >= 0.0 and x[k] <= 1.0):
            return -1
    return nodes[_descend_flat(search, x, f, eps, euclidean)[0]]


@_jit
def _search_many(search, nodes, X, f, eps, euclidean, out, visited):
    """The winning sphere of each row of ``X`` into ``out``, the spheres whose distance each
    search computed into ``visited``; a batch of ``ORDERED_BATCH`` rows or more is searched in
    Z order."""
    m = X.shape[0]
    order = _query_order(X) if m >= ORDERED_BATCH else np.arange(m)
    for j in range(m):
        q = order[j]
        best, visited[q] = _descend_flat(search, X[q], f, eps, euclidean)
        out[q] = nodes[best]


@_jit
def search_one(search, nodes, x, eps, euclidean):
    """:func:`_search_one` for any number of features (read from ``x``)."""
    return _search_one(search, nodes, x, x.shape[0], eps, euclidean)


@_jit
def search_many(search, nodes, X, eps, euclidean, out, visited):
    """:func:`_search_many` for any number of features (read from ``X``)."""
    _search_many(search, nodes, X, X.shape[1], eps, euclidean, out, visited)


def _specialised(features):
    """``(search_one, search_many)`` for vectors of exactly ``features`` features: the loop
    over the features has a fixed length, which the compiler unrolls (about a quarter faster).
    Compiled ahead of time only (numba's cache does not keep closures: the kernels numba
    compiles at run time are the general ones)."""

    def one(search, nodes, x, eps, euclidean):
        return _search_one(search, nodes, x, features, eps, euclidean)

    def many(search, nodes, X, eps, euclidean, out, visited):
        _search_many(search, nodes, X, features, eps, euclidean, out, visited)

    return njit(nogil=True, error_model="numpy")(one), njit(nogil=True, error_model="numpy")(many)


def search_kernels(features: int):
    """``(search_one, search_many)`` for vectors of ``features`` features: numba's, the
    general ones (the kernels compiled ahead of time have one of their own for each count in
    ``SPECIALISED``)."""
    return search_one, search_many


# the signatures the kernels are compiled with ahead of time (and called with)
_TABLE, _FLAT, _VECTOR, _ROWS = "int64[:, ::1]", "int64[::1]", "float64[::1]", "float64[:, ::1]"


def aot_exports() -> dict:
    """name -> (function, signature) of every kernel ``setup.py`` compiles ahead of time; the
    searches of each feature count in ``SPECIALISED`` are ``search_one_<count>`` and
    ``search_many_<count>``, the general ones ``search_one`` and ``search_many``."""
    exports = {
        "winner": (winner, f"int64({_TABLE}, int64, {_VECTOR}, float64, boolean)"),
        "nearest": (nearest, f"int64({_TABLE}, int64, {_VECTOR})"),
        "winners": (winners, f"void({_TABLE}, int64, {_ROWS}, float64, boolean, boolean, "
                             f"{_FLAT}, {_FLAT})"),
        "learn": (learn, f"UniTuple(int64, 6)({_TABLE}, {_ROWS}, {_FLAT}, int64, int64, int64, "
                         "float64, boolean, boolean, float64, int64, int64, "
                         f"{_VECTOR}, boolean)"),
        "layout": (layout, f"void({_TABLE}, int64, {_FLAT}, {_FLAT}, {_FLAT})"),
    }
    for features in (0, *SPECIALISED):
        one, many = _specialised(features) if features else (search_one, search_many)
        suffix = f"_{features}" if features else ""
        exports["search_one" + suffix] = (one, f"int64({_FLAT}, {_FLAT}, {_VECTOR}, float64, "
                                               "boolean)")
        exports["search_many" + suffix] = (many, f"void({_FLAT}, {_FLAT}, {_ROWS}, float64, "
                                                 f"boolean, {_FLAT}, {_FLAT})")
    return exports


def _warm_up() -> None:
    """Every entry kernel once, with the argument types :class:`rhbl.tree.SphereTree` passes
    (the searches: the general ones, which numba compiles at run time)."""
    table = np.array([[0, 0, -1, 0, 0, -1, -1, -1]], dtype=np.int64)
    table.view(np.float64)[0, :2] = (0.5, 0.25)
    x = np.full(1, 0.5)
    winner(table, 1, x, 1e-9, False)
    nearest(table, 1, x)
    out = np.empty(1, dtype=np.int64)
    winners(table, 1, x[None, :], 1e-9, False, False, out, out.copy())
    learn(table, x[None, :], np.zeros(1, dtype=np.int64), 0, 1, 0, 1e-9, False, False, 0.0, 1, 1,
          np.full(1, np.inf), False)
    search = np.empty(1 + 1 + SEARCH_INT_COLUMNS, dtype=np.int64)
    nodes = np.empty(1, dtype=np.int64)
    layout(table, 1, np.zeros(1, dtype=np.int64), search, nodes)
    one, many = search_kernels(1)
    one(search, nodes, x, 1e-9, False)
    many(search, nodes, x[None, :], 1e-9, False, out, out.copy())


def load() -> None:
    """Compile the kernels or load them from numba's cache (call once per process)."""
    try:
        _warm_up()
    except OSError as e:  # the cache folder took the index, not the code (disk full, ...)
        log.warning("cannot cache the tree's compiled code (%s): compiled in this process", e)
        for kernel in (_distance, _better, _descend, _brute, winner, winners, _candidates,
                       _nearest, _nearest_label, nearest, learn, layout, _query_order,
                       _descend_flat, _search_one, _search_many, search_one, search_many):
            kernel._cache.disable()
        _warm_up()
