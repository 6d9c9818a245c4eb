"""SphereTree apart from the estimator; snapshots written by earlier code; the module layering."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import rhbl
from rhbl import HypersphereClassifier, SnapshotError, SphereTree, load

DATA = Path(__file__).parent / "data"


def fixture_data():
    """The training data of the committed snapshots (no random generator: stable everywhere)."""
    X = (np.arange(1, 61)[:, None] * np.array([0.37, 0.61, 0.13])) % 1.0
    y = np.array(["fwd", "left", "right"])[(np.arange(60) * 7) % 3]
    return X, y


def test_snapshots_written_before_the_tree_was_split_load_identically():
    # written by the code before SphereTree existed, from exactly the recipe below
    X, y = fixture_data()
    clf = HypersphereClassifier("fwd", spawn="winner", max_depth=6, eps=1e-8).fit(X, y)
    clf.partial_fit(X[:5], ["left"] * 5)
    meta = {"task": "fixture", "n": 60, "beams": [0, 90]}
    old = load(DATA / "main-v1-str.rhbl")
    assert old.tree_equal(clf) and old.metadata == meta
    assert clf.to_bytes(metadata=meta) == (DATA / "main-v1-str.rhbl").read_bytes()
    Q = np.vstack([X, (X[:-1] + X[1:]) / 2])
    assert old.predict(Q).tolist() == clf.predict(Q).tolist()
    assert [old.predict_one(q) for q in Q] == clf.predict(Q).tolist()

    yi = (np.arange(40) * 5) % 4
    clf = HypersphereClassifier(0, distance="euclidean", min_radius=0.01, clip=True)
    clf.fit(X[:40] * 1.1 - 0.05, yi)
    old = load(DATA / "main-v1-int.rhbl")
    assert old.tree_equal(clf, metadata=True)
    assert old.to_bytes() == (DATA / "main-v1-int.rhbl").read_bytes()
    assert old.predict(Q).tolist() == clf.predict(Q).tolist()
    assert type(old.predict_one(Q[0])) is int


def test_tree_round_trip_through_arrays():
    X, y = fixture_data()
    clf = HypersphereClassifier("fwd").fit(X, y)
    tree = clf.tree_
    assert isinstance(tree, SphereTree)
    assert (tree.node_count, tree.height) == (clf.node_count_, clf.height_)
    assert tree.children[0] and all(tree.parent[c] == 0 for c in tree.children[0])
    with pytest.raises(ValueError, match="read-only"):
        tree.radii[0] = 1.0
    again = SphereTree.from_arrays(**tree.to_arrays(), distance="squared", eps=1e-9)
    assert again.equal(tree) and again.children == tree.children and again.height == tree.height
    assert not again.equal(SphereTree.from_arrays(**tree.to_arrays(), distance="squared", eps=1e-8))
    back = HypersphereClassifier.from_tree(again, clf.classes_, n_seen=clf.n_seen_,
                                           n_relabelled=clf.n_relabelled_, default_label="fwd")
    assert back.tree_equal(clf)
    assert back.predict(X).tolist() == clf.predict(X).tolist()
    # the rebuilt tree grows on exactly like the original
    assert back.partial_fit(X[::-1], y).tree_equal(clf.partial_fit(X[::-1], y))


def test_from_arrays_names_the_problem():
    good = HypersphereClassifier("a").fit([[0.2, 0.2], [0.25, 0.3], [0.9, 0.1]], ["b", "c", "a"])
    arrays = {k: v for k, v in good.tree_.to_arrays().items() if k != "depth"}

    def bad(**change):
        return SphereTree.from_arrays(**{**arrays, **change}, distance="squared", eps=1e-9)

    cases = [
        ({"centers": np.zeros((0, 2))}, "centers must have shape"),
        ({"radii": arrays["radii"][:-1]}, "radii must have shape"),
        ({"parent": arrays["parent"].astype(float)}, "parent must hold integers"),
        ({"radii": np.r_[arrays["radii"][:-1], np.inf]}, "non-finite"),
        ({"radii": np.r_[arrays["radii"][:-1], -1.0]}, "negative radius"),
        ({"parent": np.r_[arrays["parent"][:-1], 3]}, "each parent must precede its child"),
        ({"label": np.r_[arrays["label"][:-1], -1]}, "label index out of range"),
        ({"radii": np.r_[arrays["radii"][:-1], 0.6]}, "radius exceeds its parent's"),
        ({"depth": np.zeros(3, dtype=np.int64)}, "depth does not follow from parent"),
    ]
    for change, match in cases:
        with pytest.raises(ValueError, match=match):
            bad(**change)
    with pytest.raises(ValueError, match="distance must be one of"):
        SphereTree.from_arrays(**arrays, distance="manhattan", eps=1e-9)


def test_from_tree_names_the_problem():
    tree = HypersphereClassifier("a").fit([[0.2, 0.2], [0.9, 0.1]], ["b", "c"]).tree_
    for classes, match in ((["a", "b"], "label index out of range"),
                           (["a", "b", "a"], "duplicate labels"),
                           ([], "non-empty list of str or int"),
                           (["a", "b", 1.5], "non-empty list of str or int")):
        with pytest.raises(ValueError, match=match):
            HypersphereClassifier.from_tree(tree, classes)
    with pytest.raises(ValueError, match="invalid parameters: spawn must be"):
        HypersphereClassifier.from_tree(tree, ["a", "b", "c"], spawn="some")
    with pytest.raises(ValueError, match="invalid parameters: invalid parameter 'colour'"):
        HypersphereClassifier.from_tree(tree, ["a", "b", "c"], colour="red")
    with pytest.raises(ValueError, match="distance='euclidean' but the tree was grown with"):
        HypersphereClassifier.from_tree(tree, ["a", "b", "c"], distance="euclidean")
    with pytest.raises(ValueError, match="must be a SphereTree"):
        HypersphereClassifier.from_tree({"centers": []}, ["a"])
    clf = HypersphereClassifier.from_tree(tree, ["a", "b", "c"], metadata={"k": 1})
    assert clf.predict_one([0.9, 0.1]) == "c" and clf.metadata == {"k": 1}
    assert (clf.distance, clf.eps) == (tree.distance, tree.eps)


def test_snapshot_errors_from_tree_checks_name_the_file(tmp_path):
    import msgpack

    clf = HypersphereClassifier("a").fit([[0.2, 0.2], [0.9, 0.1]], ["b", "c"])
    doc = msgpack.unpackb(clf.to_bytes())
    doc["labels"] = ["a", "a", "c"]
    path = tmp_path / "dup.rhbl"
    path.write_bytes(msgpack.packb(doc, use_bin_type=True))
    with pytest.raises(SnapshotError, match=r"dup\.rhbl: duplicate labels"):
        load(path)


def _imports(path: Path) -> tuple[set[str], list[int]]:
    """Modules of this package imported by ``path``, and lines of imports inside functions."""
    tree = ast.parse(path.read_text())
    ours: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            ours |= {node.module} if node.module else {a.name for a in node.names}
    nested = [
        inner.lineno
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
        for inner in ast.walk(fn)
        if isinstance(inner, ast.Import | ast.ImportFrom)
    ]
    return ours, nested


def test_snapshots_store_every_parameter_but_the_search():
    assert set(rhbl.snapshot.PARAMS) == set(HypersphereClassifier().get_params()) - {"algorithm", "compiled"}
    with pytest.raises(ValueError, match="need at least one feature"):
        HypersphereClassifier("a").fit(np.zeros((0, 0)), [])


def test_modules_import_one_way():
    """_reference <- tree <- snapshot, compaction <- classifier: no import circle, and no import
    hidden in a function; the kernels (numba) and scipy's k-d tree (radius="margin") are the
    modules loaded on first use."""
    root = Path(rhbl.__file__).parent
    assert _imports(root / "_layout.py") == (set(), [])
    assert _imports(root / "_kernels.py") == ({"_layout"}, [])
    assert _imports(root / "_reference.py") == (set(), [])
    assert _imports(root / "tree.py") == ({"_layout", "_reference"}, [])
    assert 'importlib.import_module("._kernels", __package__)' in (root / "tree.py").read_text()
    assert 'importlib.import_module("scipy.spatial")' in (root / "tree.py").read_text()
    assert _imports(root / "snapshot.py") == ({"_errors"}, [])
    assert _imports(root / "compaction.py") == ({"tree"}, [])
    assert _imports(root / "classifier.py") == ({"snapshot", "_errors", "tree", "compaction"}, [])
