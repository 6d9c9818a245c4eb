"""The paper's rules checked on small examples worked out by hand from its formulas.

Two features, so the root is c0 = (0.5, 0.5), r0 = n/4 = 0.5 (squared units), label "d".
Training, one vector at a time (d2 = squared distance):

1. x1 = (0.1, 0.5) "a": d2(x1, c0) = 0.16 <= 0.5, the root has no children, "d" != "a":
   spawn A = ((0.1, 0.5), 0.5 - 0.16 = 0.34, "a").
2. x2 = (0.9, 0.5) "b": d2(x2, A) = 0.64 > 0.34, so the root is the only candidate:
   spawn B = ((0.9, 0.5), 0.5 - 0.16 = 0.34, "b").
3. x3 = (0.3, 0.5) "c": A encloses (0.04 <= 0.34), B does not (0.36 > 0.34); A is a candidate:
   spawn C under A = ((0.3, 0.5), 0.34 - 0.04 = 0.30, "c").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rhbl import HypersphereClassifier

X3 = [[0.1, 0.5], [0.9, 0.5], [0.3, 0.5]]
Y3 = ["a", "b", "c"]


def tree3(**kw) -> HypersphereClassifier:
    return HypersphereClassifier(default_label="d", **kw).fit(X3, Y3)


def test_three_spawns_exact_geometry():
    clf = tree3()
    t = clf.tree_arrays()
    assert clf.node_count_ == 4
    assert clf.height_ == 2
    np.testing.assert_allclose(t["centers"], [[0.5, 0.5], [0.1, 0.5], [0.9, 0.5], [0.3, 0.5]])
    np.testing.assert_allclose(t["radii"], [0.5, 0.34, 0.34, 0.30])
    assert t["parent"].tolist() == [-1, 0, 0, 1]
    assert t["depth"].tolist() == [0, 1, 1, 2]
    assert [clf.classes_[i] for i in t["label"]] == ["d", "a", "b", "c"]
    assert clf.label_counts() == {"d": 1, "a": 1, "b": 1, "c": 1}


@pytest.mark.parametrize(
    "x, want, why",
    [
        # C: 0.04 <= 0.30 and B: 0.16 <= 0.34 enclose; smallest radius C
        ([0.5, 0.5], "c", "C (0.30) beats B (0.34)"),
        # root 0.25, A 0.01, C 0.09 <= 0.30
        ([0.0, 0.5], "c", "C inside A"),
        # root 0.41, A 0.89 > 0.34, B 0.25 <= 0.34
        ([0.9, 0.0], "b", "only B"),
        # root 0.5 <= 0.5 (inclusive at the boundary), B 0.26
        ([1.0, 1.0], "b", "corner on the root's boundary"),
        # A 0.26 <= 0.34, C 0.09 + 0.25 = 0.34 > 0.30
        ([0.0, 0.0], "a", "A but not C"),
        # C encloses (0.2025 <= 0.30) but its parent A does not (0.4225 > 0.34): C is
        # unreachable, B (0.0225 <= 0.34) wins although C's radius is smaller
        ([0.75, 0.5], "b", "child sticking out of its parent is not reachable"),
        # A: 0.01 + 0.25 = 0.26 <= 0.34; C: 0.09 + 0.25 = 0.34 > 0.30
        ([0.0, 1.0], "a", "A: 0.01 + 0.25 = 0.26"),
    ],
)
def test_classification_by_hand(x, want, why):
    clf = tree3()
    assert clf.predict_one(x) == want, why
    assert clf.predict([x])[0] == want, why


def test_root_only_region():
    clf = HypersphereClassifier(default_label="d").fit([[0.1, 0.1]], ["a"])
    # A = ((0.1, 0.1), 0.5 - 0.32 = 0.18); (0.9, 0.9): 1.28 > 0.18 -> root
    np.testing.assert_allclose(clf.tree_arrays()["radii"], [0.5, 0.18])
    assert clf.predict_one([0.9, 0.9]) == "d"
    assert clf.predict_one([0.3, 0.3]) == "a"  # 0.08 <= 0.18


def test_decision_path_by_hand():
    clf = tree3()
    path = clf.decision_path([0.0, 0.5])
    assert [p["index"] for p in path] == [0, 1, 3]
    assert [p["label"] for p in path] == ["d", "a", "c"]
    assert [p["depth"] for p in path] == [0, 1, 2]
    np.testing.assert_allclose([p["radius"] for p in path], [0.5, 0.34, 0.30])
    np.testing.assert_allclose([p["distance"] for p in path], [0.25, 0.01, 0.09])
    assert path[-1]["center"] == pytest.approx([0.3, 0.5])


def test_literal_rule_spawns_under_every_conflicting_candidate():
    # x4 = (0.5, 0.5) "e": candidates C (0.04 <= 0.30, label c) and B (0.16 <= 0.34, label b).
    # Both spawn: D under C, r = 0.30 - 0.04 = 0.26; E under B, r = 0.34 - 0.16 = 0.18.
    # The search visits A's subtree first (creation order), so D is created before E.
    clf = tree3()
    clf.partial_fit([[0.5, 0.5]], ["e"])
    t = clf.tree_arrays()
    assert clf.node_count_ == 6
    assert t["parent"].tolist()[4:] == [3, 2]
    np.testing.assert_allclose(t["radii"][4:], [0.26, 0.18])
    assert clf.height_ == 3
    assert clf.predict_one([0.5, 0.5]) == "e"


def test_winner_rule_spawns_only_under_the_winner():
    # spawn="winner": only C (the smallest candidate, 0.30) spawns: D = ((0.5,0.5), 0.26, "e")
    clf = tree3(spawn="winner")
    clf.partial_fit([[0.5, 0.5]], ["e"])
    t = clf.tree_arrays()
    assert clf.node_count_ == 5
    assert t["parent"][4] == 3
    assert t["radii"][4] == pytest.approx(0.26)
    assert clf.predict_one([0.5, 0.5]) == "e"


def test_no_spawn_when_candidate_label_agrees():
    clf = tree3()
    clf.partial_fit([[0.05, 0.5]], ["c"])  # candidate C encloses (0.0625 <= 0.30), label c
    assert clf.node_count_ == 4


def test_euclidean_variant_by_hand():
    # root radius sqrt(n)/2 = 0.70711; x1 at distance 0.4: child radius 0.30711
    clf = HypersphereClassifier(default_label="d", distance="euclidean").fit(X3[:1], Y3[:1])
    r0 = math.sqrt(2) / 2
    np.testing.assert_allclose(clf.tree_arrays()["radii"], [r0, r0 - 0.4])
    # (0.1, 0.85) is 0.35 from x1 (> 0.307, outside); squared would be 0.1225 <= 0.34
    assert clf.predict_one([0.1, 0.85]) == "d"
    assert clf.predict_one([0.1, 0.75]) == "a"  # 0.25 <= 0.307
    sq = HypersphereClassifier(default_label="d").fit(X3[:1], Y3[:1])
    assert sq.predict_one([0.1, 0.85]) == "a"


def test_paper_contraction_example():
    # Section 5: radii 5 (Euclidean) vs 25 (squared) around (0,0); a vector at (2.5, 0)
    # contracts the Euclidean child by 50% and the squared one by 25%.
    assert (5 - 2.5) / 5 == 0.5
    assert (25 - 2.5**2) / 25 == 0.75


def test_five_feature_root():
    clf = HypersphereClassifier(default_label="fwd").fit(np.zeros((0, 5)), [])
    assert clf.node_count_ == 1
    assert clf.height_ == 0
    assert clf.tree_arrays()["radii"][0] == 1.25
    assert clf.predict_one(np.ones(5)) == "fwd"  # corner: 5 * 0.25 = 1.25 <= 1.25
