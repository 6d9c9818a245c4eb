"""Typed exceptions of the ``rhbl`` package."""

from __future__ import annotations

__all__ = ["NotFittedError", "RhblError", "SnapshotError"]


class RhblError(Exception):
    """Base class of every error raised on purpose by ``rhbl``."""


class NotFittedError(RhblError, ValueError, AttributeError):
    """The classifier was used before any training (like scikit-learn's ``NotFittedError``)."""


class SnapshotError(RhblError, ValueError):
    """A snapshot could not be read or written.

    The message names the file (or ``<bytes>``) and the problem, for example
    ``"tree.rhbl: truncated or not msgpack (...)"`` or
    ``"tree.rhbl: snapshot version 2 is newer than this reader (1)"``.
    """

    def __init__(self, source: str, problem: str) -> None:
        super().__init__(f"{source}: {problem}")
        self.source = source
        self.problem = problem
