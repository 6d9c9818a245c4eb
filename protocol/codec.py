"""msgpack codec of the rhbl protocol and the field validators its messages use.

Every message is a msgpack map with string keys and an integer protocol version ``v``. Decoding
checks size, type, version and every field it reads, and raises :class:`DecodeError` naming the
field and what was expected; unknown extra fields are ignored (senders may add fields freely).
"""

from __future__ import annotations

import math
from typing import Any

import msgpack

__all__ = [
    "MAX_PAYLOAD",
    "PROTOCOL_VERSION",
    "DecodeError",
    "ProtocolError",
    "get_bool",
    "get_bytes",
    "get_float",
    "get_int",
    "get_opt",
    "get_str",
    "get_vec",
    "pack",
    "pack_value",
    "unpack",
]

PROTOCOL_VERSION = 1
MAX_PAYLOAD = 4 * 1024 * 1024  # bytes; the default limit of ``unpack``
_MAX_STR = 256


class ProtocolError(Exception):
    """Base class of protocol errors."""


class DecodeError(ProtocolError, ValueError):
    """A payload is not a valid message: the text names the field and what was expected."""


def pack(fields: dict[str, Any]) -> bytes:
    """Encode a map (``v`` is added) as msgpack bytes."""
    out = {"v": PROTOCOL_VERSION}
    out.update(fields)
    return msgpack.packb(out, use_bin_type=True)


def pack_value(value: Any) -> bytes:
    """One value as msgpack bytes, as :func:`pack` encodes it inside a map (a message's parts
    packed once: ``protocol.messages.VelCmdPacker``)."""
    return msgpack.packb(value, use_bin_type=True)


def unpack(data: Any, what: str = "message", max_size: int = MAX_PAYLOAD) -> dict[str, Any]:
    """Decode msgpack bytes into a map, checking size, type and protocol version."""
    if hasattr(data, "to_bytes"):  # zenoh.ZBytes
        data = data.to_bytes()
    if isinstance(data, bytearray | memoryview):
        data = bytes(data)
    if not isinstance(data, bytes):
        raise DecodeError(f"{what}: expected bytes, got {type(data).__name__}")
    if len(data) > max_size:
        raise DecodeError(f"{what}: payload of {len(data)} bytes exceeds the {max_size}-byte limit")
    try:
        obj = msgpack.unpackb(
            data,
            raw=False,
            strict_map_key=True,
            max_str_len=max_size,
            max_bin_len=max_size,
            max_array_len=max(1024, max_size // 8),
            max_map_len=1024,
        )
    except Exception as e:  # msgpack raises several types (ExtraData, ValueError, ...)
        raise DecodeError(f"{what}: not valid msgpack ({type(e).__name__}: {e})") from None
    if not isinstance(obj, dict):
        raise DecodeError(f"{what}: expected a msgpack map, got {type(obj).__name__}")
    v = obj.get("v")
    if isinstance(v, bool) or not isinstance(v, int):
        raise DecodeError(
            f"{what}: field 'v': expected the protocol version (an integer), got {v!r}"
        )
    if v != PROTOCOL_VERSION:
        raise DecodeError(
            f"{what}: field 'v': unsupported protocol version {v}, expected {PROTOCOL_VERSION}"
        )
    return obj


def _missing(what: str, name: str, expected: str) -> DecodeError:
    return DecodeError(f"{what}: field '{name}': missing, expected {expected}")


def _bad(what: str, name: str, expected: str, got: Any) -> DecodeError:
    text = repr(got)
    if len(text) > 80:
        text = text[:77] + "..."
    return DecodeError(f"{what}: field '{name}': expected {expected}, got {text}")


_NOVALUE = object()


def get_opt(m: dict, name: str, getter, what: str, *args, default=None, **kw):
    """``getter(m, name, ...)`` if the field is present and not nil, else ``default``."""
    if m.get(name) is None:
        return default
    return getter(m, name, what, *args, **kw)


def get_float(m: dict, name: str, what: str, finite: bool = True) -> float:
    x = m.get(name, _NOVALUE)
    if x is _NOVALUE:
        raise _missing(what, name, "a number")
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise _bad(what, name, "a number", x)
    x = float(x)
    if finite and not math.isfinite(x):
        raise _bad(what, name, "a finite number", x)
    return x


def get_int(m: dict, name: str, what: str, minimum: int | None = None) -> int:
    x = m.get(name, _NOVALUE)
    if x is _NOVALUE:
        raise _missing(what, name, "an integer")
    if isinstance(x, bool) or not isinstance(x, int):
        raise _bad(what, name, "an integer", x)
    if minimum is not None and x < minimum:
        raise _bad(what, name, f"an integer >= {minimum}", x)
    return int(x)


def get_bool(m: dict, name: str, what: str) -> bool:
    x = m.get(name, _NOVALUE)
    if x is _NOVALUE:
        raise _missing(what, name, "true or false")
    if not isinstance(x, bool):
        raise _bad(what, name, "true or false", x)
    return x


def get_str(m: dict, name: str, what: str, max_len: int = _MAX_STR) -> str:
    x = m.get(name, _NOVALUE)
    if x is _NOVALUE:
        raise _missing(what, name, "a string")
    if not isinstance(x, str):
        raise _bad(what, name, "a string", x)
    if len(x) > max_len:
        raise _bad(what, name, f"a string of at most {max_len} characters", f"{len(x)} characters")
    return x


def get_vec(m: dict, name: str, what: str, n: int, finite: bool = True) -> tuple[float, ...]:
    x = m.get(name, _NOVALUE)
    expected = f"a list of {n} {'finite ' if finite else ''}numbers"
    if x is _NOVALUE:
        raise _missing(what, name, expected)
    if not isinstance(x, list | tuple) or len(x) != n:
        raise _bad(what, name, expected, x)
    out = []
    for e in x:
        if isinstance(e, bool) or not isinstance(e, int | float):
            raise _bad(what, name, expected, x)
        e = float(e)
        if finite and not math.isfinite(e):
            raise _bad(what, name, expected, x)
        out.append(e)
    return tuple(out)


def get_bytes(m: dict, name: str, what: str) -> bytes:
    x = m.get(name, _NOVALUE)
    if x is _NOVALUE:
        raise _missing(what, name, "bytes")
    if not isinstance(x, bytes):
        raise _bad(what, name, "bytes (msgpack bin)", type(x).__name__)
    return x
