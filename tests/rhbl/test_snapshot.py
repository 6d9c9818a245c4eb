"""msgpack snapshots: round trips, atomic writes, typed errors, exact extensibility."""

from __future__ import annotations

import os

import msgpack
import numpy as np
import pytest

from rhbl import HypersphereClassifier, SnapshotError, load, loads
from rhbl import snapshot as snap


def data(m=300, n=5, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.random((m, n))
    y = np.where(X[:, 0] > X[:, 1], "fwd", np.where(X[:, 2] > 0.5, "rot-left", "fwd-right"))
    return X, y


@pytest.fixture
def fitted():
    X, y = data()
    return HypersphereClassifier("fwd", spawn="winner", max_nodes=500).fit(X, y)


def test_round_trip_is_exact(tmp_path, fitted):
    path = tmp_path / "t.rhbl"
    fitted.save(path, metadata={"task": "wall", "features": {"beams": [0, 45]}, "n": 3})
    clf = load(path)
    assert clf.tree_equal(fitted, metadata=True)
    assert clf.metadata == {"task": "wall", "features": {"beams": [0, 45]}, "n": 3}
    assert clf.get_params() == fitted.get_params()
    Q = np.random.default_rng(1).random((200, 5))
    assert clf.predict(Q).tolist() == fitted.predict(Q).tolist()
    assert (clf.node_count_, clf.height_) == (fitted.node_count_, fitted.height_)
    assert loads(fitted.to_bytes()).tree_equal(fitted)
    assert [f for f in os.listdir(tmp_path)] == ["t.rhbl"]  # no temporary left behind


def test_self_describing(tmp_path, fitted):
    path = tmp_path / "t.rhbl"
    fitted.save(path)
    doc = msgpack.unpackb(path.read_bytes())
    assert doc["format"] == "rhbl-tree" and doc["version"] == 1
    assert doc["params"]["spawn"] == "winner" and doc["params"]["max_nodes"] == 500
    assert doc["centers"]["shape"] == [fitted.node_count_, 5]
    assert doc["labels"][0] == "fwd"


def test_int_labels_and_params_survive(tmp_path):
    clf = HypersphereClassifier(
        0, distance="euclidean", min_radius=0.01, max_depth=7, clip=True, eps=1e-7
    ).fit([[0.1, 0.2], [0.9, 0.9], [1.5, 0.3]], [3, 1, 2])
    clf.save(tmp_path / "i.rhbl")
    back = load(tmp_path / "i.rhbl")
    assert back.tree_equal(clf)
    assert back.classes_.tolist() == [0, 3, 1, 2]
    assert type(back.predict_one([0.1, 0.2])) is int
    assert back.get_params() == clf.get_params()
    assert back.predict_one([7.0, -1.0]) == clf.predict_one([7.0, -1.0])  # clip respected


@pytest.mark.parametrize("spawn", ["all", "winner"])
def test_extensibility_is_exact(tmp_path, spawn):
    X, y = data(400, seed=3)
    kw = {"spawn": spawn, "max_nodes": 300 if spawn == "all" else None}
    one = HypersphereClassifier("fwd", **kw).fit(X, y)
    a = HypersphereClassifier("fwd", **kw).fit(X[:170], y[:170])
    a.save(tmp_path / "a.rhbl")
    b = load(tmp_path / "a.rhbl").partial_fit(X[170:], y[170:])
    assert b.tree_equal(one)


def test_metadata_argument_updates_and_must_serialise(tmp_path, fitted):
    fitted.metadata["a"] = 1
    fitted.save(tmp_path / "m.rhbl", metadata={"b": np.float64(2.5), "c": (1, 2)})
    assert load(tmp_path / "m.rhbl").metadata == {"a": 1, "b": 2.5, "c": [1, 2]}
    with pytest.raises(SnapshotError, match="cannot serialise"):
        fitted.save(tmp_path / "bad.rhbl", metadata={"x": object()})
    assert not (tmp_path / "bad.rhbl").exists()


def test_atomic_write_keeps_old_file_on_crash(tmp_path, fitted, monkeypatch):
    path = tmp_path / "t.rhbl"
    fitted.save(path)
    before = path.read_bytes()

    def boom(*a, **k):
        raise OSError("disk on fire")

    monkeypatch.setattr(snap.os, "replace", boom)
    with pytest.raises(OSError, match="disk on fire"):
        HypersphereClassifier("x").fit([[0.5] * 5], ["y"]).save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["t.rhbl"]


def _special_files(tmp_path):
    """A FIFO, a socket and (as root) a character device like /dev/null, all made here: name
    -> (path, what the error calls it)."""
    import socket
    import stat

    made = {"fifo": (tmp_path / "fifo", "a FIFO"), "socket": (tmp_path / "sock", "a socket"),
            "folder": (tmp_path / "dir", "a folder")}
    os.mkfifo(made["fifo"][0])
    s = socket.socket(socket.AF_UNIX)
    s.bind(str(made["socket"][0]))
    s.close()
    made["folder"][0].mkdir()
    if os.geteuid() == 0:  # mknod needs root (CI runs as root)
        dev = tmp_path / "null"
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.stat("/dev/null").st_rdev)
        made["device"] = (dev, "a character device")
    return made


def test_a_snapshot_never_replaces_what_is_not_a_regular_file(tmp_path, fitted):
    made = _special_files(tmp_path)
    assert "device" in made or os.geteuid() != 0
    for name, (path, kind) in made.items():
        mode = os.lstat(path).st_mode
        with pytest.raises(SnapshotError, match=f"{path}: is {kind}"):
            fitted.save(path)
        assert os.lstat(path).st_mode == mode, name  # still what it was
        link = tmp_path / f"link-to-{name}"
        link.symlink_to(path)
        with pytest.raises(SnapshotError, match=f"is {kind} \\(the symlink's target {path}\\)"):
            fitted.save(link)
        assert link.is_symlink() and os.lstat(path).st_mode == mode
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_a_snapshot_is_written_through_a_symlink_to_its_file(tmp_path, fitted):
    real = tmp_path / "trees" / "t3.rhbl"
    real.parent.mkdir()
    link = tmp_path / "current.rhbl"
    link.symlink_to(real)  # dangling: the file is made where the link points
    fitted.save(link)
    assert link.is_symlink() and real.is_file()
    small = HypersphereClassifier("x").fit([[0.5] * 5], ["y"])
    small.save(link)  # replaces the file, keeps the link
    assert link.is_symlink() and load(real).node_count_ == small.node_count_


def test_a_snapshot_in_a_missing_folder_names_it(tmp_path, fitted):
    with pytest.raises(SnapshotError, match="the folder .*nope does not exist"):
        fitted.save(tmp_path / "nope" / "t.rhbl")


def _bad(tmp_path, content: bytes):
    p = tmp_path / "bad.rhbl"
    p.write_bytes(content)
    return p


def test_errors_name_file_and_problem(tmp_path, fitted):
    good = fitted.to_bytes()
    cases = {
        "truncated": good[: len(good) // 2],
        "empty": b"",
        "garbage": b"\xc1\xc1\xc1 not msgpack",
        "trailing": good + b"\x00",
        "foreign": msgpack.packb({"format": "something-else", "version": 1}),
        "list": msgpack.packb([1, 2, 3]),
        "json": b'{"format": "rhbl-tree"}',
    }
    for name, content in cases.items():
        p = _bad(tmp_path, content)
        with pytest.raises(SnapshotError, match="bad.rhbl: ") as info:
            load(p)
        assert info.value.source == str(p), name
    with pytest.raises(SnapshotError, match="cannot read"):
        load(tmp_path / "missing.rhbl")


def _doc(fitted):
    return msgpack.unpackb(fitted.to_bytes())


def _mutated(fitted, **changes):
    doc = _doc(fitted)
    for key, value in changes.items():
        if value is None:
            del doc[key]
        else:
            doc[key] = value
    return msgpack.packb(doc, use_bin_type=True)


def test_newer_version_and_inconsistent_arrays(fitted):
    doc = _doc(fitted)
    n = fitted.node_count_
    with pytest.raises(SnapshotError, match="version 2 is newer"):
        loads(_mutated(fitted, version=2), source="f.rhbl")
    with pytest.raises(SnapshotError, match="missing field 'radii'"):
        loads(_mutated(fitted, radii=None))
    short = dict(doc["centers"], data=doc["centers"]["data"][:-8])
    with pytest.raises(SnapshotError, match="'centers' has .* bytes"):
        loads(_mutated(fitted, centers=short))
    parent = np.frombuffer(doc["parent"]["data"], "<i8").copy()
    parent[1] = 5
    with pytest.raises(SnapshotError, match="parent"):
        loads(_mutated(fitted, parent=dict(doc["parent"], data=parent.tobytes())))
    labels = np.full(n, 99, "<i8")
    with pytest.raises(SnapshotError, match="label index"):
        loads(_mutated(fitted, label_index=dict(doc["label_index"], data=labels.tobytes())))
    radii = np.frombuffer(doc["radii"]["data"], "<f8").copy()
    radii[-1] = np.nan
    with pytest.raises(SnapshotError, match="non-finite"):
        loads(_mutated(fitted, radii=dict(doc["radii"], data=radii.tobytes())))
    with pytest.raises(SnapshotError, match="invalid parameters"):
        loads(_mutated(fitted, params=dict(doc["params"], spawn="bogus")))
    with pytest.raises(SnapshotError, match="unknown parameters"):
        loads(_mutated(fitted, params=dict(doc["params"], colour=1)))
