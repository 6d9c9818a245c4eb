"""Recursive, Hyperspherical Behavioral Learning: the hypersphere tree and its snapshots.

```python
from rhbl import HypersphereClassifier, load
clf = HypersphereClassifier(default_label="fwd").fit(X, y)
clf.predict_one(x); clf.save("tree.rhbl"); clf2 = load("tree.rhbl")
```
See ``docs/rhbl.md``. This package imports only numpy, msgpack and (with the first classifier
made) numba.
"""

from ._errors import NotFittedError, RhblError, SnapshotError
from .classifier import HypersphereClassifier, load, loads
from .snapshot import FORMAT, VERSION
from .tree import SphereTree

__all__ = [
    "FORMAT",
    "VERSION",
    "HypersphereClassifier",
    "NotFittedError",
    "RhblError",
    "SnapshotError",
    "SphereTree",
    "load",
    "loads",
]
