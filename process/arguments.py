"""Checked command-line values: the argparse ``type=`` of every option of every ``rhbl`` command.

A bad value is refused by the parser itself, before the command does any work or opens a
connection: one line naming the option and what was allowed, exit 2 (``lab.cli``'s parser
prints no usage block). Give every option that takes a value one of these (or ``choices``)::

    parser.add_argument("--seconds", type=seconds, ...)             # > 0, finite, at most MAX_SECONDS
    parser.add_argument("--wait", type=seconds_or_zero, ...)        # 0 means "for ever" / "off"
    parser.add_argument("--episodes", type=positive_int, ...)
    parser.add_argument("--perturb", type=fraction, ...)            # 0 .. 1
    parser.add_argument("--out", type=output_file, ...)             # process.files' rule
    parser.add_argument("--tree", type=input_file, ...)             # an existing regular file
    parser.add_argument("--robot", type=key_chunk, ...)             # protocol.keys.check_chunk
    parser.add_argument("--gain", type=Number(float, low=0.5, high=2.0), ...)  # your own range

Each type is a :class:`Checked` with a ``kind`` (``number``, ``input``, ``output``, ``folder``,
``chunk``, ``text``, ``endpoint``, ``address``, ``host``, ``list``) and, for numbers, its range:
tests/test_cli_walk.py walks every option of every command with hostile values made from them
(negative, zero, NaN, infinities, huge, empty, a FIFO, a device, a folder, a missing folder,
...), so a new option is covered by that test as soon as it has a type from here. An option whose
values are checked elsewhere has no place: a check in ``main`` runs after the parse, often after
a connection.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from process import files
from protocol import keys

__all__ = [
    "MAX_SECONDS",
    "Checked",
    "Number",
    "PathArg",
    "address",
    "checked_list",
    "endpoint",
    "fraction",
    "host",
    "input_file",
    "key_chunk",
    "key_path",
    "non_negative_float",
    "non_negative_int",
    "output_file",
    "output_file_or_default",
    "output_folder",
    "port",
    "positive_float",
    "positive_int",
    "seconds",
    "seconds_or_zero",
    "seed",
    "syntax_only",
    "text",
    "token",
]

# the longest duration an option takes (about 31 years): beyond it time.sleep and
# threading's timeouts overflow
MAX_SECONDS = 1e9
MAX_INT = 2**31 - 1  # counts, sizes and seeds: beyond it a value is a typing error


class Checked:
    """An argparse ``type``: ``parse(text)`` returns the value or raises ValueError with the
    reason; argparse then says ``argument --opt: <reason>``. ``kind`` tells the CLI walk test
    which hostile values to try; ``example`` is a valid value (for the test's other options)."""

    kind = "text"
    example = "x"
    empty_ok = False  # "" is a value (meaning "none"), not a mistake

    def __init__(self, name: str, parse: Callable[[str], Any] | None = None):
        self.__name__ = name  # argparse names the type with it
        self._parse = parse

    def parse(self, text: str) -> Any:
        return self._parse(text) if self._parse is not None else text

    def __call__(self, text: str) -> Any:
        try:
            return self.parse(text)
        except argparse.ArgumentTypeError:
            raise
        except (ValueError, OverflowError) as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    def __repr__(self) -> str:
        return self.__name__


class Number(Checked):
    """A finite number (``cast``: int or float) in ``[low, high]`` (``low_open``: ``low``
    itself refused). NaN and infinities are always refused."""

    kind = "number"

    def __init__(self, cast: type, low: float | None = None, high: float | None = None, *,
                 low_open: bool = False, name: str | None = None, note: str = ""):
        super().__init__(name or cast.__name__)
        self.cast, self.low, self.high, self.low_open, self.note = cast, low, high, low_open, note
        if low is None:
            self.example = "1"
        else:
            v = low + 1 if low_open else low
            self.example = f"{int(v)}" if cast is int else f"{v:g}"

    def describe(self) -> str:
        what = "an integer" if self.cast is int else "a finite number"
        show = (lambda v: f"{int(v)}") if self.cast is int else (lambda v: f"{v:g}")
        parts = []
        if self.low is not None:
            parts.append(f"{'>' if self.low_open else '>='} {show(self.low)}")
        if self.high is not None:
            parts.append(f"<= {show(self.high)}")
        return f"{what}{' ' + ' and '.join(parts) if parts else ''}{self.note}"

    def parse(self, text: str) -> Any:
        try:
            value = self.cast(text.strip()) if self.cast is int else float(text)
        except (ValueError, OverflowError):
            raise ValueError(f"must be {self.describe()}, got {text!r}") from None
        if self.cast is not int and not math.isfinite(value):
            raise ValueError(f"must be {self.describe()}, got {text!r}")
        low_bad = self.low is not None and (value < self.low or (self.low_open and
                                                                 value == self.low))
        if low_bad or (self.high is not None and value > self.high):
            raise ValueError(f"must be {self.describe()}, got {text!r}")
        return value


positive_float = Number(float, 0, low_open=True, name="positive number")
non_negative_float = Number(float, 0, name="non-negative number")
fraction = Number(float, 0, 1, name="fraction")
positive_int = Number(int, 1, MAX_INT, name="positive integer")
non_negative_int = Number(int, 0, MAX_INT, name="non-negative integer")
seed = Number(int, 0, 2**32 - 1, name="seed")
port = Number(int, 0, 65535, name="port", note=" (0: any free port)")
seconds = Number(float, 0, MAX_SECONDS, low_open=True, name="seconds")
seconds_or_zero = Number(float, 0, MAX_SECONDS, name="seconds")


_files_checked = True  # False inside ``syntax_only()``


@contextlib.contextmanager
def syntax_only() -> Iterator[None]:
    """Parse a command line meant for another machine (a compose file's, whose paths exist in
    its containers): inside this block the path types check the text only, not the files."""
    global _files_checked
    before, _files_checked = _files_checked, False
    try:
        yield
    finally:
        _files_checked = before


def files_checked() -> bool:
    """Whether path arguments are checked against the file system (see ``syntax_only``)."""
    return _files_checked


class PathArg(Checked):
    """A path under ``process.files``' rule: ``kind`` ``input`` (an existing regular file),
    ``output`` (a regular file or a new one; its folder is made) or ``folder`` (a folder, or a
    new one: made by the command)."""

    def __init__(self, kind: str, empty_ok: bool = False):
        super().__init__(f"{kind} path")
        self.kind, self.empty_ok = kind, empty_ok

    def parse(self, text: str) -> str:
        if text == "" and self.empty_ok:
            return text
        if not _files_checked:
            if not text:
                raise ValueError("an empty path")
            return text
        if self.kind == "input":
            files.check_input(text)
        elif self.kind == "output":
            files.check_output(text)
        else:
            _check_folder(text)
        return text


def _check_folder(text: str) -> None:
    if not text:
        raise ValueError("an empty path")
    p = Path(text)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        parent = next((q for q in p.absolute().parents if q.exists()), None)
        if parent is None or not parent.is_dir():
            raise ValueError(f"{text}: cannot be made ({parent} is not a folder)") from None
        return
    except OSError as exc:
        raise ValueError(f"{text}: {exc.strerror or exc}") from exc
    if not stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{text}: is {files.kind_of(st.st_mode)}, not a folder")


input_file = PathArg("input")
output_file = PathArg("output")
output_folder = PathArg("folder")
# ``nargs="?", const=""``: a file, or "" for the command's default one (argparse types the const)
output_file_or_default = PathArg("output", empty_ok=True)


def _chunk(text: str) -> str:
    try:
        return keys.check_chunk(text)
    except ValueError:
        raise ValueError(f"must be a non-empty key chunk of letters, digits, '_', '-', '.', "
                         f"got {text!r}") from None


key_chunk = Checked("name", _chunk)
key_chunk.kind, key_chunk.example = "chunk", "r0"


def _key_path(text: str) -> str:
    for part in text.split("/"):
        keys.check_chunk(part, "each '/'-separated part")
    return text


key_path = Checked("key path", _key_path)  # plain key chunks joined by '/': no wildcard
key_path.kind, key_path.example = "chunk", "test/a"

_PRINTABLE = re.compile(r"^[^\x00-\x1f\x7f]{1,1000}$")


def _text(value: str) -> str:
    if not _PRINTABLE.match(value):
        raise ValueError(f"must be 1 to 1000 printable characters (no control characters), "
                         f"got {value[:60]!r}{'...' if len(value) > 60 else ''}")
    return value


text = Checked("text", _text)


def _token(value: str) -> str:
    return value if value == "" else _text(value)


token = Checked("token", _token)  # an access token; "" = none given (a compose default)
token.empty_ok = True

_PORTED = ("tcp", "udp", "tls", "quic", "ws")
_HOST = re.compile(r"^(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.\-]+)$")


def _host(value: str) -> str:
    if not _HOST.match(value) or value.startswith("-"):
        raise ValueError(f"must be a host name or an IP address, got {value!r}")
    return value


def _address(value: str) -> str:
    """``HOST:PORT`` (``[v6]:PORT`` too)."""
    h, sep, p = value.rpartition(":")
    if not sep or not h or not p.isdigit() or not 0 <= int(p) <= 65535:
        raise ValueError(f"must be HOST:PORT with a port 0..65535 (e.g. 127.0.0.1:8080), "
                         f"got {value!r}")
    _host(h)
    return value


def _endpoint(value: str) -> str:
    """A zenoh endpoint (``tcp/127.0.0.1:7447``), or a comma list of them."""
    for ep in (e.strip() for e in value.split(",")):
        proto, sep, rest = ep.partition("/")
        if not sep or not re.match(r"^[a-z][a-z0-9\-]*$", proto) or not rest:
            raise ValueError(f"must be a zenoh endpoint PROTOCOL/ADDRESS (e.g. "
                             f"tcp/127.0.0.1:7447), got {ep!r}")
        if proto in _PORTED:
            addr = rest.split("#", 1)[0].split("?", 1)[0]
            try:
                _address(addr)
            except ValueError:
                raise ValueError(f"{proto} endpoint must be {proto}/HOST:PORT with a port "
                                 f"0..65535, got {ep!r}") from None
    return value


host = Checked("host", _host)
host.kind, host.example = "host", "127.0.0.1"
address = Checked("address", _address)
address.kind, address.example = "address", "127.0.0.1:0"
endpoint = Checked("endpoint", _endpoint)
endpoint.kind, endpoint.example = "endpoint", "tcp/127.0.0.1:7447"


def checked_list(name: str, parse: Callable[[str], Any], example: str) -> Checked:
    """A comma list parsed by ``parse`` (``kind`` ``list``: the walk tries non-numbers, NaN,
    infinities, negatives and zero in it)."""
    c = Checked(name, parse)
    c.kind, c.example = "list", example
    return c
