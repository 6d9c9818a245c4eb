"""The files a person names on a command line: the one rule for reading and for writing them.

Every rhbl process checks the files it is given with these, before any work or connection
(``process.arguments`` calls them as argparse types), and writes and opens through them, so the
rule also holds when the file changed in between:

- **written** (``--out``, ``--json``, ``--plot``, ``--stats``, ``--record``, a journal): only to a
  regular file or a new one. A symlink is followed to the file it names (that file is replaced,
  the link kept). A device, a FIFO, a socket or a folder at the path is refused and left as it
  is; its folder is made by the writer when missing (refused when that cannot be done).
  :func:`check_output` checks, :func:`replace_file` and :func:`write_text` write atomically (a
  temporary file beside it, fsync, ``os.replace``), :func:`open_output` opens a file to append
  to or to create (a recording).
- **read** (a snapshot, a recording, a world, a zenoh config): only a regular file.
  :func:`check_input` checks, :func:`open_input` opens without blocking on a FIFO and checks the
  file it opened.

Every refusal is a :class:`FileRuleError` (a ``ValueError``: one line naming the path and what
is wrong, exit 2 at the command line). ``rhbl.snapshot.check_target`` applies the same rule to
snapshots inside the algorithm package, which imports nothing of ours.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = [
    "FileRuleError",
    "check_input",
    "check_output",
    "kind_of",
    "open_input",
    "open_output",
    "replace_file",
    "write_text",
]

_KINDS = {stat.S_IFCHR: "a character device", stat.S_IFBLK: "a block device",
          stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder",
          stat.S_IFLNK: "a symlink"}


class FileRuleError(ValueError):
    """A path that cannot be read or written under the rule above; names the path."""


def kind_of(mode: int) -> str:
    """What a file of this ``st_mode`` is, in words (``"a FIFO"``, ``"a regular file"``)."""
    return "a regular file" if stat.S_ISREG(mode) else _KINDS.get(stat.S_IFMT(mode),
                                                                  "not a regular file")


def _target(path: Path) -> Path:
    """The file that writing ``path`` changes: the symlink's target, followed."""
    return path.resolve() if path.is_symlink() else path


def check_output(path: str | os.PathLike, what: str = "", *, make: bool = False) -> Path:
    """The file that writing ``path`` replaces or creates (a symlink followed); FileRuleError
    when it is anything but a regular file or nothing yet, or its folder cannot be made.
    ``what`` (an option, ``--out``) prefixes the message. Changes nothing unless ``make``:
    then the missing folders are made (the writers do that, not the check)."""
    given = Path(path)
    label = f"{what} {given}" if what else str(given)
    if not str(path):
        raise FileRuleError(f"{what or 'path'}: an empty path")
    target = _target(given)
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise FileRuleError(f"{label}: cannot write there: {exc.strerror or exc}") from exc
    if st is not None and not stat.S_ISREG(st.st_mode):
        via = f" (the symlink's target {target})" if target != given else ""
        raise FileRuleError(f"{label}: is {kind_of(st.st_mode)}{via}: only a regular file (or "
                            f"a new one) is written; choose another path")
    folder = target.parent if str(target.parent) else Path(".")
    if make:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except FileExistsError:
            raise FileRuleError(f"{label}: cannot write there: {folder} is not a "
                                f"folder") from None
        except OSError as exc:
            raise FileRuleError(f"{label}: cannot make its folder {folder}: "
                                f"{exc.strerror or exc}") from exc
    existing = next((q for q in (folder.absolute(), *folder.absolute().parents)
                     if os.path.lexists(q)), Path("/"))
    if not existing.is_dir():
        raise FileRuleError(f"{label}: cannot write there: {existing} is not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise FileRuleError(f"{label}: {'its folder ' if existing == folder.absolute() else ''}"
                            f"{existing} is not writable")
    return target


def check_input(path: str | os.PathLike, what: str = "") -> Path:
    """``path`` if it is a regular file (a symlink to one too) that exists; FileRuleError
    naming it otherwise (missing, a folder, a FIFO, a device, a socket). Opens nothing."""
    given = Path(path)
    label = f"{what} {given}" if what else str(given)
    if not str(path):
        raise FileRuleError(f"{what or 'path'}: an empty path")
    try:
        st = os.stat(given)
    except FileNotFoundError:
        raise FileRuleError(f"{label} does not exist") from None
    except OSError as exc:
        raise FileRuleError(f"{label}: cannot read it: {exc.strerror or exc}") from exc
    if not stat.S_ISREG(st.st_mode):
        raise FileRuleError(f"{label}: is {kind_of(st.st_mode)}, not a file to read")
    return given


def open_input(path: str | os.PathLike, what: str = "") -> IO[bytes]:
    """``path`` opened for reading (binary, buffered) if it is a regular file: opened without
    blocking (a FIFO with no writer would block for ever) and checked again on the open file
    (it may have changed since it was checked). FileRuleError otherwise."""
    given = Path(path)
    label = f"{what} {given}" if what else str(given)
    try:
        fd = os.open(given, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise FileRuleError(f"{label} does not exist") from None
    except OSError as exc:
        raise FileRuleError(f"{label}: cannot open it: {exc.strerror or exc}") from exc
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileRuleError(f"{label}: is {kind_of(mode)}, not a file to read")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def open_output(path: str | os.PathLike, *, overwrite: bool, what: str = "") -> int:
    """A file descriptor of ``path`` opened for writing (created 0644, truncated when
    ``overwrite``, else it must not exist), refused unless it is a regular file: checked before
    (:func:`check_output`) and on the open file. FileExistsError when it exists and not
    ``overwrite``; FileRuleError for the rule."""
    target = check_output(path, what, make=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    flags |= os.O_TRUNC if overwrite else os.O_EXCL
    if overwrite:  # truncate only what is checked to be a regular file: no O_TRUNC on a device
        flags &= ~os.O_TRUNC
    fd = os.open(target, flags, 0o644)
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileRuleError(f"{what + ' ' if what else ''}{path}: is {kind_of(mode)}: "
                                f"only a regular file (or a new one) is written")
        if overwrite:
            os.ftruncate(fd, 0)
        os.set_blocking(fd, True)
        return fd
    except BaseException:
        os.close(fd)
        raise


@contextlib.contextmanager
def replace_file(path: str | os.PathLike, what: str = "") -> Iterator[Path]:
    """A temporary path beside ``path``'s target to write the new file to; when the block ends
    without an error it is fsynced and put in place with ``os.replace`` (a reader sees the old
    file or the new one, never half), else removed. The target is checked first
    (:func:`check_output`)."""
    target = check_output(path, what, make=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike, text: str, what: str = "") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically under the rule (:func:`replace_file`);
    the file written."""
    with replace_file(path, what) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
