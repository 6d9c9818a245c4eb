"""API contract, degenerate inputs and growth options of HypersphereClassifier."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import rhbl
from rhbl import HypersphereClassifier, NotFittedError


def synthetic(m=400, n=5, seed=0, k=5):
    rng = np.random.default_rng(seed)
    X = rng.random((m, n))
    protos = rng.random((k, n))
    y = np.argmin(((X[:, None, :] - protos) ** 2).sum(-1), axis=1)
    names = np.array(["fwd", "fwd-left", "rot-left", "fwd-right", "rot-right"][:k])
    return X, names[y]


def test_exports():
    assert set(rhbl.__all__) >= {"HypersphereClassifier", "load", "SnapshotError", "NotFittedError"}


def test_rhbl_imports_nothing_of_ours():
    code = (
        "import sys, rhbl; bad = [m for m in ('protocol', 'server', 'client', 'lab') "
        "if m in sys.modules]; assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_not_fitted():
    clf = HypersphereClassifier(default_label="fwd")
    for call in (
        lambda: clf.predict([[0.5] * 5]),
        lambda: clf.predict_one([0.5] * 5),
        lambda: clf.decision_path([0.5] * 5),
        lambda: clf.label_counts(),
        lambda: clf.node_count_,
        lambda: clf.save("/nonexistent/x"),
    ):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()
    with pytest.raises(ValueError):
        clf.predict([[0.5] * 5])
    assert getattr(clf, "node_count_", None) is None  # AttributeError subclass


def test_fit_predict_score_and_attributes():
    X, y = synthetic()
    clf = HypersphereClassifier(default_label="fwd")
    assert clf.fit(X, y) is clf
    assert clf.n_features_in_ == 5
    assert clf.classes_[0] == "fwd"
    assert set(clf.classes_) == set(y)
    pred = clf.predict(X)
    assert isinstance(pred, np.ndarray) and pred.shape == (len(X),)
    assert clf.score(X, y) > 0.8  # later spheres can overrule earlier vectors
    assert sum(clf.label_counts().values()) == clf.node_count_
    assert clf.n_seen_ == len(X)
    assert clf.height_ >= 1
    # fit starts afresh; partial_fit extends
    n = clf.node_count_
    assert clf.partial_fit(X[:10], y[:10]) is clf
    assert clf.node_count_ >= n
    assert clf.fit(X[:1], y[:1]).node_count_ <= 2


def test_int_labels_keep_their_type():
    X, y = synthetic(100)
    yi = np.unique(y, return_inverse=True)[1]
    clf = HypersphereClassifier(default_label=0).fit(X, yi)
    assert clf.predict(X).dtype == np.int64
    assert type(clf.predict_one(X[0])) is int
    assert all(type(k) is int for k in clf.label_counts())
    with pytest.raises(ValueError, match="str or int"):
        clf.partial_fit(X[:1], [1.5])


def test_default_label_none_uses_first_label():
    clf = HypersphereClassifier().fit([[0.2, 0.2], [0.8, 0.8]], ["x", "y"])
    assert clf.classes_.tolist() == ["x", "y"]
    assert clf.node_count_ == 2


def test_predict_one_matches_predict_and_paths():
    X, y = synthetic(600, n=6, seed=3)
    clf = HypersphereClassifier(default_label="fwd").fit(X, y)
    Q = np.random.default_rng(9).random((500, 6))
    batch = clf.predict(Q)
    assert [clf.predict_one(q) for q in Q] == batch.tolist()
    assert clf.node_count_ > 64  # "auto" descends; brute force must agree
    assert clf.set_params(algorithm="brute").predict(Q).tolist() == batch.tolist()
    for q in Q[:20]:
        path = clf.decision_path(q)
        assert path[0]["index"] == 0 and path[-1]["label"] == clf.predict_one(q)
        assert [p["depth"] for p in path] == list(range(len(path)))
        assert all(p["distance"] <= p["radius"] + clf.eps for p in path)


def test_input_validation():
    clf = HypersphereClassifier(default_label="a").fit([[0.5, 0.5]], ["b"])
    with pytest.raises(ValueError, match=r"outside \[0, 1\].*clip=True"):
        clf.partial_fit([[1.5, 0.5]], ["a"])
    with pytest.raises(ValueError, match=r"outside \[0, 1\]"):
        clf.predict([[0.5, -0.1]])
    with pytest.raises(ValueError, match=r"outside \[0, 1\]"):
        clf.predict_one([0.5, -0.1])
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="finite"):
            clf.partial_fit([[bad, 0.5]], ["a"])
        with pytest.raises(ValueError, match="finite"):
            clf.predict_one([0.5, bad])
        with pytest.raises(ValueError, match="finite"):
            clf.predict([[0.5, bad]])
    with pytest.raises(ValueError, match="features"):
        clf.predict([[0.5, 0.5, 0.5]])
    with pytest.raises(ValueError, match="shape"):
        clf.predict_one([0.5, 0.5, 0.5])
    with pytest.raises(ValueError, match="rows"):
        clf.partial_fit([[0.5, 0.5]], ["a", "b"])
    with pytest.raises(ValueError, match="2-D"):
        clf.predict([0.5, 0.5])
    n = clf.node_count_
    assert clf.node_count_ == n  # failed calls changed nothing


def test_clip_option():
    clf = HypersphereClassifier(default_label="a", clip=True).fit([[1.7, -3.0]], ["b"])
    assert clf.tree_arrays()["centers"][1].tolist() == [1.0, 0.0]
    assert clf.predict_one([2.0, -1.0]) == "b"
    assert clf.predict([[2.0, -1.0]]).tolist() == ["b"]
    with pytest.raises(ValueError, match="finite"):
        clf.predict_one([np.nan, 0.0])


def test_coinciding_vector_relabels_in_place():
    clf = HypersphereClassifier(default_label="d").fit([[0.2, 0.7]], ["a"])
    clf.partial_fit([[0.2, 0.7]], ["b"])
    assert clf.node_count_ == 2
    assert clf.n_relabelled_ == 1
    assert clf.predict_one([0.2, 0.7]) == "b"
    # within eps counts as the same centre
    clf.partial_fit([[0.2 + 1e-12, 0.7]], ["c"])
    assert clf.node_count_ == 2 and clf.predict_one([0.2, 0.7]) == "c"


def test_root_centre_relabels_the_root():
    clf = HypersphereClassifier(default_label="d").fit([[0.5, 0.5]], ["a"])
    assert clf.node_count_ == 1
    assert clf.predict_one([0.0, 1.0]) == "a"


@pytest.mark.parametrize("spawn", ["all", "winner"])
@pytest.mark.parametrize("distance", ["squared", "euclidean"])
def test_alternating_labels_do_not_grow(spawn, distance):
    X, y = synthetic(200, seed=1)
    clf = HypersphereClassifier(default_label="fwd", spawn=spawn, distance=distance).fit(X, y)
    n0 = clf.node_count_
    x = np.array([[0.31, 0.62, 0.5, 0.11, 0.9]])
    for i in range(1000):
        label = "fwd-left" if i % 2 else "rot-right"
        clf.partial_fit(x, [label])
        assert clf.predict_one(x[0]) == label
        if i == 1:
            n2 = clf.node_count_  # the first two passes may spawn, then only relabels
    assert n0 <= n2 == clf.node_count_
    assert clf.n_relabelled_ >= 998


def test_zero_radius_sphere():
    # (0, 0) is on the root's boundary: the child has radius exactly 0.5 - 0.5 = 0
    clf = HypersphereClassifier(default_label="d").fit([[0.0, 0.0]], ["a"])
    assert clf.tree_arrays()["radii"].tolist() == [0.5, 0.0]
    assert clf.predict_one([0.0, 0.0]) == "a"
    assert clf.predict_one([1e-3, 0.0]) == "d"
    # a zero-radius sphere can be relabelled but never gets children (nothing else fits)
    clf.partial_fit([[0.0, 0.0]], ["b"])
    assert clf.node_count_ == 2 and clf.predict_one([0.0, 0.0]) == "b"


def test_min_radius_max_nodes_max_depth():
    X, y = synthetic(500, seed=2)
    free = HypersphereClassifier(default_label="fwd").fit(X, y)
    capped = HypersphereClassifier(default_label="fwd", max_nodes=50).fit(X, y)
    assert capped.node_count_ == 50 < free.node_count_
    assert capped.n_skipped_ > 0
    small = HypersphereClassifier(default_label="fwd", min_radius=0.05).fit(X, y)
    assert small.tree_arrays()["radii"][1:].min() >= 0.05
    assert small.n_skipped_ > 0
    shallow = HypersphereClassifier(default_label="fwd", max_depth=3).fit(X, y)
    assert shallow.height_ <= 3
    winner = HypersphereClassifier(default_label="fwd", spawn="winner").fit(X, y)
    assert winner.node_count_ < free.node_count_
    # raising the cap later lets the tree grow again
    capped.set_params(max_nodes=None).partial_fit(X, y)
    assert capped.node_count_ > 50


def test_params_contract():
    clf = HypersphereClassifier("fwd", spawn="winner", max_nodes=10)
    params = clf.get_params()
    assert params["default_label"] == "fwd" and params["spawn"] == "winner"
    assert HypersphereClassifier(**params).get_params() == params
    with pytest.raises(ValueError, match="invalid parameter"):
        clf.set_params(colour="red")
    for bad in ({"distance": "manhattan"}, {"spawn": "some"}, {"min_radius": -1},
                {"max_nodes": 0}, {"max_depth": -1}, {"eps": -1.0}, {"algorithm": "kd_tree"}):
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name):
            HypersphereClassifier("a", **bad).fit([[0.5]], ["a"])
    for name, value in (("distance", "euclidean"), ("eps", 1e-6)):
        fitted = HypersphereClassifier("a").fit([[0.1]], ["b"])
        fitted.set_params(**{name: value})
        with pytest.raises(ValueError, match=f"{name}=.* grown with"):
            fitted.partial_fit([[0.2]], ["a"])
        with pytest.raises(ValueError, match=f"{name}=.* grown with"):
            fitted.learn_one([0.2], "a")
        assert fitted.node_count_ == 2
    fitted = HypersphereClassifier("a").fit([[0.1]], ["b"]).set_params(algorithm="bogus")
    with pytest.raises(ValueError, match="algorithm must be one of"):
        fitted.predict([[0.1], [0.2]])
    assert "spawn='winner'" in repr(clf)


def test_learn_one_reports_changes():
    clf = HypersphereClassifier("d").fit(np.zeros((0, 2)), [])
    assert clf.learn_one([0.2, 0.2], "a") == 1
    assert clf.learn_one([0.2, 0.2], "a") == 0
    assert clf.learn_one([0.2, 0.2], "b") == 1  # relabel


@pytest.mark.parametrize("rows", [40, 300])  # a tree of at most and of more than 64 spheres
def test_algorithms_agree_on_small_and_large_trees(rows):
    X, y = synthetic(rows, n=4, seed=5)
    Q = np.random.default_rng(1).random((300, 4))
    for spawn in ("all", "winner"):
        want = [HypersphereClassifier("fwd", spawn=spawn).fit(X, y).predict_one(q) for q in Q]
        answers = {}
        for algorithm in ("auto", "brute", "descent"):
            clf = HypersphereClassifier("fwd", spawn=spawn, algorithm=algorithm).fit(X, y)
            assert (clf.node_count_ <= 64) == (rows == 40)
            answers[algorithm] = clf.predict(Q).tolist()
            assert clf.score(Q, want) == 1.0
            assert clf.predict(np.zeros((0, 4))).shape == (0,)
        assert answers == {a: want for a in answers}
        # the choice changes no tree: not compared, not saved
        assert clf.tree_equal(HypersphereClassifier("fwd", spawn=spawn).fit(X, y))
        assert rhbl.loads(clf.to_bytes()).algorithm == "auto"


@pytest.mark.parametrize("distance", ["squared", "euclidean"])
def test_batch_filter_exact_on_boundaries(distance):
    # grid points sit exactly on many sphere boundaries (including radius-0 spheres)
    g = np.linspace(0, 1, 5)
    grid = np.array(np.meshgrid(g, g, g)).reshape(3, -1).T
    rng = np.random.default_rng(3)
    y = rng.choice(["a", "b", "c"], len(grid))
    clf = HypersphereClassifier("a", distance=distance, algorithm="descent")
    clf.fit(grid[rng.permutation(len(grid))], y)
    Q = np.vstack([grid, (grid[:-1] + grid[1:]) / 2])
    assert clf.predict(Q).tolist() == [clf.predict_one(q) for q in Q]


def test_one_row_predict_checks_like_batch():
    clf = HypersphereClassifier("a").fit([[0.2, 0.2], [0.8, 0.8]], ["b", "c"])
    for bad, match in (([[1.5, 0.5]], r"X\[0, 0\] = .*1.5.* is outside"),
                       ([[0.5, np.nan]], r"X\[0, 1\] is nan"),
                       ([[0.5]], "has 1 features")):
        with pytest.raises(ValueError, match=match):
            clf.predict(np.array(bad))
    one = clf.predict(np.array([[0.8, 0.8]]))
    assert one.tolist() == ["c"] and one.dtype == clf.predict(np.array([[0.8, 0.8]] * 2)).dtype
    one[0] = "z"  # a copy, not a view of the classes
    assert clf.predict([[0.8, 0.8]]).tolist() == ["c"]
    assert clf.predict(np.array([[0.8, 0.8]], dtype=np.float32)).tolist() == ["c"]
    clipped = HypersphereClassifier("a", clip=True).fit([[0.0, 0.0]], ["b"])
    assert clipped.predict(np.array([[-0.5, -1.0]])).tolist() == ["b"]


def test_single_query_cache_follows_training():
    X, y = synthetic(200, n=3, seed=2)
    clf = HypersphereClassifier("fwd").fit(X[:100], y[:100])
    q = X[150]
    clf.predict_one(q)  # builds the cache
    clf.partial_fit(X[100:], y[100:])
    fresh = HypersphereClassifier("fwd").fit(X, y)
    assert clf.predict_one(q) == fresh.predict_one(q) == clf.predict([q])[0]
    clf.learn_one(q, "rot-left")  # spawn or relabel in place
    assert clf.predict_one(q) == "rot-left"


@pytest.mark.parametrize("labels", [["b", "a", "c"], [7, 3, 9]])
def test_labels_in_a_numpy_array_learn_as_a_list_does(labels):
    """A numpy array of str or int labels is interned in one pass over its distinct values:
    the same tree, classes in order of first appearance and labels of the same type as the
    same labels given as a list."""
    rng = np.random.default_rng(1)
    X = rng.random((300, 3))
    y = [labels[i] for i in rng.integers(0, 3, 300)]
    a = HypersphereClassifier(spawn="winner").partial_fit(X, y)
    b = HypersphereClassifier(spawn="winner").partial_fit(X, np.array(y))
    assert a.tree_equal(b)
    assert list(a.classes_) == list(b.classes_) == list(dict.fromkeys(y))
    assert type(b.predict_one(X[0])) is type(labels[0])
    b.partial_fit(X[:5], np.array(y[:5]))  # known labels only: no new class
    assert list(b.classes_) == list(a.classes_)
    with pytest.raises(ValueError, match="rows but y has"):
        b.partial_fit(X[:4], np.array(y[:5]))


def _margin_tree(compiled=True, X=None, y=None, **params):
    if X is None:
        X, y = synthetic(1500, n=4, seed=3)
    return HypersphereClassifier("fwd", spawn="winner", radius="margin", compiled=compiled,
                                 **params).fit(X, y), X, y


@pytest.mark.parametrize("distance", ["squared", "euclidean"])
def test_margin_bounds_every_sphere_by_the_nearest_vector_of_another_label(distance):
    """radius="margin": no sphere of a fit reaches past the nearest training vector of
    another label (in the tree's units), and it is a smaller tree than the parent's radius
    grows on the same vectors; the margins are those of a brute-force search."""
    X, y = synthetic(1500, n=4, seed=3)
    clf = HypersphereClassifier("fwd", spawn="winner", radius="margin",
                                distance=distance).fit(X, y)
    parent = HypersphereClassifier("fwd", spawn="winner", distance=distance).fit(X, y)
    a = clf.tree_arrays()
    d2 = ((a["centers"][1:, None, :] - X[None, :, :]) ** 2).sum(-1)
    labels = clf.classes_[a["label"][1:]]
    other = np.where(labels[:, None] != y[None, :], d2, np.inf).min(1)
    bound = other if distance == "squared" else np.sqrt(other)
    assert (a["radii"][1:] <= bound + 1e-12).all()
    assert clf.node_count_ < parent.node_count_
    idx = np.array([list(clf.classes_).index(v) for v in y])
    brute = np.where(idx[:, None] != idx[None, :],
                     ((X[:, None, :] - X[None, :, :]) ** 2).sum(-1), np.inf).min(1)
    got = rhbl.tree.margins(X, idx, distance)
    assert np.allclose(got, brute if distance == "squared" else np.sqrt(brute))
    assert (rhbl.tree.margins(X, np.zeros(len(X), dtype=int)) == np.inf).all()


def test_margin_tree_answers_uncovered_vectors_by_the_nearest_centre():
    """Where no sphere but the root encloses a vector, a margin tree answers with the label of
    the sphere whose centre is nearest (the root left out), in every search: one query, a
    batch, the search table, the numpy reference; the decision path ends at that sphere."""
    clf, X, y = _margin_tree()
    ref, _, _ = _margin_tree(compiled=False, X=X, y=y)
    assert clf.tree_equal(ref)
    rng = np.random.default_rng(4)
    Q = rng.random((3000, 4))
    a = clf.tree_arrays()
    centres, labels = a["centers"][1:], clf.classes_[a["label"][1:]]
    paper = HypersphereClassifier.from_tree(rhbl.tree.SphereTree.from_arrays(
        **a, distance="squared", eps=clf.eps), clf.classes_, default_label="fwd",
        spawn="winner")
    uncovered = paper.tree_.apply(Q) == 0
    assert 0.05 < uncovered.mean() < 0.95  # both kinds are tested
    nearest = labels[((Q[:, None, :] - centres[None]) ** 2).sum(-1).argmin(1)]
    want = np.where(uncovered, nearest, paper.predict(Q))
    assert (clf.predict(Q) == want).all()
    assert (ref.predict(Q) == want).all()
    assert [clf.predict_one(q) for q in Q[:100]] == list(want[:100])  # until the search table
    assert [clf.predict_one(q) for q in Q[:100]] == list(want[:100])  # and on it
    assert [ref.predict_one(q) for q in Q[:50]] == list(want[:50])
    q = Q[np.flatnonzero(uncovered)[0]]
    path = clf.decision_path(q)
    assert path[0]["index"] == 0 and path[-1]["label"] == clf.predict_one(q)
    assert (clf.predict(X) == y).mean() > 0.8


def test_every_search_of_a_margin_tree_takes_the_first_of_equally_near_centres():
    """Queries on a grid among centres on a grid tie between centres exactly; one query (the
    compiled kernel), a batch (the k-d tree's candidates), the numpy reference and a read-only
    or float32 query all answer the first of the equally near (the lowest creation index), as
    training does."""
    rng = np.random.default_rng(7)
    X = np.round(rng.random((800, 3)) * 10) / 10
    y = np.where(X[:, 0] + X[:, 1] > 1.0, "a", np.where(X[:, 2] > 0.5, "b", "c"))
    clf = HypersphereClassifier(default_label="a", spawn="winner", radius="margin").fit(X, y)
    ref = HypersphereClassifier(default_label="a", spawn="winner", radius="margin",
                                compiled=False).fit(X, y)
    assert clf.tree_equal(ref)
    Q = np.round(rng.random((3000, 3)) * 20) / 20
    tree = clf.tree_
    n = tree.node_count
    C = tree.centers[1:n]
    d = ((C[None, :, :] - Q[:, None, :]) ** 2).sum(-1)
    first = d.argmin(1) + 1
    uncovered = tree._searched(Q, "auto", True)[0] == 0
    ties = ((d == d.min(1, keepdims=True)).sum(1) > 1) & uncovered
    assert ties.sum() > 20  # the grid makes ties among the uncovered queries
    assert (tree.apply(Q)[uncovered] == first[uncovered]).all()
    assert [tree.apply_one(q) for q in Q[uncovered][:200]] == list(first[uncovered][:200])
    assert (ref.tree_.apply(Q) == tree.apply(Q)).all()
    assert (clf.predict(Q) == np.array([clf.predict_one(q) for q in Q])).all()
    frozen = Q.copy()
    frozen.flags.writeable = False
    assert [clf.predict_one(q) for q in frozen[:300]] == list(clf.predict(Q[:300]))
    Q32 = Q[:200].astype(np.float32)
    assert [tree.apply_one(q) for q in Q32] == list(tree.apply(Q32.astype(np.float64)))


@pytest.mark.parametrize("spawn", ["winner", "all"])
def test_margin_is_a_property_of_fit_partial_fit_extends_by_the_parent(spawn):
    """partial_fit (and learn_one) extend a margin tree with the parent's bound alone: the
    same spheres however the vectors are cut into calls; and a margin tree learns by the rule
    it answers by: right after a vector is learned the tree answers its label (the nearest
    centre too, where only the root encloses it)."""
    X, y = synthetic(800, n=3, seed=5)
    margin = HypersphereClassifier("fwd", spawn=spawn, radius="margin")
    for a in range(0, 800, 100):
        margin.partial_fit(X[a:a + 100], y[a:a + 100])
    whole = HypersphereClassifier("fwd", spawn=spawn, radius="margin").partial_fit(X, y)
    assert whole.tree_equal(margin)
    ref = HypersphereClassifier("fwd", spawn=spawn, radius="margin", compiled=False)
    ref.partial_fit(X, y)
    assert ref.tree_equal(margin)
    fitted = HypersphereClassifier("fwd", spawn=spawn, radius="margin").fit(X, y)
    assert not fitted.tree_equal(margin)
    one = HypersphereClassifier("fwd", spawn=spawn, radius="margin").fit(X[:200], y[:200])
    rng = np.random.default_rng(8)
    for x in rng.random((60, 3)):
        label = str(rng.choice(["fwd", "rot-left", "fwd-right"]))
        one.learn_one(x, label)
        assert one.predict_one(x) == label


def test_margin_snapshots_and_parameter_checks(tmp_path):
    """A margin tree's snapshot says so and loads answering as it did; the paper's radius is
    left out of a snapshot (readers before the parameter read it); a tree cannot change its
    radius rule, and a bad radius is named."""
    clf, X, y = _margin_tree()
    clf.save(tmp_path / "m.rhbl")
    back = rhbl.load(tmp_path / "m.rhbl")
    assert back.radius == "margin" and back.tree_equal(clf)
    Q = np.random.default_rng(6).random((500, 4))
    assert (back.predict(Q) == clf.predict(Q)).all()
    plain = HypersphereClassifier("fwd").fit(X, y)
    doc = rhbl.snapshot.decode(plain.to_bytes())
    assert "radius" not in doc.params and rhbl.loads(plain.to_bytes()).radius == "parent"
    with pytest.raises(ValueError, match="radius must be one of"):
        HypersphereClassifier("a", radius="wide").fit([[0.5]], ["a"])
    back.set_params(radius="parent")
    with pytest.raises(ValueError, match="radius='parent' but the tree answers"):
        back.partial_fit(X[:3], y[:3])
    with pytest.raises(ValueError, match="compaction keeps a tree's answers by the paper's"):
        clf.compact(X)
