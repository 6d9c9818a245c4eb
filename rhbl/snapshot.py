"""The msgpack snapshot format of a hypersphere tree (the unit of extensible retraining).

A snapshot is one msgpack map::

    {"format": "rhbl-tree", "version": 1,
     "params": {default_label, distance, spawn, radius, min_radius, max_nodes, max_depth, clip,
                eps},
     "n_features": n, "labels": [str | int, ...],            # label index -> label
     "centers": {"dtype": "<f8", "shape": [N, n], "data": bytes},
     "radii": {"dtype": "<f8", "shape": [N], ...},
     "parent": {"dtype": "<i8", ...},                          # -1 for the root; parent < child
     "label_index": {"dtype": "<i8", ...},
     "counters": {"n_seen": int, "n_skipped": int, "n_relabelled": int},
     "metadata": {...}}                                        # free map

Spheres are stored in creation order, which is also the order of every node's children, so
loading and training further gives exactly the tree that training in one process gives.

This module knows the format only: :func:`encode` and :func:`decode` turn a :class:`Snapshot`
(parameters, labels, the tree's arrays, counters, metadata) into bytes and back, checking the
structure of every field; :func:`write` writes bytes atomically (temporary file in the same
folder, fsync, ``os.replace``) to a regular file only: :func:`check_target` refuses a device, a
FIFO, a socket or a folder at the path (a symlink is followed to the file it names, which is
replaced and the link kept). :class:`rhbl.HypersphereClassifier` (``save``, ``to_bytes``)
and :func:`rhbl.load`/:func:`rhbl.loads` build on it; the consistency of the tree and of the
parameters is checked there, by :meth:`rhbl.SphereTree.from_arrays` and
:meth:`rhbl.HypersphereClassifier.from_tree`. Every problem while reading raises
:class:`SnapshotError` naming the file and the problem.
"""

from __future__ import annotations

import contextlib
import math
import os
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import numpy as np

from ._errors import SnapshotError

__all__ = ["FORMAT", "PARAMS", "VERSION", "Snapshot", "check_target", "decode", "encode", "read",
           "write"]

FORMAT = "rhbl-tree"
VERSION = 1
# the parameters a snapshot stores, in the order written (the classifier's, but ``algorithm``:
# the choice of winner search changes no answer, so it is not part of the tree)
PARAMS = ("default_label", "distance", "spawn", "radius", "min_radius", "max_nodes", "max_depth",
          "clip", "eps")
# the tree's arrays a snapshot stores: field name -> (SphereTree.to_arrays name, dtype)
_ARRAYS = {"centers": ("centers", "<f8"), "radii": ("radii", "<f8"), "parent": ("parent", "<i8"),
           "label_index": ("label", "<i8")}
# the most features a snapshot may declare (a tree of laser features has tens; a declared size
# beyond it is refused before any size is computed from it)
MAX_FEATURES = 1 << 20


@dataclass
class Snapshot:
    """The contents of a snapshot.

    ``arrays`` holds ``centers``, ``radii``, ``parent`` and ``label`` as
    :meth:`rhbl.SphereTree.to_arrays` names them (further arrays are ignored); ``params``
    only names from :data:`PARAMS`.
    """

    params: dict[str, Any]
    labels: list[Any]
    arrays: dict[str, np.ndarray]
    n_seen: int
    n_skipped: int
    n_relabelled: int
    metadata: dict[str, Any]


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


def _to_dict(snap: Snapshot) -> dict[str, Any]:
    """The snapshot map of ``snap`` (before msgpack)."""
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "params": {name: snap.params[name] for name in PARAMS if name in snap.params},
        "n_features": int(snap.arrays["centers"].shape[1]),
        "labels": list(snap.labels),
    }
    for field, (name, dtype) in _ARRAYS.items():
        doc[field] = _array(snap.arrays[name], dtype)
    doc["counters"] = {
        "n_seen": snap.n_seen,
        "n_skipped": snap.n_skipped,
        "n_relabelled": snap.n_relabelled,
    }
    doc["metadata"] = dict(snap.metadata)
    return doc


def encode(snap: Snapshot, *, source: str = "<bytes>") -> bytes:
    """The snapshot as msgpack bytes (``source`` names them in errors)."""
    try:
        return msgpack.packb(_to_dict(snap), default=_default, use_bin_type=True)
    except (TypeError, ValueError, OverflowError) as exc:
        raise SnapshotError(source, f"cannot serialise the snapshot: {exc}") from exc


def check_target(path: Any) -> Path:
    """The file a snapshot written to ``path`` replaces: ``path`` itself, or the file a symlink
    at ``path`` names (followed deliberately: the link is kept and its file replaced, as an
    editor saving through a link does). :class:`SnapshotError` when that is anything but a
    regular file or nothing yet (a device, a FIFO, a socket, a folder: ``os.replace`` would put
    a regular file in its place), or when its folder does not exist. Cheap: callers check their
    output path with it before any work."""
    given = Path(path)
    target = given.resolve() if given.is_symlink() else given
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise SnapshotError(str(given), f"cannot write there: {exc.strerror or exc}") from exc
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = _KINDS.get(stat.S_IFMT(st.st_mode), "not a regular file")
        via = f" (the symlink's target {target})" if target != given else ""
        raise SnapshotError(str(given), f"is {kind}{via}: a snapshot is written only to a "
                                        f"regular file (or a new one); choose another path")
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise SnapshotError(str(given), f"cannot write there: the folder {folder} does not exist")
    return target


_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}


def write(path: Any, data: bytes) -> None:
    """Write ``data`` atomically to the regular file at ``path`` (see :func:`check_target`:
    anything else there is refused with :class:`SnapshotError`, and left as it is)."""
    path = check_target(path)
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


def read(path: Any) -> bytes:
    """The bytes of a snapshot file."""
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise SnapshotError(str(path), f"cannot read: {exc.strerror or exc}") from exc


def decode(data: bytes, *, source: str = "<bytes>") -> Snapshot:
    """The contents of snapshot bytes, their structure checked (``source`` names them in errors)."""
    if not data:
        raise SnapshotError(source, "empty file")
    try:
        doc = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except msgpack.ExtraData:
        raise SnapshotError(source, "trailing data after the snapshot (corrupted)") from None
    except Exception as exc:  # msgpack raises several types for truncated/garbage input
        raise SnapshotError(source, f"truncated or not msgpack ({type(exc).__name__}: {exc})") from None
    return _from_dict(doc, source=source)


def _get(doc: dict, key: str, types: type | tuple, source: str) -> Any:
    if key not in doc:
        raise SnapshotError(source, f"missing field {key!r}")
    value = doc[key]
    if not isinstance(value, types) or types is int and isinstance(value, bool):
        raise SnapshotError(source, f"field {key!r} has type {type(value).__name__}")
    return value


def _is_count(x: Any) -> bool:
    """An integer >= 0 (a boolean is not one)."""
    return isinstance(x, int) and not isinstance(x, bool) and x >= 0


def _read_array(doc: dict, key: str, dtype: str, shape: tuple, source: str) -> np.ndarray:
    spec = _get(doc, key, dict, source)
    if spec.get("dtype") != dtype:
        raise SnapshotError(source, f"array {key!r} has dtype {spec.get('dtype')!r}, expected {dtype!r}")
    declared = spec.get("shape", [])
    if not (isinstance(declared, list) and all(_is_count(d) for d in declared)
            and declared == list(shape)):
        raise SnapshotError(source, f"array {key!r} has shape {declared!r:.80}, expected {list(shape)}")
    raw = spec.get("data")
    if not isinstance(raw, bytes):
        raise SnapshotError(source, f"array {key!r} has no byte data")
    want = math.prod(shape) * np.dtype(dtype).itemsize  # Python ints: no wrap-around
    if len(raw) != want:
        raise SnapshotError(source, f"array {key!r} has {len(raw)} bytes, expected {want} "
                                    f"(shape {list(shape)} of {dtype})")
    return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).astype(dtype[1:], copy=True)


def _from_dict(doc: Any, *, source: str = "<dict>") -> Snapshot:
    """The contents of a decoded snapshot map, the structure of every field checked."""
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
    unknown = set(params) - set(PARAMS)
    if unknown:
        raise SnapshotError(source, f"unknown parameters {sorted(unknown)}")
    n_features = _get(doc, "n_features", int, source)
    labels = _get(doc, "labels", list, source)
    radii_spec = _get(doc, "radii", dict, source)
    shape = radii_spec.get("shape")
    if not (isinstance(shape, list) and len(shape) == 1 and _is_count(shape[0]) and shape[0] >= 1):
        raise SnapshotError(source, f"array 'radii' has an invalid shape {shape!r:.80}")
    n = shape[0]
    if not 1 <= n_features <= MAX_FEATURES:
        raise SnapshotError(source, f"invalid n_features {n_features}: expected 1..{MAX_FEATURES}")
    arrays = {
        name: _read_array(doc, field, dtype, (n, n_features) if field == "centers" else (n,), source)
        for field, (name, dtype) in _ARRAYS.items()
    }
    counters = _get(doc, "counters", dict, source)
    metadata = _get(doc, "metadata", dict, source)
    seen, skipped, relabelled = (counters.get(k) for k in ("n_seen", "n_skipped", "n_relabelled"))
    if not all(_is_count(c) for c in (seen, skipped, relabelled)):
        raise SnapshotError(source, f"invalid counters {counters!r:.120}: expected n_seen, "
                                    f"n_skipped and n_relabelled, integers >= 0")
    return Snapshot(params, labels, arrays, seen, skipped, relabelled, metadata)
