"""The checksum of the laser's kernel source (numba-free, for the kernels' loader): kernels
compiled ahead of time (``server._laser_aot``, built by ``setup.py``) are used only while they
were compiled from this checkout's ``server/_laser_kernels.py``."""

from __future__ import annotations

import zlib
from pathlib import Path

__all__ = ["source_hash"]


def source_hash() -> int:
    """CRC-32 of ``_laser_kernels.py``, as the ahead-of-time build records it."""
    return zlib.crc32((Path(__file__).parent / "_laser_kernels.py").read_bytes())
