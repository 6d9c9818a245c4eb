"""The layout of the tree's two tables, shared by :mod:`rhbl.tree` and the kernels.

Both tables hold 8-byte cells (int64; the float columns are read through a float64 view of the
same memory), a row per sphere, the centre in columns ``0 .. features - 1`` and the radius in
column ``features``; the integer columns follow, numbered here from ``features + 1``.

* The node table (:class:`rhbl.tree.SphereTree`'s, in creation order, grown by doubling):
  parent (-1 for the root), depth, label index and the children as a linked list in creation
  order (first child, next sibling, last child; -1 for none). A per-sphere value added later
  is one more column (``INT_COLUMNS`` grows); a kernel reads only the columns it names.
* The search table (built from the node table when the tree is searched, flat, in depth-first
  pre-order): ``SKIP``, the position just after the sphere's subtree, and ``RANK``, the
  sphere's place in the winner order (smallest radius, then deepest, then earliest created:
  the lower rank wins) and ``BOUND``, the lowest rank in the sphere's subtree (a search that
  holds a better winner skips the subtree untested); a second array gives each position's
  creation index.

This module imports nothing (the kernels' loader reads it without numba), and
:func:`source_hash` names the kernels' code, so that kernels compiled ahead of time are used
only while they are the code of this checkout.
"""

from __future__ import annotations

import zlib
from pathlib import Path

__all__ = ["INT_COLUMNS", "SEARCH_INT_COLUMNS", "SPECIALISED", "source_hash"]

# the node table's integer columns
PARENT, DEPTH, LABEL, FIRST, NEXT, LAST = range(6)
INT_COLUMNS = 6
# the search table's integer columns
SKIP, RANK, BOUND = range(3)
SEARCH_INT_COLUMNS = 3
# feature counts whose searches have kernels of their own, compiled ahead of time (the loop over
# the features unrolled: about a quarter faster): the shipped feature specs' (5 beams, and 5
# beams with the heading); other counts use the general kernel. Each count is two more kernels
# to compile at install.
SPECIALISED = (5, 6)

# the files whose code the kernels are
SOURCES = ("_layout.py", "_kernels.py")


def source_hash() -> int:
    """A checksum (CRC-32) of the kernels' source files, as the ahead-of-time build records
    it."""
    here = Path(__file__).parent
    crc = 0
    for name in SOURCES:
        crc = zlib.crc32((here / name).read_bytes(), crc)
    return crc
