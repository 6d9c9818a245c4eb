"""msgpack snapshots of a :class:`HypersphereClassifier` (the unit of extensible retraining).

A snapshot is one msgpack map::

    {"format": "rhbl-tree", "version": 1,
     "params": {default_label, distance, spawn, min_radius, max_nodes, max_depth, clip, eps},
     "n_features": n, "labels": [str | int, ...],            # label index -> label
     "centers": {"dtype": "<f8", "shape": [N, n], "data": bytes},
     "radii": {"dtype": "<f8", "shape": [N], ...},
     "parent": {"dtype": "<i8", ...},                          # -1 for the root; parent < child
     "label_index": {"dtype": "<i8", ...},
     "counters": {"n_seen": int, "n_skipped": int, "n_relabelled": int},
     "metadata": {...}}                                        # free map

Spheres are stored in creation order, which is also the order of every node's children, so
loading and training further gives exactly the tree that training in one process gives.
Files are written atomically (temporary file in the same folder, fsync, ``os.replace``).
Every problem while loading raises :class:`SnapshotError` naming the file and the problem.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from ._errors import SnapshotError
from .classifier import _PARAMS, HypersphereClassifier, _label_array

__all__ = ["FORMAT", "VERSION", "dumps", "load", "loads", "save"]

FORMAT = "rhbl-tree"
VERSION = 1


def _default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple | set | frozenset):
        return list(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__} {obj!r}")


def _array(a: np.ndarray, dtype: str) -> dict[str, Any]:
    a = np.ascontiguousarray(a, dtype=np.dtype(dtype))
    return {"dtype": dtype, "shape": list(a.shape), "data": a.tobytes()}


def to_dict(clf: HypersphereClassifier, metadata: dict[str, Any] | None = None) -> dict:
    """The snapshot map of a fitted classifier."""
    clf._check_fitted()
    if metadata is not None:
        clf.metadata.update(metadata)
    arrays = clf.tree_arrays()
    params = clf.get_params()
    params["distance"] = clf._tree_distance
    return {
        "format": FORMAT,
        "version": VERSION,
        "params": params,
        "n_features": clf.n_features_in_,
        "labels": list(clf._labels),
        "centers": _array(arrays["centers"], "<f8"),
        "radii": _array(arrays["radii"], "<f8"),
        "parent": _array(arrays["parent"], "<i8"),
        "label_index": _array(arrays["label"], "<i8"),
        "counters": {
            "n_seen": clf.n_seen_,
            "n_skipped": clf.n_skipped_,
            "n_relabelled": clf.n_relabelled_,
        },
        "metadata": dict(clf.metadata),
    }


def dumps(clf: HypersphereClassifier, metadata: dict[str, Any] | None = None, *,
          source: str = "<bytes>") -> bytes:
    """The snapshot of ``clf`` as msgpack bytes."""
    clf._check_fitted()
    try:
        return msgpack.packb(to_dict(clf, metadata), default=_default, use_bin_type=True)
    except (TypeError, ValueError, OverflowError) as exc:
        raise SnapshotError(source, f"cannot serialise the snapshot: {exc}") from exc


def save(clf: HypersphereClassifier, path: Any, metadata: dict[str, Any] | None = None) -> None:
    """Write the snapshot of ``clf`` to ``path`` atomically."""
    path = Path(path)
    data = dumps(clf, metadata, source=str(path))
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    try:  # make the rename durable; best effort (not every platform can open a folder)
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def load(path: Any) -> HypersphereClassifier:
    """Read a snapshot file written by :meth:`HypersphereClassifier.save`."""
    source = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise SnapshotError(source, f"cannot read: {exc.strerror or exc}") from exc
    return loads(data, source=source)


def loads(data: bytes, *, source: str = "<bytes>") -> HypersphereClassifier:
    """Rebuild a classifier from snapshot bytes (``source`` names them in errors)."""
    if not data:
        raise SnapshotError(source, "empty file")
    try:
        doc = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except msgpack.ExtraData:
        raise SnapshotError(source, "trailing data after the snapshot (corrupted)") from None
    except Exception as exc:  # msgpack raises several types for truncated/garbage input
        raise SnapshotError(source, f"truncated or not msgpack ({type(exc).__name__}: {exc})") from None
    return from_dict(doc, source=source)


def _get(doc: dict, key: str, types: type | tuple, source: str) -> Any:
    if key not in doc:
        raise SnapshotError(source, f"missing field {key!r}")
    value = doc[key]
    if not isinstance(value, types):
        raise SnapshotError(source, f"field {key!r} has type {type(value).__name__}")
    return value


def _read_array(doc: dict, key: str, dtype: str, shape: tuple, source: str) -> np.ndarray:
    spec = _get(doc, key, dict, source)
    if spec.get("dtype") != dtype:
        raise SnapshotError(source, f"array {key!r} has dtype {spec.get('dtype')!r}, expected {dtype!r}")
    if list(spec.get("shape", [])) != list(shape):
        raise SnapshotError(source, f"array {key!r} has shape {spec.get('shape')}, expected {list(shape)}")
    raw = spec.get("data")
    if not isinstance(raw, bytes):
        raise SnapshotError(source, f"array {key!r} has no byte data")
    want = int(np.prod(shape)) * np.dtype(dtype).itemsize
    if len(raw) != want:
        raise SnapshotError(source, f"array {key!r} has {len(raw)} bytes, expected {want}")
    return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).astype(dtype[1:], copy=True)


def from_dict(doc: Any, *, source: str = "<dict>") -> HypersphereClassifier:
    """Rebuild a classifier from a decoded snapshot map, checking every field."""
    if not isinstance(doc, dict):
        raise SnapshotError(source, f"not an rhbl snapshot (top level is {type(doc).__name__})")
    fmt = doc.get("format")
    if fmt != FORMAT:
        raise SnapshotError(source, f"not an rhbl snapshot (format {fmt!r}, expected {FORMAT!r})")
    version = doc.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise SnapshotError(source, f"invalid snapshot version {version!r}")
    if version > VERSION:
        raise SnapshotError(
            source, f"snapshot version {version} is newer than this reader ({VERSION}); upgrade rhbl"
        )
    params = _get(doc, "params", dict, source)
    unknown = set(params) - set(_PARAMS)
    if unknown:
        raise SnapshotError(source, f"unknown parameters {sorted(unknown)}")
    clf = HypersphereClassifier()
    try:
        clf.set_params(**params)
        clf._check_params()
    except ValueError as exc:
        raise SnapshotError(source, f"invalid parameters: {exc}") from None
    n_features = _get(doc, "n_features", int, source)
    labels = _get(doc, "labels", list, source)
    if not labels or not all(isinstance(v, str | int) for v in labels):
        raise SnapshotError(source, "labels must be a non-empty list of str or int")
    if len(set(labels)) != len(labels):
        raise SnapshotError(source, "duplicate labels")
    radii_spec = _get(doc, "radii", dict, source)
    shape = radii_spec.get("shape")
    if not (isinstance(shape, list) and len(shape) == 1 and isinstance(shape[0], int) and shape[0] >= 1):
        raise SnapshotError(source, f"array 'radii' has an invalid shape {shape!r}")
    n = shape[0]
    if n_features < 1:
        raise SnapshotError(source, f"invalid n_features {n_features}")
    centers = _read_array(doc, "centers", "<f8", (n, n_features), source)
    radii = _read_array(doc, "radii", "<f8", (n,), source)
    parent = _read_array(doc, "parent", "<i8", (n,), source)
    label = _read_array(doc, "label_index", "<i8", (n,), source)
    counters = _get(doc, "counters", dict, source)
    metadata = _get(doc, "metadata", dict, source)
    # consistency of the tree
    if not (np.isfinite(centers).all() and np.isfinite(radii).all()):
        raise SnapshotError(source, "non-finite sphere data")
    if (radii < 0).any():
        raise SnapshotError(source, "negative radius")
    if parent[0] != -1 or (n > 1 and ((parent[1:] < 0) | (parent[1:] >= np.arange(1, n))).any()):
        raise SnapshotError(source, "inconsistent parent indices (each parent must precede its child)")
    if (label < 0).any() or (label >= len(labels)).any():
        raise SnapshotError(source, "label index out of range")
    if n > 1 and (radii[1:] > radii[parent[1:]]).any():
        raise SnapshotError(source, "a child's radius exceeds its parent's")
    try:
        seen, skipped, relabelled = (int(counters[k]) for k in ("n_seen", "n_skipped", "n_relabelled"))
    except (KeyError, TypeError, ValueError):
        raise SnapshotError(source, "invalid counters") from None
    # rebuild
    clf._init_tree(n_features, labels[0])
    clf._labels = list(labels)
    clf._label_index = {v: i for i, v in enumerate(labels)}
    clf._label_values = _label_array(clf._labels)
    depth = np.zeros(n, dtype=np.int64)
    children: list[list[int]] = [[] for _ in range(n)]
    for i in range(1, n):
        p = int(parent[i])
        depth[i] = depth[p] + 1
        children[p].append(i)
    cap = max(64, n)
    clf._centers = np.empty((cap, n_features))
    clf._centers[:n] = centers
    for name, arr in (("_radii", radii), ("_parent", parent), ("_depth", depth), ("_label", label)):
        full = np.empty(cap, dtype=arr.dtype)
        full[:n] = arr
        setattr(clf, name, full)
    clf._children = children
    clf._ct = None
    clf._n = n
    clf.height_ = int(depth.max())
    clf.n_seen_, clf.n_skipped_, clf.n_relabelled_ = seen, skipped, relabelled
    clf.metadata = metadata
    clf._layout = None
    clf._one = None
    return clf
