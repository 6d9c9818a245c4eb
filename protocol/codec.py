"""msgpack codec of the rhbl protocol, the field validators its messages use, and the one
statement of a message's map they are derived from.

Every message is a msgpack map with string keys and an integer protocol version ``v``. Decoding
checks size, type, version and every field it reads, and raises :class:`DecodeError` naming the
field and what was expected; unknown extra fields are ignored (senders may add fields freely).

A message states each field once, as a dataclass field made by :func:`wire` with the field's
:class:`Kind` (``Number()``, ``Integer(minimum=0)``, ``String(max_len=64)``, ``Vector(3)``,
...)::

    @message                                     # protocol.messages: dataclass + Layout
    class Pose(_Message):
        ts: float = wire(Number())               # required: no default
        pose: tuple = wire(Vector(3))
        note: str = wire(String(), default="")   # optional on the wire, "" when absent

and :class:`Layout` derives the rest from those fields: the JSON-schema fragments (``FIELDS``),
``REQUIRED``, the map ``to_map`` writes (in the fields' order; a field whose default is None is
left out when None) and ``from_map``'s checks (a missing required field, a field of the wrong
kind: each a ``DecodeError`` naming it).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import msgpack

__all__ = [
    "MAX_PAYLOAD",
    "PROTOCOL_VERSION",
    "Boolean",
    "Const",
    "DecodeError",
    "Integer",
    "IntegerList",
    "Kind",
    "Layout",
    "Number",
    "ProtocolError",
    "Records",
    "Rest",
    "String",
    "Vector",
    "VectorList",
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
    "wire",
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


# ---- the one statement of a message's fields ------------------------------------------------
class Kind:
    """How one field's value goes on the wire: ``schema`` its JSON-schema fragment, ``expected``
    what it must be (said when it is missing), ``write(value)`` the value as it is packed,
    ``read(x, key, what)`` a wire value checked (a ``DecodeError`` naming the field ``key`` of
    ``what`` and what was expected) and converted. ``nil_absent``: an optional field given as
    nil is taken as absent (lists are not: a nil list is refused)."""

    schema: dict = {}
    expected: str = "a value"
    nil_absent: bool = True
    inline: str = ""  # ``write`` as an expression of ``{}`` (the value), if it has one

    def write(self, value: Any) -> Any:
        return value

    def read(self, x: Any, key: str, what: str) -> Any:  # pragma: no cover - overridden
        raise NotImplementedError

    def missing(self, key: str, what: str) -> DecodeError:
        return _missing(what, key, self.expected)


class Number(Kind):
    """A number (an integer is taken as a float), finite unless ``finite=False``."""

    expected = "a number"
    inline = "float({})"

    def __init__(self, finite: bool = True) -> None:
        self.finite = finite
        self.schema = {"type": "number"}
        self.write = float

    def read(self, x, key, what):
        if type(x) is float and (x - x == 0.0 or not self.finite):  # x - x: NaN unless finite
            return x
        return get_float({key: x}, key, what, self.finite)


class Integer(Kind):
    """An integer (never a boolean), at least ``minimum`` if given."""

    expected = "an integer"
    inline = "int({})"

    def __init__(self, minimum: int | None = None) -> None:
        self.minimum = minimum
        self.schema = ({"type": "integer"} if minimum is None
                       else {"type": "integer", "minimum": minimum})
        self.write = int

    def read(self, x, key, what):
        if type(x) is int and (self.minimum is None or x >= self.minimum):
            return x
        return get_int({key: x}, key, what, self.minimum)


class Boolean(Kind):
    """True or false."""

    expected = "true or false"
    inline = "bool({})"

    def __init__(self) -> None:
        self.schema = {"type": "boolean"}
        self.write = bool

    def read(self, x, key, what):
        if x is True or x is False:
            return x
        return get_bool({key: x}, key, what)


class String(Kind):
    """A string of at most ``max_len`` characters (and not empty if ``non_empty``)."""

    expected = "a string"
    inline = "str({})"

    def __init__(self, max_len: int = _MAX_STR, non_empty: bool = False) -> None:
        self.max_len, self.non_empty = max_len, non_empty
        self.schema = ({"type": "string", "minLength": 1, "maxLength": max_len} if non_empty
                       else {"type": "string", "maxLength": max_len})
        self.write = str

    def read(self, x, key, what):
        if type(x) is not str or len(x) > self.max_len:
            x = get_str({key: x}, key, what, self.max_len)
        if self.non_empty and not x:
            raise DecodeError(f"{what}: field '{key}': expected a non-empty string, got ''")
        return x


class Vector(Kind):
    """A list of ``n`` finite numbers, as a tuple of floats."""

    inline = "[float(e) for e in {}]"

    def __init__(self, n: int) -> None:
        self.n = n
        self.expected = f"a list of {n} finite numbers"
        self.schema = {"type": "array", "items": {"type": "number"}, "minItems": n,
                       "maxItems": n}

    def write(self, value):
        return [float(x) for x in value]

    def read(self, x, key, what):
        if type(x) is list and len(x) == self.n:
            for e in x:
                if type(e) is not float or e - e != 0.0:
                    break
            else:
                return tuple(x)
        return get_vec({key: x}, key, what, self.n)


class VectorList(Kind):
    """A list of ``Vector(n)`` (each checked as one), as a tuple of tuples."""

    nil_absent = False

    def __init__(self, n: int) -> None:
        self.item = Vector(n)
        self.expected = f"a list of [{n} numbers]"
        self.schema = {"type": "array", "items": self.item.schema}

    def write(self, value):
        return [[float(x) for x in v] for v in value]

    def read(self, x, key, what):
        if not isinstance(x, list | tuple):
            raise DecodeError(f"{what}: field '{key}': expected {self.expected}, "
                              f"got {type(x).__name__}")
        return tuple(self.item.read(e, key, what) for e in x)


class IntegerList(Kind):
    """A list of at most ``max_items`` integers, each at least ``minimum`` (given to ``read``:
    another field's value, say), as a tuple."""

    nil_absent = False

    def __init__(self, max_items: int) -> None:
        self.max_items = max_items
        self.expected = f"a list of at most {max_items} integers"
        self.schema = {"type": "array", "items": {"type": "integer", "minimum": 0},
                       "maxItems": max_items}

    def write(self, value):
        return [int(x) for x in value]

    def read(self, x, key, what, minimum: int = 0):
        if not isinstance(x, list | tuple) or len(x) > self.max_items:
            of = f" of {len(x)}" if isinstance(x, list | tuple) else ""
            raise DecodeError(f"{what}: field '{key}': expected {self.expected}, "
                              f"got {type(x).__name__}{of}")
        return tuple(get_int({key: e}, key, what, minimum=minimum) for e in x)


class Records(Kind):
    """A list of at most ``max_items`` maps, each with the fields ``fields`` (name -> ``Kind``,
    all required; other keys of an item are ignored), as a tuple of ``record(**fields)`` (a
    NamedTuple, say); written from such records (their attributes) as maps."""

    nil_absent = False

    def __init__(self, fields: dict[str, Kind], record: Any, max_items: int) -> None:
        self.item_kinds, self.record, self.max_items = dict(fields), record, int(max_items)
        names = ", ".join(fields)
        self.expected = f"a list of at most {max_items} maps of {names}"
        self.schema = {"type": "array", "maxItems": max_items,
                       "items": {"type": "object",
                                 "properties": {k: kind.schema for k, kind in fields.items()},
                                 "required": list(fields)}}

    def write(self, value):
        kinds = self.item_kinds
        return [{k: kind.write(getattr(r, k)) for k, kind in kinds.items()} for r in value]

    def read(self, x, key, what):
        if not isinstance(x, list | tuple) or len(x) > self.max_items:
            of = f" of {len(x)}" if isinstance(x, list | tuple) else ""
            raise DecodeError(f"{what}: field '{key}': expected {self.expected}, "
                              f"got {type(x).__name__}{of}")
        out = []
        for i, item in enumerate(x):
            name = f"{key}[{i}]"
            if not isinstance(item, dict):
                raise DecodeError(f"{what}: field '{name}': expected a map of "
                                  f"{', '.join(self.item_kinds)}, got {item!r:.80}")
            values = {}
            for k, kind in self.item_kinds.items():
                if k not in item:
                    raise kind.missing(f"{name}.{k}", what)
                values[k] = kind.read(item[k], f"{name}.{k}", what)
            out.append(self.record(**values))
        return tuple(out)


class Const(Kind):
    """A constant written with every message (``ok``: true in an ack); if ``checked``, a map
    without exactly it is refused."""

    def __init__(self, value: Any, checked: bool = True) -> None:
        self.value, self.checked = value, checked
        self.schema = {"const": value}
        self.expected = {True: "true", False: "false"}.get(value, repr(value))

    def write(self, value):
        return self.value

    def read(self, x, key, what):
        if self.checked and x is not self.value:
            raise DecodeError(f"{what}: field '{key}': expected {self.expected}, got {x!r}")
        return self.value

    def missing(self, key, what):
        return DecodeError(f"{what}: field '{key}': expected {self.expected}, got None")


class Rest(Kind):
    """Every field of the map not stated (a dict): written first, read as it came."""


_NO_DEFAULT = dataclasses.MISSING
_AS_DEFAULT = object()


@dataclasses.dataclass(frozen=True)
class Wire:
    """A field's place on the wire (``wire()`` puts it in the dataclass field's metadata)."""

    kind: Kind
    key: str | None = None  # the wire name: the attribute's unless given
    required: bool | None = None  # None: required when the constructor requires it
    absent: Any = _AS_DEFAULT  # the value of an optional field left out
    part: int | None = None  # this attribute is element ``part`` of a Vector field ``key``
    omit_false: bool = False  # left out when false (as when None)
    own: bool = False  # read by the message's own ``_read_own`` (rules across fields)


def wire(kind: Kind, *, default: Any = _NO_DEFAULT, default_factory: Any = _NO_DEFAULT,
         required: bool | None = None, absent: Any = _AS_DEFAULT, key: str | None = None,
         part: int | None = None, omit_false: bool = False, own: bool = False,
         **field_kw) -> Any:
    """A message's dataclass field stated once: its ``kind`` on the wire, its constructor
    ``default``; ``required`` on the wire (default: when the constructor requires it);
    ``absent`` the value decoded when an optional field is left out (default: ``default``);
    ``key`` its wire name (default: the attribute's); ``part`` its index in a vector shared by
    several attributes (``VelCmd``'s ``vel``); ``omit_false`` written only when true;
    ``own``: decoded by the message's ``_read_own``. Other keywords go to
    ``dataclasses.field`` (``kw_only``, ``init``, ``repr``, ...)."""
    meta = {"wire": Wire(kind, key, required, absent, part, omit_false, own)}
    return dataclasses.field(default=default, default_factory=default_factory, metadata=meta,
                             **field_kw)


class Layout:
    """A message's map, derived from its dataclass fields made by :func:`wire`, in their order:
    ``fields`` (wire name -> JSON-schema fragment), ``kinds`` (wire name -> ``Kind``),
    ``required``, ``write(obj)`` (the map), ``read(m, what)`` (the constructor's keywords,
    every field checked but those read by the message itself)."""

    def __init__(self, cls: type) -> None:
        groups: dict[str, list] = {}  # wire name -> [(part, attribute, Wire, field)]
        for f in dataclasses.fields(cls):
            w = f.metadata.get("wire")
            if w is not None:
                groups.setdefault(w.key or f.name, []).append((w.part or 0, f.name, w, f))
        self.fields: dict[str, dict] = {}
        self.kinds: dict[str, Kind] = {}
        required: list[str] = []
        self.rest: str | None = None
        writers, readers = [], []
        for key, group in groups.items():
            group.sort(key=lambda g: g[0])
            attrs = tuple(g[1] for g in group)
            _, attr, w, f = group[0]
            if isinstance(w.kind, Rest):
                self.rest = attr
                continue
            self.fields[key], self.kinds[key] = w.kind.schema, w.kind
            needed = w.required
            if needed is None:
                needed = (f.default is _NO_DEFAULT and f.default_factory is _NO_DEFAULT
                          and f.init)
            if needed:
                required.append(key)
            absent = f.default if w.absent is _AS_DEFAULT else w.absent
            writers.append((attrs, key, w.kind, f.default is None, w.omit_false))
            if w.own or not f.init and not (isinstance(w.kind, Const) and w.kind.checked):
                continue
            readers.append((attrs[0] if len(attrs) == 1 and f.init else None,
                            attrs if len(attrs) > 1 else (), key, w.kind.read, needed,
                            w.kind.nil_absent and not needed, absent, w.kind))
        self.required: tuple[str, ...] = tuple(required)
        self._readers = tuple(readers)
        self.to_map = self._compile_writer(writers)  # a message's own to_map (``write``)
        self._known = frozenset(("v", *self.fields))

    def write(self, obj) -> dict[str, Any]:
        return self.to_map(obj)

    def _compile_writer(self, writers: list):
        """``write`` as one function written out for this message, as a hand-written
        ``to_map`` would be (a loop over the fields costs twice as much, and the server encodes
        a state and a scan per robot per tick): the map's fields in order, a field whose
        default is None left out when None, one stated ``omit_false`` left out when false."""
        env: dict[str, Any] = {}
        literal: list[str] = []  # the fields always written, up to the first one left out
        lines: list[str] = []
        for i, (attrs, key, kind, omit_none, omit_false) in enumerate(writers):
            value, env[f"w{i}"] = f"obj.{attrs[0]}", kind.write
            omitted = omit_none or omit_false
            arg = "x" if omitted else value
            expr = kind.inline.format(arg) if kind.inline else f"w{i}({arg})"
            if len(attrs) > 1:  # a Vector's elements, one attribute each
                expr = "[" + ", ".join(f"float(obj.{a})" for a in attrs) + "]"
            if not omitted and not lines:
                literal.append(f"{key!r}: {expr}")
            elif not omitted:
                lines.append(f"    m[{key!r}] = {expr}")
            else:
                lines += [f"    x = {value}",
                          f"    if {'x' if omit_false else 'x is not None'}:",
                          f"        m[{key!r}] = {expr}"]
        first = "{" + ", ".join(literal) + "}"
        if self.rest is not None:
            first = f"dict(obj.{self.rest}); m.update({first})"
        lines.insert(0, f"    m = {first}")
        lines.append("    return m")
        exec("def write(obj):\n" + "\n".join(lines), env)  # noqa: S102 - our own text
        return env["write"]

    def read(self, m: dict, what: str) -> dict[str, Any]:
        values: dict[str, Any] = {}
        get = m.get
        for attr, parts, key, read, needed, nil_absent, absent, kind in self._readers:
            x = get(key, _NOVALUE)
            if x is _NOVALUE or x is None and nil_absent:
                if needed:
                    raise kind.missing(key, what)
                x = absent
            else:
                x = read(x, key, what)
            if attr is not None:
                values[attr] = x
            elif parts:
                values.update(zip(parts, x, strict=True))
        if self.rest is not None:
            values[self.rest] = {k: v for k, v in m.items() if k not in self._known}
        return values
