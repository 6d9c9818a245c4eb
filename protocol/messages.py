"""Message types of the rhbl protocol (docs/protocol.md): dataclasses with ``encode()`` /
``decode()``. ``decode`` validates every field it reads (type, length, finiteness), the protocol
version and the payload size, and raises :class:`DecodeError` naming the field.

Field names on the wire are exactly the ones in docs/protocol.md; extra fields are allowed.
"""

from __future__ import annotations

import math
import struct
import sys
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from protocol.codec import (
    MAX_PAYLOAD,
    PROTOCOL_VERSION,
    DecodeError,
    ProtocolError,
    get_bool,
    get_bytes,
    get_float,
    get_int,
    get_opt,
    get_str,
    get_vec,
    pack,
    pack_value,
    unpack,
)
from protocol.keys import parse as parse_key

__all__ = [
    "CARRIES",
    "COMMAND_MAX_PAYLOAD",
    "MAX_BEAMS",
    "Decision",
    "PROTOCOL_VERSION",
    "Ack",
    "DecodeError",
    "DriverState",
    "Geometry",
    "LabeledScan",
    "LaserConfig",
    "LearnerAck",
    "MAX_VA",
    "MAX_VX",
    "MotorPower",
    "Nack",
    "ProtocolError",
    "Scan",
    "SetOdom",
    "SetPose",
    "SimPose",
    "State",
    "TeacherAction",
    "TreeNotice",
    "VelCmd",
    "VelCmdPacker",
    "Withdrawal",
    "WorldInfo",
    "kind_of",
]

COMMAND_MAX_PAYLOAD = 64 * 1024  # bytes: commands and requests are small
# the robot's speed limits (docs/protocol.md section 2): |vx| <= MAX_VX m/s, |va| <= MAX_VA
# rad/s (100 deg/s); a server clamps every command to them, a bridge can clamp the same way
MAX_VX = 0.5
MAX_VA = math.radians(100.0)
MAX_BEAMS = 100_000
MAX_ORIGIN = 64  # characters of a teacher session's identity (``origin``)
MAX_WITHDRAWN = 100_000  # labels one withdrawal may name (hours of demonstration at 10 Hz)

# JSON-schema fragments of the field kinds the decoders check (``_Message.FIELDS``)
NUM = {"type": "number"}
INT = {"type": "integer"}
UINT = {"type": "integer", "minimum": 0}
BOOL = {"type": "boolean"}
STR = {"type": "string", "maxLength": 256}
ORIGIN = {"type": "string", "minLength": 1, "maxLength": MAX_ORIGIN}
RANGES = {"description": "msgpack bin: 1..100000 little-endian float32 values, finite (m)"}


def vec(n: int) -> dict:
    return {"type": "array", "items": NUM, "minItems": n, "maxItems": n}


VEC3 = vec(3)


class _Message:
    """A message: ``WHAT`` names it in errors; ``FIELDS`` (wire name -> JSON-schema fragment) and
    ``REQUIRED`` are its map, the one description of it from which ``json_schema`` derives the
    recordings' schemas (tests/protocol/test_schemas.py holds them against ``to_map`` and
    ``from_map``); ``NAME`` is its schema's name (``rhbl.v<version>.<NAME>``)."""

    WHAT: ClassVar[str] = "message"
    NAME: ClassVar[str] = ""  # default: the class name
    MAX_SIZE: ClassVar[int] = MAX_PAYLOAD
    FIELDS: ClassVar[dict[str, dict]] = {}
    REQUIRED: ClassVar[tuple[str, ...]] = ()

    def to_map(self) -> dict[str, Any]:  # pragma: no cover - overridden
        raise NotImplementedError

    @classmethod
    def from_map(cls, m: dict[str, Any]):  # pragma: no cover - overridden
        raise NotImplementedError

    def encode(self) -> bytes:
        return pack(self.to_map())

    @classmethod
    def decode(cls, data: Any, max_size: int | None = None):
        m = unpack(data, cls.WHAT, cls.MAX_SIZE if max_size is None else max_size)
        return cls.from_map(m)

    @classmethod
    def schema_name(cls) -> str:
        return f"rhbl.v{PROTOCOL_VERSION}.{cls.NAME or cls.__name__}"

    @classmethod
    def json_schema(cls) -> dict:
        """The JSON schema of the message's map (``FIELDS``, ``REQUIRED`` and the version
        ``v``); other fields are allowed, as receivers ignore them."""
        return {
            "title": cls.schema_name(),
            "description": (f"rhbl wire protocol version {PROTOCOL_VERSION} (docs/protocol.md): "
                            f"{cls.WHAT}, a msgpack map as published on the bus"),
            "type": "object",
            "properties": {"v": {"const": PROTOCOL_VERSION}, **cls.FIELDS},
            "required": ["v", *cls.REQUIRED],
        }


def _opt_vec3(m, name, what):
    return get_opt(m, name, get_vec, what, 3)


@dataclass
class State(_Message):
    """Position2d state: ``pos`` is the odometry pose [x, y, yaw], ``vel`` [vx, vy, va] in the
    robot frame, ``stall`` true if the robot pushed into an obstacle during the last tick,
    ``driver`` the command source driving (``""``: none), ``truth`` the true pose (simulation)."""

    WHAT: ClassVar[str] = "state"
    FIELDS = {"ts": NUM, "seq": UINT, "pos": VEC3, "vel": VEC3, "stall": BOOL, "driver": STR,
              "truth": VEC3}
    REQUIRED = ("ts", "seq", "pos", "vel", "stall")
    ts: float
    seq: int
    pos: tuple[float, float, float]
    vel: tuple[float, float, float] = (0.0, 0.0, 0.0)
    stall: bool = False
    driver: str = ""
    truth: tuple[float, float, float] | None = None

    def to_map(self):
        m = {
            "ts": float(self.ts),
            "seq": int(self.seq),
            "pos": [float(x) for x in self.pos],
            "vel": [float(x) for x in self.vel],
            "stall": bool(self.stall),
            "driver": str(self.driver),
        }
        if self.truth is not None:
            m["truth"] = [float(x) for x in self.truth]
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            ts=get_float(m, "ts", w),
            seq=get_int(m, "seq", w, minimum=0),
            pos=get_vec(m, "pos", w, 3),
            vel=get_vec(m, "vel", w, 3),
            stall=get_bool(m, "stall", w),
            driver=get_opt(m, "driver", get_str, w, default=""),
            truth=_opt_vec3(m, "truth", w),
        )


@dataclass
class Scan(_Message):
    """A laser scan. ``ranges`` float32, ``ranges[0]`` at ``min_angle`` (the robot's right),
    counter-clockwise; bearing(i) = min_angle + i * resolution. ``pose`` the odometry pose at
    the scan, ``truth`` the true pose (simulation)."""

    WHAT: ClassVar[str] = "scan"
    FIELDS = {"ts": NUM, "id": UINT, "min_angle": NUM, "max_angle": NUM, "resolution": NUM,
              "max_range": NUM, "ranges": RANGES, "pose": VEC3, "truth": VEC3}
    REQUIRED = ("ts", "id", "min_angle", "max_angle", "resolution", "max_range", "ranges",
                "pose")
    ts: float
    id: int
    ranges: np.ndarray
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    min_angle: float = -np.pi / 2
    max_angle: float = np.pi / 2
    resolution: float = np.pi / 359
    max_range: float = 8.0
    truth: tuple[float, float, float] | None = None

    @property
    def count(self) -> int:
        return int(len(self.ranges))

    def bearings(self) -> np.ndarray:
        return self.min_angle + np.arange(self.count) * self.resolution

    def to_map(self):
        m = {
            "ts": float(self.ts),
            "id": int(self.id),
            "min_angle": float(self.min_angle),
            "max_angle": float(self.max_angle),
            "resolution": float(self.resolution),
            "max_range": float(self.max_range),
            "ranges": np.ascontiguousarray(self.ranges, dtype="<f4").tobytes(),
            "pose": [float(x) for x in self.pose],
        }
        if self.truth is not None:
            m["truth"] = [float(x) for x in self.truth]
        return m

    @classmethod
    def from_map(cls, m):
        # a scan as senders write it is checked in bulk; anything else field by field (the
        # same values accepted, and those checks name what is wrong)
        scan = _scan_in_bulk(cls, m)
        return scan if scan is not None else cls._from_map_by_field(m)

    @classmethod
    def _from_map_by_field(cls, m):
        w = cls.WHAT
        return cls(
            ts=get_float(m, "ts", w),
            id=get_int(m, "id", w, minimum=0),
            ranges=_get_ranges(m, "ranges", w),
            pose=get_vec(m, "pose", w, 3),
            min_angle=get_float(m, "min_angle", w),
            max_angle=get_float(m, "max_angle", w),
            resolution=get_float(m, "resolution", w),
            max_range=get_float(m, "max_range", w),
            truth=_opt_vec3(m, "truth", w),
        )


_F32LE = np.dtype("<f4")
_LITTLE = sys.byteorder == "little"  # the wire's float32s are this machine's


def _floats3(v) -> tuple[float, float, float] | None:
    """``v`` as a tuple when it is a list of 3 Python floats (finiteness not checked)."""
    if type(v) is list and len(v) == 3:
        a, b, c = v
        if type(a) is float and type(b) is float and type(c) is float:
            return a, b, c
    return None


def _scan_in_bulk(cls, m: dict):
    """The scan of ``m`` when every field is as a sender encodes it (numbers as msgpack
    floats, ``id`` an integer >= 0, ``pose``/``truth`` lists of 3 floats, ``ranges`` 1..100,000
    float32 values) and all numbers are finite, checked with one sum of them all (float64:
    finite exactly when every value is, as a float32 sum of 100,000 values cannot overflow);
    None otherwise, and ``_from_map_by_field`` then accepts what is valid or names what is
    not. The same values as that path."""
    get = m.get
    ts, lo, hi, res, mr = (get("ts"), get("min_angle"), get("max_angle"), get("resolution"),
                           get("max_range"))
    sid, raw, truth = get("id"), get("ranges"), get("truth")
    pose = _floats3(get("pose"))
    if not (type(ts) is float and type(lo) is float and type(hi) is float
            and type(res) is float and type(mr) is float and type(sid) is int and sid >= 0
            and type(raw) is bytes and pose is not None):
        return None
    if truth is not None and (truth := _floats3(truth)) is None:
        return None
    n = len(raw)
    if n % 4 or not 0 < n <= 4 * MAX_BEAMS:
        return None
    # a writable array of its own: the bytes copied once (on a big-endian machine, converted)
    ranges = (np.frombuffer(bytearray(raw), np.float32) if _LITTLE
              else np.frombuffer(raw, _F32LE).astype(np.float32))
    total = ts + lo + hi + res + mr + sum(pose) + (0.0 if truth is None else sum(truth))
    if not math.isfinite(total + float(np.add.reduce(ranges, dtype=np.float64))):
        return None
    return cls(ts=ts, id=sid, ranges=ranges, pose=pose, min_angle=lo,
               max_angle=hi, resolution=res, max_range=mr, truth=truth)


def _get_ranges(m: dict, name: str, what: str) -> np.ndarray:
    """1..100,000 finite little-endian float32 values (bytes) as a float32 array."""
    raw = get_bytes(m, name, what)
    if len(raw) % 4 or not 0 < len(raw) // 4 <= MAX_BEAMS:
        raise DecodeError(
            f"{what}: field '{name}': expected 1..{MAX_BEAMS} little-endian float32 values, "
            f"got {len(raw)} bytes"
        )
    ranges = np.frombuffer(raw, dtype="<f4").astype(np.float32)
    if not np.isfinite(ranges).all():
        raise DecodeError(f"{what}: field '{name}': expected finite values, got NaN or infinity")
    return ranges


@dataclass
class VelCmd(_Message):
    """A velocity command: ``vel`` [vx, vy, va] (m/s, m/s, rad/s; vy is ignored by a
    differential drive), ``state`` motors on, ``source`` who commands (``teacher``,
    ``controller``, ...), ``scan_id`` the scan this command answers (lock-step), optional."""

    WHAT: ClassVar[str] = "cmd/vel"
    FIELDS = {"vel": VEC3, "state": BOOL, "source": STR, "scan_id": UINT, "ts": NUM}
    REQUIRED = ("vel", "state")
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    vx: float = 0.0
    va: float = 0.0
    vy: float = 0.0
    state: bool = True
    source: str = ""
    scan_id: int | None = None
    ts: float | None = None

    def to_map(self):
        m = {
            "vel": [float(self.vx), float(self.vy), float(self.va)],
            "state": bool(self.state),
            "source": str(self.source),
        }
        if self.scan_id is not None:
            m["scan_id"] = int(self.scan_id)
        if self.ts is not None:
            m["ts"] = float(self.ts)
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        vx, vy, va = get_vec(m, "vel", w, 3)
        return cls(
            vx=vx,
            va=va,
            vy=vy,
            state=get_bool(m, "state", w),
            source=get_opt(m, "source", get_str, w, default=""),
            scan_id=get_opt(m, "scan_id", get_int, w, minimum=0),
            ts=get_opt(m, "ts", get_float, w),
        )


_VEL = struct.Struct(">BdBdBd")  # msgpack float64s (0xcb), as Python floats are packed
_F64 = struct.Struct(">Bd")
_UINTS = ((1 << 8, struct.Struct(">BB"), 0xCC), (1 << 16, struct.Struct(">BH"), 0xCD),
          (1 << 32, struct.Struct(">BI"), 0xCE))


class VelCmdPacker:
    """The bytes of ``VelCmd(vx=, va=, state=, source=SOURCE, scan_id=, ts=).encode()``, byte
    for byte, for one ``source``: the map's fixed parts packed once, only the numbers per
    command (a command per scan is the controller's hot path). ``vx``, ``va`` and ``ts`` are
    not checked here (``PlayerClient.send_command`` refuses non-finite speeds)."""

    def __init__(self, source: str = "") -> None:
        self.source = str(source)
        self._vel = b"".join(pack_value(x) for x in ("v", PROTOCOL_VERSION, "vel")) + b"\x93"
        self._state = pack_value("state")
        self._source = pack_value("source") + pack_value(self.source)
        self._scan_id, self._ts = pack_value("scan_id"), pack_value("ts")

    def pack(self, vx: float, va: float, state: bool = True, scan_id: int | None = None,
             ts: float | None = None) -> bytes:
        parts = [b"", self._vel, _VEL.pack(0xCB, float(vx), 0xCB, 0.0, 0xCB, float(va)),
                 self._state, b"\xc3" if state else b"\xc2", self._source]
        if scan_id is not None:
            parts += (self._scan_id, _uint(int(scan_id)))
        if ts is not None:
            parts += (self._ts, _F64.pack(0xCB, float(ts)))
        parts[0] = bytes((0x80 | (len(parts) + 2) // 2,))  # a fixmap of 4 to 6 fields
        return b"".join(parts)


def _uint(n: int) -> bytes:
    """``n`` as msgpack packs it (the smallest form)."""
    if 0 <= n < 0x80:
        return bytes((n,))
    for limit, form, tag in _UINTS:
        if 0 <= n < limit:
            return form.pack(tag, n)
    return pack_value(n)


@dataclass
class DriverState(_Message):
    """Which command source drives a robot (``source`` ``""``: none), published on
    ``driver_key``; ``priority`` of that source; ``ts`` sim time."""

    WHAT: ClassVar[str] = "driver"
    NAME: ClassVar[str] = "Driver"
    FIELDS = {"source": STR, "ts": NUM, "priority": INT}
    REQUIRED = ("source", "ts", "priority")
    source: str
    ts: float = 0.0
    priority: int = 0

    def to_map(self):
        return {"source": self.source, "ts": float(self.ts), "priority": int(self.priority)}

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            source=get_str(m, "source", w),
            ts=get_float(m, "ts", w),
            priority=get_int(m, "priority", w),
        )


def _get_origin(m: dict, what: str, required: bool) -> tuple[str | None, int | None]:
    """The label identity ``origin`` (a teacher session, 1..64 characters) and ``seq`` (int >= 0):
    both or (unless ``required``) neither."""
    origin = get_opt(m, "origin", get_str, what, max_len=MAX_ORIGIN)
    seq = get_opt(m, "seq", get_int, what, minimum=0)
    if origin == "":
        raise DecodeError(f"{what}: field 'origin': expected a non-empty string, got ''")
    if origin is None and (required or seq is not None):
        with_seq = "" if required else " (with 'seq')"
        raise DecodeError(f"{what}: field 'origin': expected a string{with_seq}, got nothing")
    if seq is None and origin is not None:
        raise DecodeError(f"{what}: field 'seq': expected an integer (with 'origin'), "
                          f"got nothing")
    return origin, seq


def _get_session(m: dict, what: str) -> str:
    """A required ``origin``: a teacher session, 1..64 characters."""
    origin = get_str(m, "origin", what, max_len=MAX_ORIGIN)
    if not origin:
        raise DecodeError(f"{what}: field 'origin': expected a non-empty string, got ''")
    return origin


def _label_fields(m: dict, what: str, required: bool) -> dict[str, Any]:
    """The fields a label and a resent label share (``TeacherAction``, ``LabeledScan``)."""
    origin, seq = _get_origin(m, what, required=required)
    return {
        "scan_id": get_int(m, "scan_id", what, minimum=0),
        "action": get_str(m, "action", what),
        "source": get_opt(m, "source", get_str, what, default=""),
        "ts": get_opt(m, "ts", get_float, what, default=0.0),
        "executed": get_opt(m, "executed", get_str, what),
        "origin": origin,
        "seq": seq,
    }


@dataclass
class TeacherAction(_Message):
    """The teacher's label for a scan: ``action`` name (e.g. ``fwd-left``), ``scan_id``;
    ``origin`` (the teacher session, a random id per process) and ``seq`` (its labels numbered
    from 0) identify the label for acknowledgements and resends, both or neither."""

    WHAT: ClassVar[str] = "teacher/action"
    FIELDS = {"scan_id": UINT, "action": STR, "source": STR, "ts": NUM, "executed": STR,
              "origin": ORIGIN, "seq": UINT}
    REQUIRED = ("scan_id", "action")
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    scan_id: int
    action: str
    source: str = "teacher"
    ts: float = 0.0
    executed: str | None = None  # the action actually executed (perturbed demonstrations)
    origin: str | None = None
    seq: int | None = None

    def to_map(self):
        m = {
            "scan_id": int(self.scan_id),
            "action": self.action,
            "source": self.source,
            "ts": float(self.ts),
        }
        if self.executed is not None:
            m["executed"] = self.executed
        if self.origin is not None:
            m["origin"] = self.origin
            m["seq"] = int(self.seq)
        return m

    @classmethod
    def from_map(cls, m):
        return cls(**_label_fields(m, cls.WHAT, required=False))


@dataclass
class LabeledScan(_Message):
    """A label resent with the scan it answers (``rhbl/<robot>/teacher/labeled``): the
    ``TeacherAction`` fields (``origin`` and ``seq`` required) plus the scan's ``ranges``
    (float32 bytes) and ``yaw`` (its odometry heading), what the learner journals. Sent only for
    a label the learner has not acknowledged: a restarted learner never saw that scan."""

    WHAT: ClassVar[str] = "teacher/labeled"
    FIELDS = {**TeacherAction.FIELDS, "ranges": RANGES, "yaw": NUM}
    REQUIRED = ("scan_id", "action", "origin", "seq", "ranges", "yaw")
    scan_id: int
    action: str
    origin: str
    seq: int
    ranges: np.ndarray
    yaw: float = 0.0
    source: str = "teacher"
    ts: float = 0.0
    executed: str | None = None

    @classmethod
    def of(cls, act: TeacherAction, ranges, yaw: float) -> LabeledScan:
        return cls(scan_id=act.scan_id, action=act.action, origin=act.origin, seq=act.seq,
                   ranges=ranges, yaw=float(yaw), source=act.source, ts=act.ts,
                   executed=act.executed)

    def action_message(self) -> TeacherAction:
        """The label alone, as it was first published."""
        return TeacherAction(scan_id=self.scan_id, action=self.action, source=self.source,
                             ts=self.ts, executed=self.executed, origin=self.origin,
                             seq=self.seq)

    def to_map(self):
        m = self.action_message().to_map()
        m["ranges"] = np.ascontiguousarray(self.ranges, dtype="<f4").tobytes()
        m["yaw"] = float(self.yaw)
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(**_label_fields(m, w, required=True), ranges=_get_ranges(m, "ranges", w),
                   yaw=get_float(m, "yaw", w))


@dataclass
class LearnerAck(_Message):
    """A learner's acknowledgement of a teacher session's labels (``rhbl/<robot>/learner/ack``):
    the labels of ``origin`` with ``seq < upto`` and those in ``seqs`` (all above ``upto``) are
    in its journal (written to the kernel, so a killed learner keeps them; fsync'd within a
    second) or were refused as bad input (logged: never to be resent). The whole state of that
    origin each time, so a later ack makes up for a lost one."""

    WHAT: ClassVar[str] = "learner/ack"
    FIELDS = {"origin": ORIGIN, "upto": UINT,
              "seqs": {"type": "array", "items": UINT, "maxItems": 4096}, "ts": NUM,
              "withdrawn": UINT}
    REQUIRED = ("origin", "upto")
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    MAX_SEQS: ClassVar[int] = 4096
    origin: str
    upto: int
    seqs: tuple[int, ...] = ()
    ts: float = 0.0
    withdrawn: int | None = None  # the withdrawals of origin with ``id < withdrawn`` are held

    def to_map(self):
        m = {"origin": self.origin, "upto": int(self.upto),
             "seqs": [int(x) for x in self.seqs], "ts": float(self.ts)}
        if self.withdrawn is not None:
            m["withdrawn"] = int(self.withdrawn)
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        origin, upto = _get_session(m, w), get_int(m, "upto", w, minimum=0)
        raw = m.get("seqs", [])
        if not isinstance(raw, list | tuple) or len(raw) > cls.MAX_SEQS:
            raise DecodeError(f"{w}: field 'seqs': expected a list of at most {cls.MAX_SEQS} "
                              f"integers, got {type(raw).__name__}"
                              f"{' of ' + str(len(raw)) if isinstance(raw, list | tuple) else ''}")
        seqs = tuple(get_int({"seqs": x}, "seqs", w, minimum=upto) for x in raw)
        return cls(origin=origin, upto=upto, seqs=seqs,
                   ts=get_opt(m, "ts", get_float, w, default=0.0),
                   withdrawn=get_opt(m, "withdrawn", get_int, w, minimum=0))


@dataclass
class Withdrawal(_Message):
    """A teacher's withdrawal of labels it gave (``rhbl/<robot>/teacher/withdraw``): the labels
    of session ``origin`` with ``first <= seq < upto`` are taken back (an undo, a discarded
    episode); a learner journals the withdrawal, never learns those labels and rebuilds its tree
    without them. ``id`` numbers the session's withdrawals from 0 (acknowledged in
    ``LearnerAck.withdrawn``, resent until then); ``ts`` wall time; ``reason`` what the person
    did. At most ``MAX_WITHDRAWN`` labels per withdrawal."""

    WHAT: ClassVar[str] = "teacher/withdraw"
    FIELDS = {"origin": ORIGIN, "id": UINT, "first": UINT, "upto": UINT, "ts": NUM,
              "reason": STR}
    REQUIRED = ("origin", "id", "first", "upto")
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    origin: str
    id: int
    first: int
    upto: int
    ts: float = 0.0
    reason: str = ""

    def to_map(self):
        return {"origin": self.origin, "id": int(self.id), "first": int(self.first),
                "upto": int(self.upto), "ts": float(self.ts), "reason": self.reason}

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        origin = _get_session(m, w)
        first, upto = get_int(m, "first", w, minimum=0), get_int(m, "upto", w, minimum=0)
        if not first < upto <= first + MAX_WITHDRAWN:
            raise DecodeError(f"{w}: fields 'first', 'upto': expected first < upto <= first + "
                              f"{MAX_WITHDRAWN}, got {first} and {upto}")
        return cls(origin=origin, id=get_int(m, "id", w, minimum=0), first=first, upto=upto,
                   ts=get_opt(m, "ts", get_float, w, default=0.0),
                   reason=get_opt(m, "reason", get_str, w, default=""))


@dataclass
class TreeNotice(_Message):
    """A learner's "tree updated" notice: size of the tree and the snapshot to fetch."""

    WHAT: ClassVar[str] = "learner/notice"
    FIELDS = {"seq": UINT, "nodes": UINT, "height": UINT, "vectors": UINT, "snapshot_id": STR,
              "ts": NUM}
    REQUIRED = ("seq", "nodes", "height")
    seq: int
    nodes: int
    height: int
    vectors: int = 0
    snapshot_id: str = ""
    ts: float = 0.0

    def to_map(self):
        return {
            "seq": int(self.seq),
            "nodes": int(self.nodes),
            "height": int(self.height),
            "vectors": int(self.vectors),
            "snapshot_id": self.snapshot_id,
            "ts": float(self.ts),
        }

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            seq=get_int(m, "seq", w, minimum=0),
            nodes=get_int(m, "nodes", w, minimum=0),
            height=get_int(m, "height", w, minimum=0),
            vectors=get_opt(m, "vectors", get_int, w, minimum=0, default=0),
            snapshot_id=get_opt(m, "snapshot_id", get_str, w, default=""),
            ts=get_opt(m, "ts", get_float, w, default=0.0),
        )


@dataclass
class Decision(_Message):
    """The controller's decision for one scan: the ``action`` it commanded for ``scan_id``
    (sim time ``ts``) and the tree's decision ``path`` from the root to the winning sphere, one
    ``(index, depth, radius, label)`` per node (the last is the winner, its label the action's);
    ``snapshot_id`` names the tree (``<lineage>:<vectors>`` as in the learner's notices, ``""``
    when unknown) and ``nodes`` its size. The controller's loop guard
    (``client.behaviour.guard.RotationGuard``): ``executed`` the action commanded when the
    guard overruled the tree's (a reversal of the rotation, or a forward order into what lies
    ahead; None: the tree's was), ``looping`` the guard overruled a reversal lately
    (``RotationGuard.looping``: the robot is held from a rot-left/rot-right loop; a person
    should show it the way out)."""

    WHAT: ClassVar[str] = "controller/decision"
    FIELDS = {"scan_id": UINT, "ts": NUM, "action": STR, "snapshot_id": STR, "nodes": UINT,
              "path": {"type": "array", "maxItems": 1024,
                       "description": "[index, depth, radius, label] per node, root to winner",
                       "items": {"type": "array", "minItems": 4, "maxItems": 4}},
              "executed": STR, "looping": BOOL}
    REQUIRED = ("scan_id", "action")
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    MAX_PATH: ClassVar[int] = 1024
    scan_id: int
    action: str
    path: tuple[tuple[int, int, float, str], ...] = ()
    ts: float = 0.0
    snapshot_id: str = ""
    nodes: int = 0
    executed: str | None = None
    looping: bool = False

    def to_map(self):
        m = {
            "scan_id": int(self.scan_id),
            "ts": float(self.ts),
            "action": self.action,
            "path": [[int(i), int(d), float(r), str(lab)] for i, d, r, lab in self.path],
            "snapshot_id": self.snapshot_id,
            "nodes": int(self.nodes),
        }
        if self.executed is not None:
            m["executed"] = self.executed
        if self.looping:
            m["looping"] = True
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        raw = m.get("path", [])
        if not isinstance(raw, list | tuple) or len(raw) > cls.MAX_PATH:
            raise DecodeError(f"{w}: field 'path': expected a list of at most {cls.MAX_PATH} "
                              f"[index, depth, radius, label], got {type(raw).__name__}")
        path = []
        for k, e in enumerate(raw):
            name = f"path[{k}]"
            if not isinstance(e, list | tuple) or len(e) != 4:
                raise DecodeError(f"{w}: field '{name}': expected [index, depth, radius, label], "
                                  f"got {e!r:.80}")
            item = dict(zip(("index", "depth", "radius", "label"), e, strict=True))
            path.append((get_int(item, "index", f"{w} {name}", minimum=0),
                         get_int(item, "depth", f"{w} {name}", minimum=0),
                         get_float(item, "radius", f"{w} {name}"),
                         get_str(item, "label", f"{w} {name}")))
        return cls(
            scan_id=get_int(m, "scan_id", w, minimum=0),
            action=get_str(m, "action", w),
            path=tuple(path),
            ts=get_opt(m, "ts", get_float, w, default=0.0),
            snapshot_id=get_opt(m, "snapshot_id", get_str, w, default=""),
            nodes=get_opt(m, "nodes", get_int, w, minimum=0, default=0),
            executed=get_opt(m, "executed", get_str, w),
            looping=get_opt(m, "looping", get_bool, w, default=False),
        )


@dataclass
class Geometry(_Message):
    """Reply to ``get_geom``: device ``pose`` [x, y, yaw] on the robot, ``size`` [length,
    width] (m); for position2d also the collision ``radius``."""

    WHAT: ClassVar[str] = "geom"
    FIELDS = {"pose": VEC3, "size": vec(2), "radius": NUM}
    REQUIRED = ("pose", "size")
    pose: tuple[float, float, float]
    size: tuple[float, float]
    radius: float | None = None

    def to_map(self):
        m = {"pose": [float(x) for x in self.pose], "size": [float(x) for x in self.size]}
        if self.radius is not None:
            m["radius"] = float(self.radius)
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            pose=get_vec(m, "pose", w, 3),
            size=get_vec(m, "size", w, 2),
            radius=get_opt(m, "radius", get_float, w),
        )


@dataclass
class LaserConfig(_Message):
    """Reply to the laser's ``get_config``."""

    WHAT: ClassVar[str] = "laser config"
    FIELDS = {"min_angle": NUM, "max_angle": NUM, "resolution": NUM, "max_range": NUM,
              "count": {"type": "integer", "minimum": 1}, "rate": NUM}
    REQUIRED = ("min_angle", "max_angle", "resolution", "max_range", "count", "rate")
    min_angle: float
    max_angle: float
    resolution: float
    max_range: float
    count: int
    rate: float = 10.0

    def to_map(self):
        return {
            "min_angle": float(self.min_angle),
            "max_angle": float(self.max_angle),
            "resolution": float(self.resolution),
            "max_range": float(self.max_range),
            "count": int(self.count),
            "rate": float(self.rate),
        }

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            min_angle=get_float(m, "min_angle", w),
            max_angle=get_float(m, "max_angle", w),
            resolution=get_float(m, "resolution", w),
            max_range=get_float(m, "max_range", w),
            count=get_int(m, "count", w, minimum=1),
            rate=get_float(m, "rate", w),
        )


@dataclass
class SetOdom(_Message):
    """Request payload of ``set_odom``: the new odometry ``pose`` [x, y, yaw]."""

    WHAT: ClassVar[str] = "set_odom"
    FIELDS = {"pose": VEC3}
    REQUIRED = ("pose",)
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    pose: tuple[float, float, float]

    def to_map(self):
        return {"pose": [float(x) for x in self.pose]}

    @classmethod
    def from_map(cls, m):
        return cls(pose=get_vec(m, "pose", cls.WHAT, 3))


@dataclass
class SetPose(_Message):
    """Request payload of the sim-only ``set_pose``: teleport the robot to the true ``pose``
    [x, y, yaw] (world frame); ``reset_odom`` (default true) also sets the odometry to it."""

    WHAT: ClassVar[str] = "set_pose"
    FIELDS = {"pose": VEC3, "reset_odom": BOOL}
    REQUIRED = ("pose",)
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    pose: tuple[float, float, float]
    reset_odom: bool = True

    def to_map(self):
        return {"pose": [float(x) for x in self.pose], "reset_odom": bool(self.reset_odom)}

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            pose=get_vec(m, "pose", w, 3),
            reset_odom=get_opt(m, "reset_odom", get_bool, w, default=True),
        )


@dataclass
class SimPose(_Message):
    """Reply to the sim-only ``get_pose``: the true ``pose`` [x, y, yaw], the odometry ``odom``
    and the sim time ``ts`` of the last published tick."""

    WHAT: ClassVar[str] = "sim pose"
    FIELDS = {"pose": VEC3, "odom": VEC3, "ts": NUM}
    REQUIRED = ("pose",)
    pose: tuple[float, float, float]
    odom: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ts: float = 0.0

    def to_map(self):
        return {
            "pose": [float(x) for x in self.pose],
            "odom": [float(x) for x in self.odom],
            "ts": float(self.ts),
        }

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            pose=get_vec(m, "pose", w, 3),
            odom=get_opt(m, "odom", get_vec, w, 3, default=(0.0, 0.0, 0.0)),
            ts=get_opt(m, "ts", get_float, w, default=0.0),
        )


@dataclass
class WorldInfo(_Message):
    """Reply to the sim-only ``get_world``: what a viewer needs to draw the world. ``walls`` are
    line segments ``[x0, y0, x1, y1]`` (m, world frame), ``goal`` is ``[x, y, radius]`` or absent,
    ``starts`` the world's start poses ``[x, y, yaw]`` (the default one first)."""

    WHAT: ClassVar[str] = "world info"
    FIELDS = {"name": STR, "task": STR, "walls": {"type": "array", "items": vec(4)},
              "goal": VEC3, "starts": {"type": "array", "items": VEC3}}
    REQUIRED = ("name", "task")
    name: str
    task: str
    walls: tuple[tuple[float, float, float, float], ...] = ()
    goal: tuple[float, float, float] | None = None
    starts: tuple[tuple[float, float, float], ...] = ()

    def to_map(self):
        m = {
            "name": self.name,
            "task": self.task,
            "walls": [[float(x) for x in w] for w in self.walls],
            "starts": [[float(x) for x in p] for p in self.starts],
        }
        if self.goal is not None:
            m["goal"] = [float(x) for x in self.goal]
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        return cls(
            name=get_str(m, "name", w),
            task=get_str(m, "task", w),
            walls=_vec_list(m, "walls", w, 4),
            goal=get_opt(m, "goal", get_vec, w, 3),
            starts=_vec_list(m, "starts", w, 3),
        )


def _vec_list(m: dict, name: str, what: str, n: int) -> tuple[tuple[float, ...], ...]:
    """A list of finite n-vectors (every element checked like ``get_vec``)."""
    x = m.get(name, [])
    if not isinstance(x, list | tuple):
        raise DecodeError(f"{what}: field '{name}': expected a list of [{n} numbers], "
                          f"got {type(x).__name__}")
    return tuple(get_vec({name: e}, name, what, n) for e in x)


@dataclass
class MotorPower(_Message):
    """Request payload of ``motor_power``: ``state`` true to enable the motors."""

    WHAT: ClassVar[str] = "motor_power"
    FIELDS = {"state": BOOL}
    REQUIRED = ("state",)
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    state: bool

    def to_map(self):
        return {"state": bool(self.state)}

    @classmethod
    def from_map(cls, m):
        return cls(state=get_bool(m, "state", cls.WHAT))


@dataclass
class Ack(_Message):
    """A successful reply without data (``ok`` true); ``info`` optional free text."""

    WHAT: ClassVar[str] = "ack"
    FIELDS = {"ok": {"const": True}, "info": STR}
    REQUIRED = ("ok",)
    info: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_map(self):
        m = dict(self.extra)
        m.update({"ok": True, "info": self.info})
        return m

    @classmethod
    def from_map(cls, m):
        w = cls.WHAT
        if m.get("ok") is not True:
            raise DecodeError(f"{w}: field 'ok': expected true, got {m.get('ok')!r}")
        extra = {k: v for k, v in m.items() if k not in ("v", "ok", "info")}
        return cls(info=get_opt(m, "info", get_str, w, default=""), extra=extra)


@dataclass
class Nack(_Message):
    """A refused request, sent as a zenoh error reply: ``reason`` says why."""

    WHAT: ClassVar[str] = "nack"
    FIELDS = {"ok": {"const": False}, "reason": {"type": "string", "maxLength": 4096}}
    REQUIRED = ("reason",)
    reason: str

    def to_map(self):
        return {"ok": False, "reason": self.reason}

    @classmethod
    def from_map(cls, m):
        return cls(reason=get_str(m, "reason", cls.WHAT, max_len=4096))


# the message each kind of key carries (``protocol.keys.parse(key).kind``; the replies of the
# requests are not published, except the world, which recorders keep on its request's key)
CARRIES: dict[str, type[_Message]] = {
    "state": State, "scan": Scan, "driver": DriverState, "cmd": VelCmd, "label": TeacherAction,
    "labeled": LabeledScan, "withdraw": Withdrawal, "ack": LearnerAck, "notice": TreeNotice, "decision": Decision,
    "world": WorldInfo}


def kind_of(key) -> tuple[str, str]:
    """``(kind, robot)`` of a bus key for what it carries: a key of ``CARRIES`` (``world`` for
    ``rhbl/<robot>/sim/req/get_world``), ``alive`` (a liveliness token), or ``other``."""
    k = parse_key(key)
    if k.kind == "sim":
        return ("world" if k.name == "get_world" else "other"), k.robot
    if k.kind in CARRIES or k.kind == "alive":
        return k.kind, k.robot
    return "other", k.robot
