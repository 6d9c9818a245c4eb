"""The compiled kernels against the numpy reference (``compiled=False``), array by array.

Every tree here is grown twice, once by the kernels and once by the reference, from the same
vectors; the two must agree exactly: every array of the tree (centres, radii, parents, depths,
labels), the counters, the height, the children, and the winner of every query under every
search (compiled: the descent on the node table and on the search table, single queries and
batches, brute force; the reference's single-query scan, brute force and descent). Every test
runs twice: with the kernels compiled ahead of time (``setup.py``; skipped where they are not
built) and with numba's.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rhbl
import rhbl.tree
from rhbl import HypersphereClassifier, SphereTree

DATA = Path(__file__).parent / "data"
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# the kernels numba compiles when first used: the same checks, after tens of seconds of
# compiling; only in the whole suite (`make test`), not the fast tier (`make check`)
NUMBA = pytest.param("numba", marks=pytest.mark.slow)


@pytest.fixture(autouse=True, scope="module", params=["ahead-of-time", NUMBA])
def kernels(request):
    """The kernels every tree of the module is grown and searched with."""
    if request.param == "ahead-of-time":
        aot = rhbl.tree._ahead_of_time()
        if aot is None:
            pytest.skip("no kernels compiled ahead of time (setup.py: no C compiler, or the "
                        "source changed since make install)")
        chosen = rhbl.tree._Kernels(aot, "ahead-of-time")
    else:
        jit = importlib.import_module("rhbl._kernels")
        jit.load()
        chosen = rhbl.tree._Kernels(jit, "numba")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(rhbl.tree, "_kernels", lambda: chosen)
        yield request.param


# a coarse grid makes coincident centres (relabels in place), duplicates, corners (radius 0)
# and vectors on sphere boundaries likely
coord = st.one_of(
    st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]),
    st.floats(0.0, 1.0, allow_nan=False, allow_infinity=False),
)


@st.composite
def trainings(draw, max_rows=80):
    n = draw(st.integers(1, 5))
    m = draw(st.integers(0, max_rows))
    X = np.array(draw(st.lists(st.lists(coord, min_size=n, max_size=n), min_size=m, max_size=m)))
    X = X.reshape(m, n)
    if m and draw(st.booleans()):  # repeat rows with other labels
        X = np.vstack([X, X[: draw(st.integers(1, m))]])
    y = draw(st.lists(st.sampled_from(["a", "b", "c"]), min_size=len(X), max_size=len(X)))
    params = {
        "distance": draw(st.sampled_from(["squared", "euclidean"])),
        "spawn": draw(st.sampled_from(["all", "winner"])),
        "max_nodes": draw(st.one_of(st.none(), st.integers(1, 60))),
        "max_depth": draw(st.one_of(st.none(), st.integers(0, 6))),
        "min_radius": draw(st.sampled_from([0.0, 0.0, 0.01, 0.1])),
        "eps": draw(st.sampled_from([1e-9, 0.0, 1e-3])),
    }
    return X, y, params


def assert_same_tree(a: HypersphereClassifier, b: HypersphereClassifier) -> None:
    """Every array, counter and derived structure of the two trees is identical."""
    ta, tb = a.tree_.to_arrays(), b.tree_.to_arrays()
    assert ta.keys() == tb.keys()
    for name in ta:
        assert ta[name].dtype == tb[name].dtype, name
        np.testing.assert_array_equal(ta[name], tb[name], err_msg=name, strict=True)
    assert (a.n_seen_, a.n_skipped_, a.n_relabelled_) == (b.n_seen_, b.n_skipped_, b.n_relabelled_)
    assert (a.node_count_, a.height_) == (b.node_count_, b.height_)
    assert a.classes_.tolist() == b.classes_.tolist()
    assert a.tree_.children == b.tree_.children
    assert a.tree_equal(b)


def assert_same_winners(tree: SphereTree, Q: np.ndarray) -> np.ndarray:
    """Every search finds the same winner for every row of ``Q``; returns the winners."""
    want = np.array([tree.apply_one(q, compiled=False) for q in Q], dtype=np.int64)
    tree._changed()  # single queries: on the node table first, then on the search table
    assert [tree.apply_one(q) for q in Q] == want.tolist()
    walked = tree._searched(Q, "descent", True, walk=True)[0]
    np.testing.assert_array_equal(walked, want, err_msg="descent on the node table")
    for compiled in (True, False):
        for algorithm in ("auto", "brute", "descent"):
            got = tree.apply(Q, algorithm, compiled=compiled)
            np.testing.assert_array_equal(got, want, err_msg=f"{algorithm} compiled={compiled}")
    assert [tree.apply_one(q) for q in Q] == want.tolist()
    # a batch large enough to be cut among threads: the same in one thread and in three
    big = np.resize(Q, (max(len(Q), rhbl.tree.PARALLEL_BATCH), Q.shape[1]))
    for parts in (1, 3):
        np.testing.assert_array_equal(tree._searched(big, "auto", True, parts=parts)[0],
                                      np.resize(want, len(big)), err_msg=f"{parts} threads")
    return want


def queries(X: np.ndarray, n: int, count: int, seed: int) -> np.ndarray:
    """Training rows, their midpoints, jittered copies and uniform vectors, in the cube."""
    rng = np.random.default_rng(seed)
    parts = [rng.random((count, n))]
    if len(X):
        parts += [X, np.clip(X + rng.normal(0, 0.02, X.shape), 0.0, 1.0)]
        if len(X) > 1:
            parts.append((X[:-1] + X[1:]) / 2)
    return np.vstack(parts)


@SETTINGS
@given(trainings())
def test_kernels_grow_and_search_exactly_like_the_reference(data):
    X, y, params = data
    n = X.shape[1]
    fast = HypersphereClassifier("a", **params).fit(X, y)
    slow = HypersphereClassifier("a", compiled=False, **params).fit(X, y)
    assert_same_tree(fast, slow)
    Q = queries(X, n, 40, seed=len(X))
    winners = assert_same_winners(fast.tree_, Q)
    assert fast.predict(Q).tolist() == slow.predict(Q).tolist()
    assert [fast.predict_one(q) for q in Q] == fast.classes_[fast.tree_.label[winners]].tolist()
    # vector by vector (learn_one, the tables growing past their first 64 rows) is the same tree
    one = HypersphereClassifier("a", **params).fit(np.zeros((0, n)), [])
    for x, label in zip(X, y, strict=True):
        one.learn_one(x, label)
    assert_same_tree(one, fast)


@SETTINGS
@given(trainings(max_rows=40), st.integers(0, 40), st.booleans())
def test_loaded_trees_grow_on_exactly_alike(data, cut, compiled_first):
    """A tree rebuilt from its arrays (a snapshot: the children's links are rebuilt) grows on
    like the original, whichever code grew the first part."""
    X, y, params = data
    first = HypersphereClassifier("a", compiled=compiled_first, **params).fit(X[:cut], y[:cut])
    again = rhbl.loads(first.to_bytes()).set_params(max_nodes=params["max_nodes"],
                                                    max_depth=params["max_depth"])
    assert again.tree_.children == first.tree_.children
    for clf in (first, again):
        clf.partial_fit(X[cut:], y[cut:])
    whole = HypersphereClassifier("a", compiled=False, **params).fit(X, y)
    assert_same_tree(again, whole)
    assert_same_tree(first, whole)


def noisy_labels(m: int, n: int, flip: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Vectors labelled by the nearest of 5 prototypes, a fraction ``flip`` of labels flipped."""
    rng = np.random.default_rng(seed)
    X = rng.random((m, n))
    y = np.argmin(((X[:, None, :] - rng.random((5, n))) ** 2).sum(-1), axis=1)
    flipped = rng.random(m) < flip
    y[flipped] = rng.integers(0, 5, flipped.sum())
    return X, y


@pytest.mark.parametrize("spawn", ["all", "winner"])
@pytest.mark.parametrize("distance", ["squared", "euclidean"])
def test_noisy_labels_deep_trees(spawn, distance):
    """Larger, deeper trees than hypothesis draws: 10% flipped labels in 6 dimensions."""
    X, y = noisy_labels(1500, 6, 0.1, seed=11)
    fast = HypersphereClassifier(0, spawn=spawn, distance=distance).fit(X, y)
    slow = HypersphereClassifier(0, spawn=spawn, distance=distance, compiled=False).fit(X, y)
    assert_same_tree(fast, slow)
    assert fast.node_count_ > (500 if spawn == "all" else 150)
    assert_same_winners(fast.tree_, queries(X[:300], 6, 500, seed=1))


def test_a_real_wall_following_tree():
    """The tree ``rhbl train --world room --seconds 1200 --rounds 0 --starts world`` wrote
    (1687 spheres of 5 features, height 82): searches agree on queries near its centres, and
    training it further, and afresh on its centres, grows identical trees."""
    room = rhbl.load(DATA / "room-1200.rhbl")
    assert (room.node_count_, room.height_, room.n_features_in_) == (1687, 82, 5)
    tree = room.tree_
    rng = np.random.default_rng(5)
    C = tree.centers
    near = np.clip(C[rng.integers(0, len(C), 3000)] + rng.normal(0, 0.01, (3000, 5)), 0, 1)
    assert_same_winners(tree, np.vstack([C, near]))
    labels = room.classes_[rng.integers(0, len(room.classes_), 2000)]
    more = near[:2000]
    fast = rhbl.load(DATA / "room-1200.rhbl").partial_fit(more, labels)
    slow = rhbl.load(DATA / "room-1200.rhbl").set_params(compiled=False).partial_fit(more, labels)
    assert_same_tree(fast, slow)
    assert fast.node_count_ > room.node_count_
    y = room.classes_[tree.label]
    fresh = HypersphereClassifier(y[0]).fit(C[1:], y[1:])
    assert_same_tree(fresh, HypersphereClassifier(y[0], compiled=False).fit(C[1:], y[1:]))


def test_visits_count_the_spheres_tested():
    X, y = noisy_labels(800, 4, 0.1, seed=2)
    tree = HypersphereClassifier(0).fit(X, y).tree_
    Q = np.random.default_rng(3).random((200, 4))
    walked = tree._searched(Q, "descent", True, walk=True)[1]  # on the node table
    visits = tree.visits(Q)  # on the search table, which also skips what cannot win
    assert visits.shape == (200,) and visits.min() >= 1
    assert visits.max() < tree.node_count - 1  # the descent skips subtrees
    assert (visits <= walked).all() and (visits < walked).any()
    assert (tree.visits(Q, "brute") == tree.node_count - 1).all()
    # the walk: exactly the children of the spheres each query reaches
    reached = [set(tree.path(w)) for w in tree.apply(Q)]  # at least the winner's path
    for q, v, path in zip(Q, walked, reached, strict=True):
        d = ((tree.centers - q) ** 2).sum(axis=1)
        ok = np.zeros(tree.node_count, dtype=bool)
        ok[0] = True
        for i in range(1, tree.node_count):
            ok[i] = d[i] <= tree.radii[i] + tree.eps and ok[tree.parent[i]]
        assert path <= set(np.flatnonzero(ok).tolist())
        assert v == sum(len(tree.children[i]) for i in np.flatnonzero(ok))


@pytest.mark.parametrize("value", ["0", "two", "-1"])
def test_a_bad_thread_count_is_named_and_the_cores_used(monkeypatch, caplog, value):
    """A bad ``RHBL_THREADS`` never stops a process: it is logged, and the default used."""
    monkeypatch.delenv("RHBL_THREADS", raising=False)
    rhbl.tree.threads.cache_clear()
    try:
        cores = rhbl.tree.threads()
        monkeypatch.setenv("RHBL_THREADS", value)
        rhbl.tree.threads.cache_clear()
        with caplog.at_level("WARNING", logger="rhbl.tree"):
            assert rhbl.tree.threads() == cores
        assert f"RHBL_THREADS must be an integer >= 1, got '{value}'" in caplog.text
        monkeypatch.setenv("RHBL_THREADS", "3")
        rhbl.tree.threads.cache_clear()
        assert rhbl.tree.threads() == 3
    finally:
        monkeypatch.undo()
        rhbl.tree.threads.cache_clear()


def test_odd_query_arrays_get_the_same_answers():
    """Read-only, strided and float32 inputs reach the kernels as the arrays they take."""
    X, y = noisy_labels(300, 3, 0.1, seed=4)
    clf = HypersphereClassifier(0).fit(X, y)
    Q = np.random.default_rng(5).random((50, 6))[:, ::2]  # strided
    want = clf.set_params(compiled=False).predict(np.ascontiguousarray(Q))
    clf.set_params(compiled=True)
    frozen = Q.copy()
    frozen.flags.writeable = False
    for batch in (Q, frozen, Q.astype(np.float32), np.asfortranarray(Q)):
        assert clf.predict(batch).tolist() == want.tolist()
    assert [clf.predict_one(q) for q in frozen] == want.tolist()
    assert [clf.predict_one(q) for q in Q] == want.tolist()
    again = HypersphereClassifier(0).fit(np.asfortranarray(X), y)
    assert_same_tree(again, HypersphereClassifier(0, compiled=False).fit(X, y))


def test_compiled_parameter():
    clf = HypersphereClassifier("a", compiled=False)
    assert clf.get_params()["compiled"] is False and "compiled=False" in repr(clf)
    clf.fit([[0.2, 0.3]], ["b"])
    # not part of the tree: not saved, not compared
    assert rhbl.loads(clf.to_bytes()).compiled is True
    assert clf.tree_equal(HypersphereClassifier("a").fit([[0.2, 0.3]], ["b"]))
    with pytest.raises(ValueError, match="compiled must be True or False, got 'yes'"):
        HypersphereClassifier("a", compiled="yes").fit([[0.2]], ["b"])


def test_importing_rhbl_does_not_import_numba(kernels):
    """The kernels are loaded by the first classifier made (or tree built), not by ``import
    rhbl``; numba is imported only for its kernels (none compiled ahead of time, or
    ``RHBL_KERNELS=jit``)."""
    code = ("import sys, rhbl, rhbl.tree; assert 'numba' not in sys.modules, 'numba imported'; "
            "rhbl.load({path!r}); assert rhbl.tree._kernels.cache_info().currsize == 1; "
            "origin = rhbl.tree.load_kernels(); "
            "assert ('numba' in sys.modules) == (origin == 'numba'), origin; print(origin)")
    env = {**os.environ, "RHBL_KERNELS": "jit" if kernels == "numba" else ""}
    done = subprocess.run([sys.executable, "-c", code.format(path=str(DATA / "main-v1-int.rhbl"))],
                          check=True, env=env, capture_output=True, text=True)
    assert done.stdout.strip() == kernels
    code = ("import sys, rhbl, rhbl.tree; rhbl.HypersphereClassifier('a', compiled=False); "
            "assert 'numba' not in sys.modules; "
            "assert rhbl.tree._kernels.cache_info().currsize == 0; rhbl.HypersphereClassifier('a'); "
            "assert rhbl.tree._kernels.cache_info().currsize == 1")
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_pickled_and_copied_trees_grow_on_alike():
    """The tree's column views are rebuilt after unpickling: a copy is a whole tree of its own."""
    import copy
    import pickle

    X, y = noisy_labels(400, 3, 0.1, seed=6)
    clf = HypersphereClassifier(0).fit(X[:200], y[:200])
    for other in (pickle.loads(pickle.dumps(clf)), copy.deepcopy(clf)):
        assert_same_tree(other, clf)
        other.partial_fit(X[200:], y[200:])
        assert other.node_count_ > clf.node_count_  # the original did not grow with it
        assert_same_tree(other, HypersphereClassifier(0, compiled=False).fit(X, y))
        assert other.predict(X).tolist() == [other.predict_one(x) for x in X]
