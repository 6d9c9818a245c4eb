"""The sphere tree of RHBL, apart from the estimator: its arrays, spawning and winner searches.

:class:`SphereTree` holds the spheres in creation order (centres, radii, parents, depths, label
indices, children), grows them one training vector at a time (:meth:`SphereTree.learn`,
:meth:`SphereTree.learn_many`) and finds the winning sphere of query vectors
(:meth:`SphereTree.apply_one`, :meth:`SphereTree.apply`). It knows labels only as indices;
parameters, input checks and label values belong to :class:`rhbl.HypersphereClassifier`, which
keeps its tree in ``tree_`` (as scikit-learn keeps ``Tree`` apart from
``DecisionTreeClassifier``).

Searches and training run compiled kernels (:mod:`rhbl._kernels`: compiled ahead of time when
rhbl was installed, else by numba when first used) by default; with ``compiled=False`` they run
the numpy code of :mod:`rhbl._reference` instead, the code before the kernels, which gives
exactly the same trees and answers (the tests compare them).

Inputs are checked vectors in ``[0, 1]^n``: this module does no input validation of its own
except in :meth:`SphereTree.from_arrays`, which rebuilds a tree from untrusted arrays.
"""

from __future__ import annotations

import functools
import importlib
import logging
import math
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np

from . import _layout, _reference

__all__ = ["ALGORITHMS", "DISTANCES", "Growth", "SphereTree", "Totals", "UNCOVERED",
           "load_kernels", "margins", "threads"]

log = logging.getLogger(__name__)

DISTANCES = ("squared", "euclidean")
# what answers a vector that no sphere but the root encloses: the root, or the sphere whose
# centre is nearest (the radii bounded by the margin: HypersphereClassifier(radius="margin"))
UNCOVERED = ("root", "nearest")
ALGORITHMS = ("auto", "brute", "descent")
# no limit, for the kernels (which take integers)
_UNLIMITED = 1 << 62
# "auto" builds the search table (and then uses it) for a batch of at least this many rows,
# or after this many single queries of a tree that has not changed since; until then it walks
# the node table (a tree that changes between queries, as in a corrective round, never pays
# for a table it would use once)
_TABLE_AFTER = 32
# uncovered="nearest": a second centre this near the first (relatively) in a k-d tree query is
# a tie to be settled by searching every centre (SphereTree._nearest)
_NEAR_TIE = 1e-9
_F64 = np.dtype(np.float64)
# set to "jit" to use numba's kernels even where kernels compiled ahead of time are installed
# (the tests and benchmarks compare the two)
KERNELS_ENV = "RHBL_KERNELS"
# a batch of at least this many rows searched on the search table is cut into slices of at
# least PARALLEL_SLICE rows, searched by ``RHBL_THREADS`` threads (default: the cores this
# process may run on; 1: never; the kernels run without the GIL)
PARALLEL_BATCH = 1024
PARALLEL_SLICE = 256
THREADS_ENV = "RHBL_THREADS"


class _Kernels:
    """The kernels of this process: ``origin`` is ``"ahead-of-time"`` (the extension module
    ``rhbl._kernels_aot`` that setup.py compiles, no numba at run time) or ``"numba"`` (the
    functions of :mod:`rhbl._kernels`, compiled on first use or loaded from numba's cache)."""

    def __init__(self, module: Any, origin: str) -> None:
        self.origin = origin
        self._module = module
        self.winner, self.winners, self.learn = module.winner, module.winners, module.learn
        self.layout, self.nearest = module.layout, module.nearest

    @functools.cache  # noqa: B019 (one instance per process)
    def search(self, features: int) -> tuple[Any, Any]:
        """``(search_one, search_many)`` for vectors of ``features`` features."""
        if self.origin == "numba":
            return self._module.search_kernels(features)
        suffix = f"_{features}" if features in _layout.SPECIALISED else ""
        return getattr(self._module, "search_one" + suffix), getattr(
            self._module, "search_many" + suffix)


def _ahead_of_time() -> Any:
    """The kernels compiled ahead of time, or None: not built (no compiler when rhbl was
    installed), built from other source than this checkout's (a change since ``make install``:
    logged) or not wanted (``RHBL_KERNELS=jit``)."""
    if os.environ.get(KERNELS_ENV, "") == "jit":
        return None
    try:
        aot = importlib.import_module("._kernels_aot", __package__)
    except ImportError:
        return None
    if aot.source_hash() != _layout.source_hash():
        log.info("the tree's kernels compiled ahead of time are older than rhbl/_kernels.py: "
                 "using numba's (make install compiles them again)")
        return None
    return aot


@functools.cache
def _kernels() -> _Kernels:
    """The compiled kernels, on the first call in a process (the first classifier or tree
    made): the extension module compiled ahead of time (about a millisecond), else numba's
    (numba imported, the kernels compiled or loaded from its cache: about a second). Importing
    rhbl loads neither."""
    aot = _ahead_of_time()
    if aot is not None:
        return _Kernels(aot, "ahead-of-time")
    kernels = importlib.import_module("._kernels", __package__)
    kernels.load()
    return _Kernels(kernels, "numba")


def load_kernels() -> str:
    """Load the compiled kernels now: once per process (the ahead-of-time extension in about a
    millisecond; numba's in about a second, most of it numba's own set-up); later calls return
    at once. Building a tree does it anyway; a process calls it to pay it before it serves.
    Returns where they come from: ``"ahead-of-time"`` or ``"numba"``."""
    return _kernels().origin


@functools.cache
def threads() -> int:
    """How many threads search a large batch: ``RHBL_THREADS``, else (unset, or not an integer
    >= 1: logged) the cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)
    cores = len(affinity(0)) if affinity else (os.cpu_count() or 1)
    value = os.environ.get(THREADS_ENV, "")
    if not value:
        return cores
    try:
        count = int(value)
    except ValueError:
        count = 0
    if count < 1:
        log.warning("%s must be an integer >= 1, got %r: using %d (the cores this process may "
                    "run on)", THREADS_ENV, value, cores)
        return cores
    return count


@functools.cache
def _pool() -> ThreadPoolExecutor:
    """The threads that search the slices of a large batch (made on first use)."""
    return ThreadPoolExecutor(max(threads(), 2), thread_name_prefix="rhbl-search")


if hasattr(os, "register_at_fork"):  # a forked child has none of its parent's threads
    os.register_at_fork(after_in_child=_pool.cache_clear)


class _Search(NamedTuple):
    """The search table of a tree that has not changed since it was built (see
    :mod:`rhbl._layout`), with the kernels for its number of features."""

    table: np.ndarray  # flat int64, a row per sphere in pre-order
    nodes: np.ndarray  # each row's creation index
    one: Any  # search_one kernel
    many: Any  # search_many kernel
    labels: list  # each sphere's label index, by creation index (a list: the fastest lookup)


class Growth(NamedTuple):
    """What one training vector changed (:meth:`SphereTree.learn`)."""

    spawned: int  # spheres added
    relabelled: int  # spheres relabelled in place (the vector sat on their centre)
    suppressed: bool  # a growth limit suppressed at least one spawn


class Totals(NamedTuple):
    """What several training vectors changed (:meth:`SphereTree.learn_many`)."""

    spawned: int  # spheres added
    relabelled: int  # spheres relabelled in place
    skipped: int  # vectors of which a growth limit suppressed at least one spawn


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
    uncovered:
        ``"root"`` (the paper): a vector that no sphere but the root encloses is the root's;
        ``"nearest"``: it is the sphere's with the nearest centre (the root left out), as a
        nearest-prototype rule answers outside every prototype's reach, in training too (a
        wrong answer there spawns a child of the root).

    ``distance``, ``eps`` and ``uncovered`` are fixed for the life of the tree. The arrays
    ``centers``, ``radii``, ``parent``, ``depth`` and ``label`` are read-only views of the first
    ``node_count`` spheres; ``children[i]`` lists the children of sphere ``i`` in creation order.

    The spheres live in one table, a row per sphere (see :mod:`rhbl._kernels`): centre,
    radius, parent, depth, label and the children as linked lists. Every
    search and training method takes ``compiled`` (default ``True``): ``False`` runs the numpy
    reference instead (same results, slower; the tests and benchmarks compare the two).
    """

    def __init__(self, n_features: int, root_label: int, *, distance: str, eps: float,
                 uncovered: str = "root") -> None:
        if distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {distance!r}")
        if uncovered not in UNCOVERED:
            raise ValueError(f"uncovered must be one of {UNCOVERED}, got {uncovered!r}")
        self.uncovered = uncovered
        self._nearest_on = uncovered == "nearest"
        if not (isinstance(n_features, int | np.integer) and n_features >= 1):
            raise ValueError(f"need at least one feature, got {n_features}")
        _kernels()  # loaded once per process, before any tree needs them
        self.n_features = int(n_features)
        self.distance = distance
        self.eps = eps
        self._eps = float(eps)  # what the kernels take
        self._euclidean = distance == "euclidean"
        self._allocate(64)
        self.node_count = 0
        self.height = 0
        self._changed()
        root_radius = math.sqrt(n_features) / 2 if self._euclidean else n_features / 4
        self._add(np.full(n_features, 0.5), root_radius, -1, root_label)

    def _allocate(self, capacity: int) -> None:
        """An empty table for ``capacity`` spheres."""
        n_feat = self.n_features
        self._table = np.empty((capacity, n_feat + 1 + _layout.INT_COLUMNS), dtype=np.int64)
        # (features, capacity) copy of the centres for the numpy training scan, filled lazily
        self._centers_t = np.empty((n_feat, capacity), dtype=np.float64)
        self._transposed = 0  # columns of _centers_t that are up to date
        self._bind()

    def _bind(self) -> None:
        """The views of the table's columns (rebuilt with the table, and after unpickling)."""
        k, n_feat = _layout, self.n_features
        base = n_feat + 1  # the first integer column
        floats = self._table.view(np.float64)
        self._centers = floats[:, :n_feat]
        self._radii = floats[:, n_feat]
        self._parent = self._table[:, base + k.PARENT]
        self._depth = self._table[:, base + k.DEPTH]
        self._label = self._table[:, base + k.LABEL]
        self._label_column = base + k.LABEL
        self._links = self._table[:, base + k.FIRST : base + k.LAST + 1]  # first, next, last

    _VIEWS = ("_centers", "_radii", "_parent", "_depth", "_label", "_label_column", "_links")

    def __getstate__(self) -> dict[str, Any]:
        """Pickle (and ``copy.deepcopy``) the table, not its views or derived caches."""
        state = {k: v for k, v in self.__dict__.items() if k not in self._VIEWS}
        state.update(_creation=None, _preorder=None, _children=None, _search=None,
                     _unchanged=0, _kd=None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        _kernels()
        self._bind()

    def _grow(self, capacity: int) -> None:
        """Move the spheres into a table of ``capacity`` rows."""
        n, done = self.node_count, self._transposed
        table, centers_t = self._table, self._centers_t
        self._allocate(capacity)
        self._table[:n] = table[:n]
        self._centers_t[:, :done] = centers_t[:, :done]
        self._transposed = done

    def centers_t(self) -> np.ndarray:
        """The centres as (features, spheres), for the numpy reference (kept in step lazily:
        the kernels do not write it)."""
        n, done = self.node_count, self._transposed
        if done < n:
            self._centers_t[:, done:n] = self._centers[done:n].T
            self._transposed = n
        return self._centers_t[:, :n]

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

    @property
    def children(self) -> list[list[int]]:
        """``children[i]``: the children of sphere ``i`` in creation order (built when asked
        for after a change; do not modify)."""
        if self._children is None:
            kids: list[list[int]] = [[] for _ in range(self.node_count)]
            for i, p in enumerate(self._parent[1 : self.node_count].tolist(), start=1):
                kids[p].append(i)
            self._children = kids
        return self._children

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
        uncovered: str = "root",
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
        tree = cls(centers.shape[1], int(label[0]), distance=distance, eps=eps,
                   uncovered=uncovered)
        tree._allocate(max(64, n))
        tree._centers[:n] = centers
        tree._radii[:n] = radii
        tree._parent[:n] = parent
        tree._label[:n] = label
        tree._depth[0] = 0
        for i, p in enumerate(parent[1:].tolist(), start=1):
            tree._depth[i] = tree._depth[p] + 1
        tree._link(n)
        tree.node_count = n
        tree._changed()
        if depth is not None and not np.array_equal(np.asarray(depth), tree._depth[:n]):
            raise ValueError("depth does not follow from parent")
        tree.height = int(tree._depth[:n].max())
        return tree

    def _link(self, n: int) -> None:
        """The children's linked lists of the first ``n`` spheres, from their parents."""
        first, after, last = 0, 1, 2  # the columns of _links
        links = self._links
        links[:n] = -1
        if n < 2:
            return
        by_parent = np.argsort(self._parent[1:n], kind="stable") + 1  # creation order kept
        p = self._parent[by_parent]
        is_last = np.r_[p[1:] != p[:-1], True]  # the last child of its parent
        is_first = np.r_[True, is_last[:-1]]
        links[p[is_first], first] = by_parent[is_first]
        links[p[is_last], last] = by_parent[is_last]
        links[by_parent[:-1][~is_last[:-1]], after] = by_parent[1:][~is_last[:-1]]

    def equal(self, other: SphereTree) -> bool:
        """True if ``other`` has the same distance, eps, rule for uncovered vectors and spheres
        (exactly)."""
        if ((self.distance, self.eps, self.uncovered, self.node_count)
                != (other.distance, other.eps, other.uncovered, other.node_count)):
            return False
        a, b = self.to_arrays(), other.to_arrays()
        return all(np.array_equal(a[k], b[k]) for k in a)

    # ------------------------------------------------------------------ growth
    def _add(self, center: np.ndarray, radius: float, parent: int, label: int) -> int:
        i = self.node_count
        if i == len(self._radii):  # full: double the capacity
            self._grow(2 * i)
        first, after, last = 0, 1, 2  # the columns of _links
        self._centers[i] = center
        self._radii[i] = radius
        depth = 0 if parent < 0 else int(self._depth[parent]) + 1
        self._parent[i], self._depth[i], self._label[i] = parent, depth, label
        self._links[i] = -1
        if parent >= 0:
            up = self._links[parent]
            if up[first] < 0:
                up[first] = i
            else:
                self._links[up[last], after] = i
            up[last] = i
        self.node_count = i + 1
        if depth > self.height:
            self.height = depth
        self._changed()
        return i

    def _changed(self) -> None:
        """Forget what was derived from the spheres (the search table, the reference's layouts,
        children)."""
        self._creation = None
        self._preorder = None
        self._children = None
        self._search: _Search | None = None
        self._unchanged = 0  # single queries since the last change
        self._kd = None  # the centres' k-d tree (uncovered="nearest"), built when first asked

    def learn(
        self,
        x: np.ndarray,
        label: int,
        *,
        spawn: str = "all",
        min_radius: float = 0.0,
        max_nodes: int | None = None,
        max_depth: int | None = None,
        max_radius: float = math.inf,
        compiled: bool = True,
    ) -> Growth:
        """Train on one checked vector ``x`` with label index ``label``.

        Every candidate (``spawn="all"``) or only the winning candidate (``spawn="winner"``)
        whose label differs spawns a child, unless a limit suppresses it: the child's radius
        below ``min_radius`` (0 = none), ``max_nodes`` spheres reached, or the child deeper than
        ``max_depth``. A candidate whose centre is within ``eps`` of ``x`` is relabelled instead.
        A child's radius is ``r_parent - d(x, c_parent)``, at most ``max_radius``. With
        ``uncovered="nearest"`` a vector only the root encloses is answered by the nearest
        centre (the first of equals), and spawns a child of the root when that is not ``label``.
        """
        if not compiled:
            return Growth(*_reference.learn(self, x, label, spawn=spawn, min_radius=min_radius,
                                            max_nodes=max_nodes, max_depth=max_depth,
                                            max_radius=max_radius))
        t = self.learn_many(x.reshape(1, -1), np.array([label], dtype=np.int64), spawn=spawn,
                            min_radius=min_radius, max_nodes=max_nodes, max_depth=max_depth,
                            caps=np.full(1, float(max_radius)))
        return Growth(t.spawned, t.relabelled, t.skipped > 0)

    def learn_many(
        self,
        X: np.ndarray,
        labels: Any,
        *,
        spawn: str = "all",
        min_radius: float = 0.0,
        max_nodes: int | None = None,
        max_depth: int | None = None,
        caps: np.ndarray | None = None,
        compiled: bool = True,
    ) -> Totals:
        """Train on the rows of a checked ``X`` in order, with label indices ``labels``: the
        same tree as :meth:`learn` on each row (row ``i`` with ``max_radius=caps[i]``; None:
        no bound), in one compiled call (``compiled=False``: a loop over :meth:`learn` in
        numpy)."""
        caps = (np.full(X.shape[0], np.inf) if caps is None
                else np.array(caps, dtype=np.float64).reshape(-1))
        if caps.shape != (X.shape[0],):
            raise ValueError(f"caps must hold one radius per row ({X.shape[0]}), got "
                             f"{caps.shape[0]}")
        if not compiled:
            spawned = relabelled = skipped = 0
            for x, label, cap in zip(X, np.asarray(labels).tolist(), caps.tolist(), strict=True):
                g = self.learn(x, label, spawn=spawn, min_radius=min_radius, max_nodes=max_nodes,
                               max_depth=max_depth, max_radius=cap, compiled=False)
                spawned, relabelled = spawned + g.spawned, relabelled + g.relabelled
                skipped += g.suppressed
            return Totals(spawned, relabelled, skipped)
        X = _queries(X)
        labels = np.array(labels, dtype=np.int64)  # a fresh array: the type the kernel takes
        limits = (float(min_radius),
                  _UNLIMITED if max_nodes is None else min(int(max_nodes), _UNLIMITED),
                  _UNLIMITED if max_depth is None else min(int(max_depth), _UNLIMITED))
        start = spawned = relabelled = skipped = 0
        while True:
            rows, self.node_count, self.height, s, r, k = _kernels().learn(
                self._table, X, labels, start, self.node_count, self.height, self._eps,
                self._euclidean, spawn == "winner", *limits, caps, self._nearest_on)
            spawned, relabelled, skipped = spawned + s, relabelled + r, skipped + k
            start += rows
            if start == X.shape[0]:
                break
            self._grow(2 * len(self._radii))  # the next row might not fit
        if spawned or relabelled:
            self._changed()
        return Totals(spawned, relabelled, skipped)

    # ------------------------------------------------------------------ single queries
    def distance_to(self, node: int, x: np.ndarray) -> float:
        """The distance from ``x`` to the centre of sphere ``node`` (in the tree's units)."""
        diff = self._centers[node] - x
        d = float(np.dot(diff, diff))
        return math.sqrt(d) if self._euclidean else d

    def apply_one(self, x: np.ndarray, *, compiled: bool = True) -> int:
        """The winning sphere (creation index) for one checked query vector.

        Compiled: the descent (only the children of enclosing spheres are tested), on the
        search table once the tree has stayed the same for a few queries, else on the node
        table; -1 for a vector outside the unit cube or with a NaN, so that a caller may check
        its input only when the search rejects it. Numpy: every sphere is tested at once (one
        vectorised ``sum((x - c)**2)`` over the features, in feature order), then the enclosing
        ones are walked in creation order in Python.
        """
        flags = x.flags
        if compiled and not (x.dtype is _F64 and flags.c_contiguous and flags.writeable):
            x = np.array(x, dtype=np.float64)  # what the kernels take (a fresh, writable copy)
        node = self._enclosing_one(x, compiled)
        return self._nearest(x, compiled) if node == 0 and self._nearest_on else node

    def _enclosing_one(self, x: np.ndarray, compiled: bool) -> int:
        """The smallest sphere enclosing ``x`` (the root when no other does): the paper's
        winner."""
        if not compiled:
            return _reference.apply_one(self, x)
        flags = x.flags
        if not (x.dtype is _F64 and flags.c_contiguous and flags.writeable):
            x = np.array(x, dtype=np.float64)  # what the kernels take (a fresh, writable copy)
        search = self._search
        if search is None:
            self._unchanged += 1
            if self._unchanged < _TABLE_AFTER:
                return _kernels().winner(self._table, self.node_count, x, self._eps,
                                         self._euclidean)
            search = self._search_table()
        return search.one(search.table, search.nodes, x, self._eps, self._euclidean)

    def _nearest(self, X: np.ndarray, compiled: bool = False) -> Any:
        """The sphere (creation index, the root left out) whose centre is nearest to ``x`` (one
        vector: an int) or to each row of ``X`` (an array), the first of equals (the lowest
        index, as training finds it); the root for a lone root. One vector ``compiled`` (a
        float64 vector the kernels take): every centre in the compiled kernel (a few
        microseconds). Else the centres' k-d tree (scipy's, built on the first call after a
        change) names the two nearest; where the second is as near as the first (to a relative
        ``_NEAR_TIE``: a tie, or one the k-d tree's arithmetic may order otherwise), every
        centre is searched, its squared distance summed in feature order as the kernel does."""
        n = self.node_count
        if n < 2:
            return 0 if X.ndim == 1 else np.zeros(X.shape[0], dtype=np.int64)
        if compiled and X.ndim == 1:
            return _kernels().nearest(self._table, n, X)
        if self._kd is None:
            self._kd = _kd_tree(self._centers[1:n].copy())
        Q = np.asarray(X, dtype=np.float64).reshape(-1, self.n_features)
        k = min(2, n - 1)
        dist, idx = self._kd.query(Q, k=k)
        dist, idx = dist.reshape(len(Q), k), idx.reshape(len(Q), k)
        out = idx[:, 0].astype(np.int64) + 1
        if k == 2:
            for row in np.flatnonzero(dist[:, 1] <= dist[:, 0] * (1.0 + _NEAR_TIE)):
                out[row] = _reference.nearest(self, Q[row])
        return int(out[0]) if X.ndim == 1 else out

    def _search_table(self) -> _Search:
        """The search table of the tree as it is (built now if the tree changed since)."""
        if self._search is None:
            n, f = self.node_count, self.n_features
            rank = np.empty(n, dtype=np.int64)
            # the winner order: smallest radius, then deepest, then earliest created
            rank[np.lexsort((np.arange(n), -self._depth[:n], self._radii[:n]))] = np.arange(n)
            table = np.empty(n * (f + 1 + _layout.SEARCH_INT_COLUMNS), dtype=np.int64)
            nodes = np.empty(n, dtype=np.int64)
            kernels = _kernels()
            kernels.layout(self._table, n, rank, table, nodes)
            self._search = _Search(table, nodes, *kernels.search(f),
                                   self._table[:n, self._label_column].tolist())
        return self._search

    def predict_one(self, x: np.ndarray, *, compiled: bool = True) -> int:
        """The label index of the winning sphere for one checked query vector (compiled: -1
        for a vector outside the unit cube, as :meth:`apply_one`)."""
        search = self._search
        if compiled and search is not None and x.dtype is _F64:
            flags = x.flags
            if flags.c_contiguous and flags.writeable:  # apply_one's search, inlined
                node = search.one(search.table, search.nodes, x, self._eps, self._euclidean)
                if node == 0 and self._nearest_on:
                    node = self._nearest(x, True)
                return -1 if node < 0 else search.labels[node]
        node = self.apply_one(x, compiled=compiled)
        return -1 if node < 0 else self._table.item(node, self._label_column)

    def path(self, node: int) -> list[int]:
        """Creation indices from the root down to ``node``."""
        out = []
        while node >= 0:
            out.append(node)
            node = int(self._parent[node])
        return out[::-1]

    # ------------------------------------------------------------------ batch queries
    def apply(self, X: np.ndarray, algorithm: str = "auto", *, compiled: bool = True
              ) -> np.ndarray:
        """The winning sphere (creation index) of each row of a checked ``X`` (m, features).

        ``algorithm``: ``"brute"`` tests every sphere; ``"descent"`` walks down the tree and
        tests only the children of enclosing spheres. ``"auto"``: compiled, the descent; numpy,
        brute force for trees of at most 64 spheres, else the descent (the numpy brute force
        tests every (query, sphere) pair at once; its descent carries the queries each sphere
        encloses). All give exactly the same answers. The compiled descent runs on the search
        table (built for it if the tree changed since the last), but for a batch of fewer than
        32 rows of a tree that has just changed: it walks the node table then. A batch of
        ``PARALLEL_BATCH`` rows or more on the search table is cut into slices searched by
        :func:`threads` threads.
        """
        out = self._searched(X, algorithm, compiled)[0]
        if self._nearest_on:
            root = np.flatnonzero(out == 0)
            if len(root):
                out[root] = self._nearest(np.asarray(X, dtype=np.float64)[root])
        return out

    def visits(self, X: np.ndarray, algorithm: str = "auto") -> np.ndarray:
        """How many spheres the compiled search computed the distance of, per row of ``X``
        (the root is never tested: it encloses the whole cube)."""
        return self._searched(X, algorithm, True)[1]

    def _searched(self, X: np.ndarray, algorithm: str, compiled: bool, *, walk: bool = False,
                  parts: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """(winners, spheres tested per row); ``walk``: the descent on the node table, not on
        the search table (the tests check both); ``parts``: the threads for a large batch on
        the search table (default :func:`threads`; the tests and benchmarks compare)."""
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
        if not compiled:
            return _reference.apply(self, X, algorithm), None
        X = _queries(X)
        out = np.empty(X.shape[0], dtype=np.int64)
        visited = np.empty(X.shape[0], dtype=np.int64)
        brute = algorithm == "brute"
        if brute or walk or (self._search is None and algorithm == "auto"
                             and X.shape[0] < _TABLE_AFTER):
            _kernels().winners(self._table, self.node_count, X, self._eps, self._euclidean,
                               brute, out, visited)
        else:
            search = self._search_table()
            m, parts = X.shape[0], parts or threads()
            if parts == 1 or m < PARALLEL_BATCH:
                search.many(search.table, search.nodes, X, self._eps, self._euclidean, out,
                            visited)
            else:
                self._search_sliced(search, X, out, visited, parts)
        return out, visited

    def _search_sliced(self, search: _Search, X: np.ndarray, out: np.ndarray,
                       visited: np.ndarray, parts: int) -> None:
        """A large batch on ``parts`` threads: the rows cut into two slices a thread
        (``PARALLEL_SLICE`` rows or more, each searched in its own Z order), which the calling
        thread and ``parts - 1`` pool threads take as each comes free (a thread the machine
        holds back delays a slice, not the batch)."""
        m = X.shape[0]
        step = max(PARALLEL_SLICE, -(-m // (2 * parts)))
        starts = iter(range(0, m, step))
        lock = threading.Lock()

        def work() -> None:
            while True:
                with lock:
                    a = next(starts, None)
                if a is None:
                    return
                b = a + step
                search.many(search.table, search.nodes, X[a:b], self._eps, self._euclidean,
                            out[a:b], visited[a:b])

        helpers = [_pool().submit(work) for _ in range(parts - 1)]
        try:
            work()
        finally:
            for helper in helpers:
                helper.result()

    def predict(self, X: np.ndarray, algorithm: str = "auto", *, compiled: bool = True
                ) -> np.ndarray:
        """The label index of the winning sphere of each row of a checked ``X``."""
        return self._label[self.apply(X, algorithm, compiled=compiled)]


def _kd_tree(points: np.ndarray) -> Any:
    """scipy's k-d tree of ``points`` (scipy.spatial imported on first use: a third of a
    second, which only ``radius="margin"`` pays)."""
    return importlib.import_module("scipy.spatial").cKDTree(points)


def margins(X: np.ndarray, labels: Any, distance: str = "squared") -> np.ndarray:
    """Each row's margin: its distance to the nearest row of ``X`` with another label (in the
    tree's units: squared for ``"squared"``), ``inf`` where every row has its label; one k-d
    tree per label, over the rows of the other labels."""
    labels = np.asarray(labels)
    out = np.full(X.shape[0], np.inf)
    for label in np.unique(labels):
        mine = labels == label
        if mine.all():
            break
        d, _ = _kd_tree(X[~mine]).query(X[mine], k=1)
        out[mine] = d
    return out * out if distance == "squared" else out


def _queries(X: np.ndarray) -> np.ndarray:
    """``X`` as the kernels take it: float64, C order, writable (a copy only if needed: other
    array types would make numba compile another version of a kernel, and the kernels compiled
    ahead of time take only these)."""
    if X.dtype is _F64 and X.flags.c_contiguous and X.flags.writeable:
        return X
    return np.array(X, dtype=np.float64, order="C")
