"""Hostile snapshot headers (declared sizes huge, negative, wrapping in int64, not matching the
data, of the wrong type) and hostile metadata, through every loader: each fails with one
``SnapshotError`` (or ``IncompatibleSnapshotError``) that names the file, never numpy's or
anything else's error."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from client.behaviour.features import FEATURES
from client.behaviour.learning import (
    DemonstrationLearner,
    IncompatibleSnapshotError,
    TreePolicy,
    load_snapshot,
)
from rhbl import SnapshotError, load


def _with(doc: dict, path: tuple, value) -> dict:
    doc = msgpack.unpackb(msgpack.packb(doc, use_bin_type=True), raw=False)  # a deep copy
    *parents, last = path
    at = doc
    for p in parents:
        at = at[p]
    at[last] = value
    return doc


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> dict:
    """A learner's snapshot (features and actions in its metadata) as its map."""
    rng = np.random.default_rng(0)
    learner = DemonstrationLearner(FEATURES["wall"])
    for k in range(60):
        learner.observe(rng.uniform(0.2, 8.0, 360).astype(np.float32), 0.0,
                        ("fwd", "fwd-left", "fwd-right")[k % 3])
    path = tmp_path_factory.mktemp("good") / "tree.rhbl"
    learner.save(path)
    return msgpack.unpackb(path.read_bytes(), raw=False)


def hostile(good: dict) -> dict[str, dict]:
    n, f = good["radii"]["shape"][0], good["n_features"]
    big = 2**62
    return {
        # the defect: 2^62 spheres of 4 features are 2^64 values, 0 in int64, so no data
        # matched the expected size and numpy's reshape failed, naming no file
        "2^62 spheres of 4 features, no data": _with(_with(_with(_with(
            good, ("radii", "shape"), [big]), ("n_features",), 4), ("centers", "shape"),
            [big, 4]), ("centers", "data"), b""),
        "n_features 2^62, shape to match, no data": _with(
            _with(_with(good, ("n_features",), big), ("centers", "shape"), [n, big]),
            ("centers", "data"), b""),
        "n_features 2^63 - 1": _with(good, ("n_features",), 2**63 - 1),
        "n_features negative": _with(good, ("n_features",), -3),
        "n_features zero": _with(good, ("n_features",), 0),
        "n_features a boolean": _with(good, ("n_features",), True),
        "n_features a float": _with(good, ("n_features",), 5.0),
        "n_features a string": _with(good, ("n_features",), "5"),
        "radii shape negative": _with(good, ("radii", "shape"), [-1]),
        "radii shape a boolean": _with(good, ("radii", "shape"), [True]),
        "radii shape huge": _with(good, ("radii", "shape"), [2**63 - 1]),
        "centers shape other": _with(good, ("centers", "shape"), [n, f + 1]),
        "centers shape a string": _with(good, ("centers", "shape"), "4x5"),
        "centers data short": _with(good, ("centers", "data"), good["centers"]["data"][:-8]),
        "centers data long": _with(good, ("centers", "data"), good["centers"]["data"] + b"\0" * 8),
        "centers data a string": _with(good, ("centers", "data"), "x"),
        "centers a list": _with(good, ("centers",), [1, 2]),
        "parent dtype other": _with(good, ("parent", "dtype"), "<i4"),
        "counters negative": _with(good, ("counters", "n_skipped"), -1),
        "counters a boolean": _with(good, ("counters", "n_seen"), True),
        "counters a float": _with(good, ("counters", "n_seen"), 1.5),
        "labels a map": _with(good, ("labels",), {"a": 1}),
        "params of the wrong type": _with(good, ("params", "max_depth"), "deep"),
        "metadata features malformed": _with(good, ("metadata", "features"), {"kind": 5}),
        "metadata features a string": _with(good, ("metadata", "features"), "wall"),
        "metadata actions malformed": _with(good, ("metadata", "actions"), {"names": 1}),
        "metadata stride a string": _with(good, ("metadata", "learning"), {"stride": "two"}),
        "metadata without features": _with(good, ("metadata",), {"task": "wall"}),
    }


CASES = sorted(hostile({"radii": {"shape": [1]}, "n_features": 1, "centers": {"data": b""},
                        "params": {}, "counters": {}, "metadata": {}, "parent": {}}))
LOADERS = {
    "rhbl.load": load,
    "load_snapshot": load_snapshot,
    "TreePolicy.load": TreePolicy.load,
    "DemonstrationLearner.resume": DemonstrationLearner.resume,
}
RHBL_ONLY = {"metadata features malformed", "metadata features a string",
             "metadata actions malformed", "metadata stride a string",
             "metadata without features"}  # what rhbl.load rightly takes (metadata is free)


@pytest.mark.parametrize("loader", sorted(LOADERS))
@pytest.mark.parametrize("case", CASES)
def test_a_hostile_snapshot_fails_naming_the_file(tmp_path, good, case, loader):
    path = tmp_path / "bad tree.rhbl"
    path.write_bytes(msgpack.packb(hostile(good)[case], use_bin_type=True))
    if loader == "rhbl.load" and case in RHBL_ONLY:
        load(path)
        return
    if loader in ("load_snapshot", "TreePolicy.load") and case == "metadata stride a string":
        LOADERS[loader](path)  # only resuming builds a learner with it
        return
    with pytest.raises((SnapshotError, IncompatibleSnapshotError)) as info:
        LOADERS[loader](path)
    text = str(info.value)
    assert text.startswith(f"{path}: "), text
    assert "\n" not in text and "reshape" not in text


def test_the_good_snapshot_loads_everywhere(tmp_path, good):
    path = tmp_path / "tree.rhbl"
    path.write_bytes(msgpack.packb(good, use_bin_type=True))
    for loader in LOADERS.values():
        loader(path)
