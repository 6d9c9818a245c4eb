"""Property-based tests (hypothesis) of the tree invariants, plus a naive reference.

The reference below is a direct, recursive transcription of the paper's rules (and of the
documented degenerate-case decisions), written independently of the vectorised classifier.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhbl import HypersphereClassifier, loads

EPS = 1e-9
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# coordinates on a coarse grid make coincident centres and boundary cases likely
coord = st.one_of(
    st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0]),
    st.floats(0.0, 1.0, allow_nan=False, allow_infinity=False),
)


@st.composite
def datasets(draw, max_rows=40):
    n = draw(st.integers(1, 4))
    m = draw(st.integers(1, max_rows))
    X = np.array(draw(st.lists(st.lists(coord, min_size=n, max_size=n), min_size=m, max_size=m)))
    y = draw(st.lists(st.sampled_from(["a", "b", "c"]), min_size=m, max_size=m))
    return X, y


class Ref:
    """Naive recursive RHBL: a list of sphere dicts, children in creation order."""

    def __init__(self, n, default, distance="squared", spawn="all"):
        self.euclid = distance == "euclidean"
        self.spawn = spawn
        r0 = n**0.5 / 2 if self.euclid else n / 4
        self.nodes = [dict(c=[0.5] * n, r=r0, label=default, kids=[], depth=0)]

    def d(self, x, c):
        s = 0.0
        for a, b in zip(x, c, strict=True):
            s += (a - b) ** 2
        return s**0.5 if self.euclid else s

    def encloses(self, i, x):
        return self.d(x, self.nodes[i]["c"]) <= self.nodes[i]["r"] + EPS

    def candidates(self, i, x):
        inside = [k for k in self.nodes[i]["kids"] if self.encloses(k, x)]
        if not inside:
            return [i]
        return [c for k in inside for c in self.candidates(k, x)]

    def winner(self, x):
        cands = self.candidates(0, x)
        return min(cands, key=lambda i: (self.nodes[i]["r"], -self.nodes[i]["depth"], i))

    def learn(self, x, a):
        cands = self.candidates(0, x)
        if self.spawn == "winner":
            cands = [self.winner(x)]
        for p in [c for c in cands if self.nodes[c]["label"] != a]:
            node = self.nodes[p]
            dist = self.d(x, node["c"])
            if dist <= EPS:
                node["label"] = a
                continue
            self.nodes.append(
                dict(c=list(x), r=max(node["r"] - dist, 0.0), label=a, kids=[], depth=node["depth"] + 1)
            )
            node["kids"].append(len(self.nodes) - 1)

    def predict(self, x):
        return self.nodes[self.winner(x)]["label"]


@SETTINGS
@given(datasets(), st.sampled_from(["squared", "euclidean"]), st.sampled_from(["all", "winner"]))
def test_matches_naive_reference(data, distance, spawn):
    X, y = data
    clf = HypersphereClassifier("a", distance=distance, spawn=spawn).fit(X, y)
    ref = Ref(X.shape[1], "a", distance, spawn)
    for x, a in zip(X.tolist(), y, strict=True):
        ref.learn(x, a)
    t = clf.tree_arrays()
    assert clf.node_count_ == len(ref.nodes)
    np.testing.assert_array_equal(t["centers"], [nd["c"] for nd in ref.nodes])
    np.testing.assert_allclose(t["radii"], [nd["r"] for nd in ref.nodes], rtol=0, atol=1e-12)
    assert [clf.classes_[i] for i in t["label"]] == [nd["label"] for nd in ref.nodes]
    Q = np.vstack([X, np.random.default_rng(0).random((30, X.shape[1]))])
    want = [ref.predict(q) for q in Q.tolist()]
    assert clf.predict(Q).tolist() == want
    assert [clf.predict_one(q) for q in Q] == want
    # the one-row fast path of predict, and the winner itself
    assert [clf.predict(q[None, :]).tolist() for q in Q] == [[w] for w in want]
    assert [clf.decision_path(q)[-1]["index"] for q in Q] == [ref.winner(q) for q in Q.tolist()]
    # every batch search, whatever the tree's size (the descent with its matrix-product filter)
    for algorithm in ("brute", "descent"):
        assert clf.set_params(algorithm=algorithm).predict(Q).tolist() == want


@SETTINGS
@given(datasets(), st.sampled_from(["all", "winner"]), st.sampled_from(["squared", "euclidean"]))
def test_tree_invariants(data, spawn, distance):
    X, y = data
    clf = HypersphereClassifier("a", spawn=spawn, distance=distance).fit(X, y)
    t = clf.tree_arrays()
    r0 = t["radii"][0]
    # every training vector is enclosed by the root
    diff = X - 0.5
    d = (diff * diff).sum(axis=1)
    if distance == "euclidean":
        d = np.sqrt(d)
    assert (d <= r0 + EPS).all()
    # a child's radius never exceeds its parent's; no negative radii
    parent = t["parent"]
    assert (t["radii"] >= 0).all()
    assert (t["radii"][1:] <= t["radii"][parent[1:]]).all()
    assert (t["depth"][1:] == t["depth"][parent[1:]] + 1).all()
    assert clf.height_ == t["depth"].max()
    assert sum(clf.label_counts().values()) == clf.node_count_


@SETTINGS
@given(datasets(), st.data())
def test_learned_vector_is_predicted(data, draw):
    X, y = data
    spawn = draw.draw(st.sampled_from(["all", "winner"]))
    clf = HypersphereClassifier("a", spawn=spawn).fit(X, y)
    x = np.array(draw.draw(st.lists(coord, min_size=X.shape[1], max_size=X.shape[1])))
    a = draw.draw(st.sampled_from(["a", "b", "c", "d"]))
    clf.partial_fit([x], [a])
    assert clf.predict_one(x) == a
    assert clf.predict([x])[0] == a
    assert clf.decision_path(x)[-1]["label"] == a


@SETTINGS
@given(datasets(), st.dictionaries(st.text(max_size=5), st.integers(-(2**63), 2**64 - 1) | st.text(max_size=5)))
def test_snapshot_round_trip_exact(data, meta):
    X, y = data
    clf = HypersphereClassifier("a").fit(X, y)
    back = loads(clf.to_bytes(metadata=meta))
    assert back.tree_equal(clf, metadata=True)
    assert back.predict(X).tolist() == clf.predict(X).tolist()


@SETTINGS
@given(datasets(max_rows=30), st.integers(0, 30))
def test_split_training_equals_one_pass(data, cut):
    X, y = data
    one = HypersphereClassifier("a").fit(X, y)
    part = loads(HypersphereClassifier("a").fit(X[:cut], y[:cut]).to_bytes())
    part.partial_fit(X[cut:], y[cut:])
    assert part.tree_equal(one)
