"""Compaction (rhbl.compaction): exact compaction never changes a prediction on its data (hypothesis),
pruning keeps its error budget, and a compacted tree is an ordinary tree (partial_fit, snapshots)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhbl import HypersphereClassifier, loads
from rhbl.compaction import compact, removal_curve, without

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])

coord = st.one_of(
    st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]),
    st.floats(0.0, 1.0, allow_nan=False, allow_infinity=False),
)


@st.composite
def trained(draw, max_rows=60):
    n = draw(st.integers(1, 4))
    m = draw(st.integers(1, max_rows))
    X = np.array(draw(st.lists(st.lists(coord, min_size=n, max_size=n), min_size=m, max_size=m)))
    y = draw(st.lists(st.sampled_from(["a", "b", "c"]), min_size=m, max_size=m))
    spawn = draw(st.sampled_from(["all", "winner"]))
    distance = draw(st.sampled_from(["squared", "euclidean"]))
    clf = HypersphereClassifier(default_label="a", spawn=spawn, distance=distance).fit(X, y)
    return clf, X, y


def _structure_ok(clf: HypersphereClassifier) -> None:
    a = clf.tree_arrays()
    assert a["parent"][0] == -1
    assert (a["parent"][1:] < np.arange(1, len(a["radii"]))).all()
    assert (a["radii"][1:] <= a["radii"][a["parent"][1:]]).all()
    assert clf.height_ == int(a["depth"].max())


@SETTINGS
@given(trained())
def test_exact_compaction_never_changes_a_prediction_on_its_data(case):
    clf, X, _ = case
    small = clf.compact(X)
    assert np.array_equal(small.predict(X), clf.predict(X))
    assert [small.predict_one(x) for x in X] == [clf.predict_one(x) for x in X]
    assert small.node_count_ <= clf.node_count_ and small.height_ <= clf.height_
    _structure_ok(small)


@SETTINGS
@given(trained(), st.floats(0.0, 0.3))
def test_prune_adds_at_most_its_error_budget(case, budget):
    clf, X, y = case
    small = clf.compact(X, y, method="prune", max_error=budget)
    before = int((clf.predict(X) != np.array(y)).sum())
    after = int((small.predict(X) != np.array(y)).sum())
    assert after - before <= int(np.floor(budget * len(y) + 1e-9))
    rec = small.metadata["compaction"][-1]
    assert (rec["data"]["errors_before"], rec["data"]["errors_after"]) == (before, after)
    _structure_ok(small)


@FEW
@given(trained(max_rows=30), st.integers(1, 5))
def test_prune_to_a_size(case, size):
    clf, X, y = case
    small = clf.compact(X, y, method="prune", max_nodes=size)
    # the exact step first, then the weakest spheres until ``size`` are left, unless none of
    # the rest can go (the end of the whole removal sequence)
    exact = clf.compact(X, y, method="exact").node_count_
    floor = min((nodes for _s, nodes, _h, _e in removal_curve(clf, X, y)), default=exact)
    assert small.node_count_ == min(exact, max(size, floor))


@FEW
@given(trained(max_rows=30))
def test_removal_curve_prefixes_are_the_trees_it_reports(case):
    clf, X, y = case
    curve = removal_curve(clf, X, y)
    if not curve:
        return
    k = len(curve) // 2
    s, nodes, _height, errors = curve[k]
    tree = without(clf, [r[0] for r in curve[: k + 1]])
    assert tree.node_count_ == nodes
    assert int((tree.predict(X) != np.array(y)).sum()) == errors


@SETTINGS
@given(trained(), trained())
def test_a_compacted_tree_trains_and_round_trips_like_any_tree(case, more):
    clf, X, y = case
    small = clf.compact(X)
    again = loads(small.to_bytes())
    assert again.tree_equal(small, metadata=True)
    X2, y2 = more[1], more[2]
    if X2.shape[1] != X.shape[1]:
        return
    # partial_fit on the compacted tree == partial_fit on its reloaded snapshot
    small.partial_fit(X2, y2)
    again.partial_fit(X2, y2)
    assert again.tree_equal(small)
    _structure_ok(small)


def test_provenance_records_the_step():
    rng = np.random.default_rng(0)
    X = rng.random((300, 3))
    y = np.where(X[:, 0] > 0.5, "l", "r")
    clf = HypersphereClassifier(default_label="l", spawn="winner").fit(X, y)
    small = clf.compact(X, data="test rows")
    rec = small.metadata["compaction"][0]
    assert rec["method"] == "exact" and rec["data"] == {"rows": 300, "labelled": False,
                                                        "source": "test rows"}
    assert (rec["nodes_before"], rec["height_before"]) == (clf.node_count_, clf.height_)
    assert (rec["nodes_after"], rec["height_after"]) == (small.node_count_, small.height_)
    assert small.node_count_ < clf.node_count_
    twice = small.compact(X, y, method="prune")
    assert [r["method"] for r in twice.metadata["compaction"]] == ["exact", "prune"]
    assert "compaction" not in clf.metadata  # the original is untouched


def test_bad_input_is_named():
    clf = HypersphereClassifier(default_label="a").fit([[0.1, 0.2], [0.8, 0.9]], ["a", "b"])
    with pytest.raises(ValueError, match="method must be one of"):
        clf.compact([[0.1, 0.2]], method="shrink")
    with pytest.raises(ValueError, match="needs the labels y"):
        clf.compact([[0.1, 0.2]], method="prune")
    with pytest.raises(ValueError, match="has 3 features"):
        clf.compact([[0.1, 0.2, 0.3]])
    with pytest.raises(ValueError, match="outside"):
        clf.compact([[0.1, 2.0]])
    with pytest.raises(ValueError, match="max_error"):
        clf.compact([[0.1, 0.2]], ["a"], method="prune", max_error=2)
    with pytest.raises(ValueError, match="rows but y has"):
        clf.compact([[0.1, 0.2]], ["a", "b"], method="prune")
    with pytest.raises(ValueError, match="root stays"):
        without(clf, [0])
    with pytest.raises(TypeError, match="HypersphereClassifier"):
        compact("tree", [[0.1, 0.2]])
