"""Message types of the rhbl protocol (docs/protocol.md): dataclasses with ``encode()`` /
``decode()``. ``decode`` validates every field it reads (type, length, finiteness), the protocol
version and the payload size, and raises :class:`DecodeError` naming the field.

Each message states each field once, with its kind on the wire (``protocol.codec.wire``);
``FIELDS``, ``REQUIRED``, ``to_map``, ``from_map`` and their checks are derived from that
(``protocol.codec.Layout``). Field names on the wire are exactly the ones in docs/protocol.md;
extra fields are allowed.
"""

from __future__ import annotations

import math
import struct
import sys
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from protocol.codec import (
    MAX_PAYLOAD,
    PROTOCOL_VERSION,
    Boolean,
    Const,
    DecodeError,
    Integer,
    IntegerList,
    Kind,
    Layout,
    Number,
    ProtocolError,
    Records,
    Rest,
    String,
    Vector,
    VectorList,
    get_bytes,
    get_float,
    get_int,
    get_str,
    pack,
    pack_value,
    unpack,
    wire,
)
from protocol.keys import parse as parse_key

__all__ = [
    "CARRIES",
    "COMMAND_MAX_PAYLOAD",
    "MAX_BEAMS",
    "SEEN_BYTES",
    "Decision",
    "DecisionGoal",
    "PROTOCOL_VERSION",
    "Ack",
    "DecodeError",
    "BeaconInfo",
    "DriverState",
    "Fiducial",
    "FiducialGeometry",
    "FiducialItem",
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
MAX_BEACONS = 256  # beacons a world may hold, and a fiducial message may list


class Ranges(Kind):
    """A scan's ranges: msgpack bin of 1..100,000 finite little-endian float32 values, as a
    float32 array."""

    expected = "bytes"
    schema = {"description": "msgpack bin: 1..100000 little-endian float32 values, finite (m)"}

    def write(self, value):
        return np.ascontiguousarray(value, dtype="<f4").tobytes()

    def read(self, x, key, what):
        raw = get_bytes({key: x}, key, what)
        if len(raw) % 4 or not 0 < len(raw) // 4 <= MAX_BEAMS:
            raise DecodeError(
                f"{what}: field '{key}': expected 1..{MAX_BEAMS} little-endian float32 values, "
                f"got {len(raw)} bytes"
            )
        ranges = np.frombuffer(raw, dtype="<f4").astype(np.float32)
        if not np.isfinite(ranges).all():
            raise DecodeError(f"{what}: field '{key}': expected finite values, got NaN or "
                              f"infinity")
        return ranges


class DecisionPath(Kind):
    """A tree's decision path: at most ``MAX`` ``[index, depth, radius, label]``, root to
    winner, as a tuple of tuples."""

    MAX = 1024
    nil_absent = False
    schema = {"type": "array", "maxItems": MAX,
              "description": "[index, depth, radius, label] per node, root to winner",
              "items": {"type": "array", "minItems": 4, "maxItems": 4}}

    def write(self, value):
        return [[int(i), int(d), float(r), str(lab)] for i, d, r, lab in value]

    def read(self, x, key, what):
        if not isinstance(x, list | tuple) or len(x) > self.MAX:
            raise DecodeError(f"{what}: field '{key}': expected a list of at most {self.MAX} "
                              f"[index, depth, radius, label], got {type(x).__name__}")
        path = []
        for k, e in enumerate(x):
            name = f"{key}[{k}]"
            if not isinstance(e, list | tuple) or len(e) != 4:
                raise DecodeError(f"{what}: field '{name}': expected [index, depth, radius, "
                                  f"label], got {e!r:.80}")
            item = dict(zip(("index", "depth", "radius", "label"), e, strict=True))
            at = f"{what} {name}"
            path.append((get_int(item, "index", at, minimum=0),
                         get_int(item, "depth", at, minimum=0),
                         get_float(item, "radius", at), get_str(item, "label", at)))
        return tuple(path)


class DecisionGoal(NamedTuple):
    """The goal a decision pursued (``Decision.goal``): ``index`` (0-based) of ``count`` goals in
    the sequence (a patrol's every visit counted) and the ``beacon`` it names."""

    index: int
    count: int
    beacon: int

    def describe(self) -> str:
        """``goal 1/2 (beacon 1)``"""
        return f"goal {self.index + 1}/{self.count} (beacon {self.beacon})"


class GoalOfDecision(Kind):
    """A :class:`DecisionGoal` as a map ``{"index", "count", "beacon"}``: non-negative integers,
    ``index`` below ``count``."""

    expected = "a map of index, count, beacon"
    schema = {"type": "object", "required": ["index", "count", "beacon"],
              "properties": {"index": {"type": "integer", "minimum": 0},
                             "count": {"type": "integer", "minimum": 1},
                             "beacon": {"type": "integer", "minimum": 0}},
              "description": "the goal pursued: index (0-based) of count, the beacon it names"}

    def write(self, value):
        return {"index": int(value[0]), "count": int(value[1]), "beacon": int(value[2])}

    def read(self, x, key, what):
        if not isinstance(x, dict):
            raise DecodeError(f"{what}: field '{key}': expected {self.expected}, got {x!r:.80}")
        goal = DecisionGoal(*(get_int({f"{key}.{k}": x[k]} if k in x else {}, f"{key}.{k}",
                                      what, minimum=0) for k in DecisionGoal._fields))
        if goal.index >= goal.count:
            raise DecodeError(f"{what}: field '{key}': expected index below count, got index "
                              f"{goal.index} of {goal.count}")
        return goal


# the kinds of field the messages have
NUM, INT, UINT, BOOL, STR = Number(), Integer(), Integer(minimum=0), Boolean(), String()
ORIGIN = String(max_len=MAX_ORIGIN, non_empty=True)
VEC3 = Vector(3)
RANGES = Ranges()


def message(cls):
    """``cls`` as a dataclass with ``FIELDS``, ``REQUIRED`` and its map derived from its
    fields (``protocol.codec.Layout``). The map is written in the fields' order: where that
    differs from the constructor's (``Scan``, ``LabeledScan``, ``Decision``, ``WorldInfo``),
    the fields out of place are keyword-only."""
    cls = dataclass(cls)
    cls._layout = layout = Layout(cls)
    cls.FIELDS, cls.REQUIRED = layout.fields, layout.required
    cls.to_map = layout.to_map  # the map's writer, written out for it (no loop, no lookup)
    return cls


class _Message:
    """A message: ``WHAT`` names it in errors; ``FIELDS`` (wire name -> JSON-schema fragment) and
    ``REQUIRED`` are its map, derived from its fields (``message``), from which ``json_schema``
    derives the recordings' schemas (tests/protocol/test_schemas.py holds them against
    ``to_map`` and ``from_map``); ``NAME`` is its schema's name (``rhbl.v<version>.<NAME>``)."""

    WHAT: ClassVar[str] = "message"
    NAME: ClassVar[str] = ""  # default: the class name
    MAX_SIZE: ClassVar[int] = MAX_PAYLOAD
    FIELDS: ClassVar[dict[str, dict]] = {}
    REQUIRED: ClassVar[tuple[str, ...]] = ()
    _layout: ClassVar[Layout]

    def to_map(self) -> dict[str, Any]:
        return self._layout.write(self)

    @classmethod
    def from_map(cls, m: dict[str, Any]):
        values = cls._layout.read(m, cls.WHAT)
        cls._read_own(m, values)
        return cls(**values)

    @classmethod
    def _read_own(cls, m: dict[str, Any], values: dict[str, Any]) -> None:
        """Read the fields stated ``own=True`` into ``values`` and check rules across
        fields (a ``DecodeError`` naming them)."""

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


@message
class State(_Message):
    """Position2d state: ``pos`` is the odometry pose [x, y, yaw], ``vel`` [vx, vy, va] in the
    robot frame, ``stall`` true if the robot pushed into an obstacle during the last tick,
    ``driver`` the command source driving (``""``: none), ``truth`` the true pose (simulation)."""

    WHAT: ClassVar[str] = "state"
    ts: float = wire(NUM)
    seq: int = wire(UINT)
    pos: tuple[float, float, float] = wire(VEC3)
    vel: tuple[float, float, float] = wire(VEC3, default=(0.0, 0.0, 0.0), required=True)
    stall: bool = wire(BOOL, default=False, required=True)
    driver: str = wire(STR, default="")
    truth: tuple[float, float, float] | None = wire(VEC3, default=None)


@message
class Scan(_Message):
    """A laser scan. ``ranges`` float32, ``ranges[0]`` at ``min_angle`` (the robot's right),
    counter-clockwise; bearing(i) = min_angle + i * resolution. ``pose`` the odometry pose at
    the scan, ``truth`` the true pose (simulation)."""

    WHAT: ClassVar[str] = "scan"
    ts: float = wire(NUM)
    id: int = wire(UINT)
    min_angle: float = wire(NUM, default=-np.pi / 2, required=True, kw_only=True)
    max_angle: float = wire(NUM, default=np.pi / 2, required=True, kw_only=True)
    resolution: float = wire(NUM, default=np.pi / 359, required=True, kw_only=True)
    max_range: float = wire(NUM, default=8.0, required=True, kw_only=True)
    ranges: np.ndarray = wire(RANGES)
    pose: tuple[float, float, float] = wire(VEC3, default=(0.0, 0.0, 0.0), required=True)
    truth: tuple[float, float, float] | None = wire(VEC3, default=None)

    @property
    def count(self) -> int:
        return int(len(self.ranges))

    def bearings(self) -> np.ndarray:
        return self.min_angle + np.arange(self.count) * self.resolution

    @classmethod
    def from_map(cls, m):
        # a scan as senders write it is checked in bulk; anything else field by field (the
        # same values accepted, and those checks name what is wrong)
        scan = _scan_in_bulk(cls, m)
        return scan if scan is not None else cls._from_map_by_field(m)

    @classmethod
    def _from_map_by_field(cls, m):
        return super().from_map(m)


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


class FiducialItem(NamedTuple):
    """One beacon a fiducial finder sees (Player's ``player_fiducial_item``): its ``id`` (0: seen
    but too far to identify), ``range`` (m) and ``bearing`` (rad, sensor frame, counter-clockwise
    positive: a beacon on the robot's left has a positive bearing)."""

    id: int
    range: float
    bearing: float

    @property
    def x(self) -> float:
        """Its position ahead of the sensor (m; Player's ``pose.px``)."""
        return self.range * math.cos(self.bearing)

    @property
    def y(self) -> float:
        """Its position to the sensor's left (m; Player's ``pose.py``)."""
        return self.range * math.sin(self.bearing)


# what a fiducial finder sees (a Fiducial's items; a goal behaviour's label carries them too)
_SEEN = Records({"id": UINT, "range": NUM, "bearing": NUM}, FiducialItem, MAX_BEACONS)
SEEN_BYTES = 5 + MAX_BEACONS * 41  # the most such a list takes in msgpack (a label's "seen")


@message
class Fiducial(_Message):
    """What a robot's fiducial finder sees at sim time ``ts``: ``items``, one
    :class:`FiducialItem` per beacon within range and field of view and not hidden behind a
    wall (none: an empty list). ``seq`` numbers them as the robot's scans: the scan of the same
    tick has ``id == seq``. ``pose`` the odometry pose, ``truth`` the true pose (simulation)."""

    WHAT: ClassVar[str] = "fiducial"
    ts: float = wire(NUM)
    seq: int = wire(UINT)
    items: tuple[FiducialItem, ...] = wire(_SEEN, default=(), required=True)
    pose: tuple[float, float, float] = wire(VEC3, default=(0.0, 0.0, 0.0), required=True)
    truth: tuple[float, float, float] | None = wire(VEC3, default=None)

    def find(self, beacon_id: int) -> FiducialItem | None:
        """The item of the beacon ``beacon_id`` (None: not in view)."""
        for item in self.items:
            if item.id == beacon_id:
                return item
        return None


@message
class VelCmd(_Message):
    """A velocity command: ``vel`` [vx, vy, va] (m/s, m/s, rad/s; vy is ignored by a
    differential drive), ``state`` motors on, ``source`` who commands (``teacher``,
    ``controller``, ...), ``scan_id`` the scan this command answers (lock-step), optional."""

    WHAT: ClassVar[str] = "cmd/vel"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    vx: float = wire(VEC3, key="vel", part=0, default=0.0, required=True)
    va: float = wire(VEC3, key="vel", part=2, default=0.0)
    vy: float = wire(VEC3, key="vel", part=1, default=0.0)
    state: bool = wire(BOOL, default=True, required=True)
    source: str = wire(STR, default="")
    scan_id: int | None = wire(UINT, default=None)
    ts: float | None = wire(NUM, default=None)


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


@message
class DriverState(_Message):
    """Which command source drives a robot (``source`` ``""``: none), published on
    ``driver_key``; ``priority`` of that source; ``ts`` sim time."""

    WHAT: ClassVar[str] = "driver"
    NAME: ClassVar[str] = "Driver"
    source: str = wire(STR)
    ts: float = wire(NUM, default=0.0, required=True)
    priority: int = wire(INT, default=0, required=True)


def _get_origin(m: dict, what: str, required: bool) -> tuple[str | None, int | None]:
    """The label identity ``origin`` (a teacher session, 1..64 characters) and ``seq`` (int >= 0):
    both or (unless ``required``) neither."""
    origin, seq = m.get("origin"), m.get("seq")
    origin = None if origin is None else ORIGIN.read(origin, "origin", what)
    seq = None if seq is None else UINT.read(seq, "seq", what)
    if origin is None and (required or seq is not None):
        with_seq = "" if required else " (with 'seq')"
        raise DecodeError(f"{what}: field 'origin': expected a string{with_seq}, got nothing")
    if seq is None and origin is not None:
        raise DecodeError(f"{what}: field 'seq': expected an integer (with 'origin'), "
                          f"got nothing")
    return origin, seq


def _goal_fields(label) -> dict:
    """A label's ``goal``, ``reached`` and ``seen`` as keywords (none: a label without goals)."""
    return {k: getattr(label, k) for k in ("goal", "reached", "seen")
            if getattr(label, k) is not None}


def _read_identity(cls, m: dict, values: dict) -> None:
    """``_read_own`` of a label and a resent label: the identity ``origin`` and ``seq``, both
    or neither (both when ``REQUIRED`` names them)."""
    values["origin"], values["seq"] = _get_origin(m, cls.WHAT, "origin" in cls.REQUIRED)


@message
class TeacherAction(_Message):
    """The teacher's label for a scan: ``action`` name (e.g. ``fwd-left``), ``scan_id``;
    ``origin`` (the teacher session, a random id per process) and ``seq`` (its labels numbered
    from 0) identify the label for acknowledgements and resends, both or neither."""

    WHAT: ClassVar[str] = "teacher/action"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    scan_id: int = wire(UINT)
    action: str = wire(STR)
    source: str = wire(STR, default="teacher", absent="")
    ts: float = wire(NUM, default=0.0)
    # the action actually executed (perturbed demonstrations)
    executed: str | None = wire(STR, default=None)
    origin: str | None = wire(ORIGIN, default=None, own=True)
    seq: int | None = wire(UINT, default=None, own=True)
    # goals in order (docs/goals.md): the goal pursued, the one reached, what the finder saw
    goal: int | None = wire(UINT, default=None, kw_only=True)
    reached: int | None = wire(UINT, default=None, kw_only=True)
    seen: tuple[FiducialItem, ...] | None = wire(_SEEN, default=None, kw_only=True)
    _read_own = classmethod(_read_identity)


@message
class LabeledScan(_Message):
    """A label resent with the scan it answers (``rhbl/<robot>/teacher/labeled``): the
    ``TeacherAction`` fields (``origin`` and ``seq`` required) plus the scan's ``ranges``
    (float32 bytes) and ``yaw`` (its odometry heading), what the learner journals. Sent only for
    a label the learner has not acknowledged: a restarted learner never saw that scan."""

    WHAT: ClassVar[str] = "teacher/labeled"
    scan_id: int = wire(UINT)
    action: str = wire(STR)
    source: str = wire(STR, default="teacher", absent="", kw_only=True)
    ts: float = wire(NUM, default=0.0, kw_only=True)
    executed: str | None = wire(STR, default=None, kw_only=True)
    origin: str = wire(ORIGIN, own=True)
    seq: int = wire(UINT, own=True)
    ranges: np.ndarray = wire(RANGES)
    yaw: float = wire(NUM, default=0.0, required=True)
    goal: int | None = wire(UINT, default=None, kw_only=True)
    reached: int | None = wire(UINT, default=None, kw_only=True)
    seen: tuple[FiducialItem, ...] | None = wire(_SEEN, default=None, kw_only=True)
    _read_own = classmethod(_read_identity)

    @classmethod
    def of(cls, act: TeacherAction, ranges, yaw: float) -> LabeledScan:
        return cls(scan_id=act.scan_id, action=act.action, origin=act.origin, seq=act.seq,
                   ranges=ranges, yaw=float(yaw), source=act.source, ts=act.ts,
                   executed=act.executed, **_goal_fields(act))

    def action_message(self) -> TeacherAction:
        """The label alone, as it was first published."""
        return TeacherAction(scan_id=self.scan_id, action=self.action, source=self.source,
                             ts=self.ts, executed=self.executed, origin=self.origin,
                             seq=self.seq, **_goal_fields(self))


@message
class LearnerAck(_Message):
    """A learner's acknowledgement of a teacher session's labels (``rhbl/<robot>/learner/ack``):
    the labels of ``origin`` with ``seq < upto`` and those in ``seqs`` (all above ``upto``) are
    in its journal (written to the kernel, so a killed learner keeps them; fsync'd within a
    second) or were refused as bad input (logged: never to be resent; ``refused`` says how many
    of them the learner refused, so what a teacher shows as held agrees with the journal). The
    whole state of that origin each time, so a later ack makes up for a lost one."""

    WHAT: ClassVar[str] = "learner/ack"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    MAX_SEQS: ClassVar[int] = 4096
    origin: str = wire(ORIGIN)
    upto: int = wire(UINT)
    seqs: tuple[int, ...] = wire(IntegerList(4096), default=(), own=True)
    ts: float = wire(NUM, default=0.0)
    # the withdrawals of origin with ``id < withdrawn`` are held
    withdrawn: int | None = wire(UINT, default=None)
    # how many of the labels acknowledged were refused as bad input, not journaled
    refused: int | None = wire(UINT, default=None)

    @classmethod
    def _read_own(cls, m, values):
        values["seqs"] = cls._layout.kinds["seqs"].read(m.get("seqs", []), "seqs", cls.WHAT,
                                                         minimum=values["upto"])


@message
class Withdrawal(_Message):
    """A teacher's withdrawal of labels it gave (``rhbl/<robot>/teacher/withdraw``): the labels
    of session ``origin`` with ``first <= seq < upto`` are taken back (an undo, a discarded
    episode); a learner journals the withdrawal, never learns those labels and rebuilds its tree
    without them. ``id`` numbers the session's withdrawals from 0 (acknowledged in
    ``LearnerAck.withdrawn``, resent until then); ``ts`` wall time; ``reason`` what the person
    did. At most ``MAX_WITHDRAWN`` labels per withdrawal."""

    WHAT: ClassVar[str] = "teacher/withdraw"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    origin: str = wire(ORIGIN)
    id: int = wire(UINT)
    first: int = wire(UINT)
    upto: int = wire(UINT)
    ts: float = wire(NUM, default=0.0)
    reason: str = wire(STR, default="")

    @classmethod
    def _read_own(cls, m, values):
        first, upto = values["first"], values["upto"]
        if not first < upto <= first + MAX_WITHDRAWN:
            raise DecodeError(f"{cls.WHAT}: fields 'first', 'upto': expected first < upto <= "
                              f"first + {MAX_WITHDRAWN}, got {first} and {upto}")


@message
class TreeNotice(_Message):
    """A learner's "tree updated" notice: size of the tree and the snapshot to fetch."""

    WHAT: ClassVar[str] = "learner/notice"
    seq: int = wire(UINT)
    nodes: int = wire(UINT)
    height: int = wire(UINT)
    vectors: int = wire(UINT, default=0)
    snapshot_id: str = wire(STR, default="")
    ts: float = wire(NUM, default=0.0)


@message
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
    should show it the way out). A tree with goals (docs/goals.md): ``goal`` the goal pursued
    (:class:`DecisionGoal`; None: a tree without goals), ``goal_why`` why the last goal changed
    (None: none has yet)."""

    WHAT: ClassVar[str] = "controller/decision"
    MAX_GOAL_WHY: ClassVar[int] = 512  # characters of ``goal_why``
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    MAX_PATH: ClassVar[int] = DecisionPath.MAX
    scan_id: int = wire(UINT)
    ts: float = wire(NUM, default=0.0, kw_only=True)
    action: str = wire(STR)
    path: tuple[tuple[int, int, float, str], ...] = wire(DecisionPath(), default=())
    snapshot_id: str = wire(STR, default="")
    nodes: int = wire(UINT, default=0)
    executed: str | None = wire(STR, default=None)
    looping: bool = wire(BOOL, default=False, omit_false=True)
    # added after v1: left out when None, so a decision without goals is encoded as before
    goal: DecisionGoal | None = wire(GoalOfDecision(), default=None)
    goal_why: str | None = wire(String(max_len=MAX_GOAL_WHY), default=None)


@message
class Geometry(_Message):
    """Reply to ``get_geom``: device ``pose`` [x, y, yaw] on the robot, ``size`` [length,
    width] (m); for position2d also the collision ``radius``."""

    WHAT: ClassVar[str] = "geom"
    pose: tuple[float, float, float] = wire(VEC3)
    size: tuple[float, float] = wire(Vector(2))
    radius: float | None = wire(NUM, default=None)


@message
class FiducialGeometry(_Message):
    """Reply to the fiducial finder's ``get_geom`` (Player's ``PLAYER_FIDUCIAL_REQ_GET_GEOM`` and
    ``GET_FOV`` in one): the sensor's ``pose`` [x, y, yaw] on the robot and ``size`` [length,
    width] (m) as in :class:`Geometry`; ``min_range``, ``max_range`` (m: a beacon farther is not
    seen), ``max_range_id`` (m: a beacon farther is reported with id 0), ``fov`` (rad, centred on
    the sensor's heading) and ``rate`` (Hz, that of the scans)."""

    WHAT: ClassVar[str] = "fiducial geom"
    pose: tuple[float, float, float] = wire(VEC3)
    size: tuple[float, float] = wire(Vector(2))
    min_range: float = wire(NUM)
    max_range: float = wire(NUM)
    max_range_id: float = wire(NUM)
    fov: float = wire(NUM)
    rate: float = wire(NUM, default=10.0, required=True)


@message
class LaserConfig(_Message):
    """Reply to the laser's ``get_config``."""

    WHAT: ClassVar[str] = "laser config"
    min_angle: float = wire(NUM)
    max_angle: float = wire(NUM)
    resolution: float = wire(NUM)
    max_range: float = wire(NUM)
    count: int = wire(Integer(minimum=1))
    rate: float = wire(NUM, default=10.0, required=True)


@message
class SetOdom(_Message):
    """Request payload of ``set_odom``: the new odometry ``pose`` [x, y, yaw]."""

    WHAT: ClassVar[str] = "set_odom"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    pose: tuple[float, float, float] = wire(VEC3)


@message
class SetPose(_Message):
    """Request payload of the sim-only ``set_pose``: teleport the robot to the true ``pose``
    [x, y, yaw] (world frame); ``reset_odom`` (default true) also sets the odometry to it."""

    WHAT: ClassVar[str] = "set_pose"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    pose: tuple[float, float, float] = wire(VEC3)
    reset_odom: bool = wire(BOOL, default=True)


@message
class SimPose(_Message):
    """Reply to the sim-only ``get_pose``: the true ``pose`` [x, y, yaw], the odometry ``odom``
    and the sim time ``ts`` of the last published tick."""

    WHAT: ClassVar[str] = "sim pose"
    pose: tuple[float, float, float] = wire(VEC3)
    odom: tuple[float, float, float] = wire(VEC3, default=(0.0, 0.0, 0.0))
    ts: float = wire(NUM, default=0.0)


class BeaconInfo(NamedTuple):
    """A beacon of a world (``WorldInfo.beacons``): ``id``, centre ``pos`` [x, y] (m),
    ``colour`` (``#rrggbb``) and ``size`` (m, its diameter)."""

    id: int
    pos: tuple[float, float]
    colour: str
    size: float


@message
class WorldInfo(_Message):
    """Reply to the sim-only ``get_world``: what a viewer needs to draw the world. ``walls`` are
    line segments ``[x0, y0, x1, y1]`` (m, world frame), ``goal`` is ``[x, y, radius]`` or absent,
    ``starts`` the world's start poses ``[x, y, yaw]`` (the default one first), ``beacons`` its
    fiducial beacons (:class:`BeaconInfo`; left out when it has none)."""

    WHAT: ClassVar[str] = "world info"
    name: str = wire(STR)
    task: str = wire(STR)
    walls: tuple[tuple[float, float, float, float], ...] = wire(VectorList(4), default=())
    starts: tuple[tuple[float, float, float], ...] = wire(VectorList(3), default=())
    goal: tuple[float, float, float] | None = wire(VEC3, default=None, kw_only=True)
    beacons: tuple[BeaconInfo, ...] = wire(
        Records({"id": UINT, "pos": Vector(2), "colour": String(max_len=16), "size": NUM},
                BeaconInfo, MAX_BEACONS),
        default=(), omit_false=True, kw_only=True)


@message
class MotorPower(_Message):
    """Request payload of ``motor_power``: ``state`` true to enable the motors."""

    WHAT: ClassVar[str] = "motor_power"
    MAX_SIZE: ClassVar[int] = COMMAND_MAX_PAYLOAD
    state: bool = wire(BOOL)


@message
class Ack(_Message):
    """A successful reply without data (``ok`` true); ``info`` optional free text; ``extra``
    the map's other fields."""

    WHAT: ClassVar[str] = "ack"
    ok: bool = wire(Const(True), default=True, required=True, init=False, repr=False,
                    compare=False)
    info: str = wire(STR, default="")
    extra: dict[str, Any] = wire(Rest(), default_factory=dict)


@message
class Nack(_Message):
    """A refused request, sent as a zenoh error reply: ``reason`` says why."""

    WHAT: ClassVar[str] = "nack"
    ok: bool = wire(Const(False, checked=False), default=False, init=False, repr=False,
                    compare=False)
    reason: str = wire(String(max_len=4096))


# the message each kind of key carries (``protocol.keys.parse(key).kind``; the replies of the
# requests are not published, except the world, which recorders keep on its request's key)
CARRIES: dict[str, type[_Message]] = {
    "state": State, "scan": Scan, "fiducial": Fiducial, "driver": DriverState, "cmd": VelCmd, "label": TeacherAction,
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
