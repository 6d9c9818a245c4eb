"""An append-only journal of labeled demonstration vectors: the learner never loses one.

The learner appends every labeled vector (the scan it answers, the features, the label) to a
journal next to its snapshot (``<snapshot>.journal``) *before* learning from it, and writes
snapshots that record how many journal records they include. A learner killed at any moment
(even SIGKILL) is rebuilt on restart from the last snapshot plus the journal records after it.

File format (little-endian)::

    frame   := length:uint32  crc32(payload):uint32  payload[length]
    frame 0 := the header, a msgpack map {"kind": "rhbl-journal", "format": 1, "lineage": str, ...}
    frame i := record i-1, a msgpack map {"i", "scan", "ts", "label", "yaw", "ranges", "x"}
               (ranges and x as float32 bytes), plus "origin" and "seq" when the label carries
               its identity (the teacher session and its number, for acknowledgements and
               deduplication: ``LabelSet``); journals without them read the same; plus
               "earlier" (float32 bytes, rows of len(x)) for a person's label whose lag the
               learner estimates: the features of the scans displayed 1, 2, ... before it
            or a tombstone {"i", "ts", "withdraw": {"origin", "id", "first", "upto", "reason"}}:
               the teacher withdrew its labels ``first <= seq < upto`` of session ``origin``
               (``JournalWithdrawal``; its withdrawal number ``id``). The labelled vectors that
               *stand* are the records no tombstone of the journal names (``Journal.standing``)

A snapshot records which labels it holds and which were withdrawn (``LabelSet.to_dict`` and
``Withdrawals.to_dict`` in its provenance), so folding the journal keeps what deduplication needs.

Folding (``Journal.fold(upto)``, ``rhbl learner --fold-journal``): once a durable snapshot holds
records ``0 .. upto - 1`` they are dropped: the file is rewritten as a header with ``base`` =
``upto`` plus the later records, and renamed over the journal (atomic). Indices never change;
``len()`` counts folded records too and ``records(start)`` needs ``start >= base``.

Durability: each record is written with one unbuffered ``os.write`` (it is in the kernel's page
cache when ``append`` returns, so it survives the process being killed) and ``os.fsync``'d at most
``fsync_interval`` seconds later (default 1 s) and on ``sync``/``close`` (so a power cut loses at
most the last second). Recovery: a short frame at the end of the file (a write cut off by a crash)
is a *torn tail*: it is reported and truncated. A CRC mismatch or undecodable frame anywhere is
*corruption*: ``JournalCorruptError`` names the file, frame and offset, and nothing is dropped
silently.
"""

from __future__ import annotations

import bisect
import contextlib
import errno
import logging
import os
import struct
import time
import uuid
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import msgpack
import numpy as np

__all__ = [
    "FORMAT",
    "Journal",
    "JournalCorruptError",
    "JournalError",
    "JournalRecord",
    "JournalWithdrawal",
    "LabelSet",
    "Withdrawals",
    "journal_path",
]

log = logging.getLogger(__name__)

FORMAT = 1
KIND = "rhbl-journal"
_FRAME = struct.Struct("<II")
_MAX_FRAME = 64 * 1024 * 1024


class JournalError(Exception):
    """A journal cannot be created, opened or appended to."""


class JournalCorruptError(JournalError):
    """A journal holds a damaged frame that is not a torn tail (never dropped silently)."""


@dataclass(frozen=True)
class JournalRecord:
    """One labeled vector: the scan it answers, its features and the demonstrated label."""

    index: int
    scan_id: int
    ts: float
    label: str
    ranges: np.ndarray  # float32 raw laser ranges (lets a tree be relearned with other features)
    yaw: float
    features: np.ndarray  # float32 feature vector as extracted when it was learned
    origin: str | None = None  # the label's identity (teacher session, its number), if any
    seq: int | None = None
    # a person's label whose lag the learner estimates: float32 features of the scans displayed
    # 1, 2, ... scans before this one (rows, nearest first; None: not kept)
    earlier: np.ndarray | None = None
    # a goal behaviour's label (client.behaviour.goals.GoalStep): the beacon pursued, the one
    # reached at this scan (or None), what the fiducial finder saw (float64 rows of id, range,
    # bearing: as on the wire, so a replay learns the same vector); goal None: no goals
    goal: int | None = None
    reached: int | None = None
    seen: np.ndarray | None = None

    def to_payload(self) -> dict:
        p = {
            "i": int(self.index),
            "scan": int(self.scan_id),
            "ts": float(self.ts),
            "label": str(self.label),
            "yaw": float(self.yaw),
            "ranges": np.asarray(self.ranges, dtype="<f4").tobytes(),
            "x": np.asarray(self.features, dtype="<f4").tobytes(),
        }
        if self.origin is not None:
            p["origin"] = str(self.origin)
            p["seq"] = int(self.seq)
        if self.earlier is not None:
            p["earlier"] = np.asarray(self.earlier, dtype="<f4").tobytes()
        if self.goal is not None:
            p["goal"] = int(self.goal)
            if self.reached is not None:
                p["reached"] = int(self.reached)
            p["seen"] = np.asarray(self.seen, dtype="<f8").reshape(-1, 3).tobytes()
        return p

    @classmethod
    def from_payload(cls, p: Mapping) -> JournalRecord:
        origin = p.get("origin")
        x = np.frombuffer(p["x"], dtype="<f4")
        earlier = p.get("earlier")
        return cls(
            index=int(p["i"]),
            scan_id=int(p["scan"]),
            ts=float(p["ts"]),
            label=str(p["label"]),
            yaw=float(p["yaw"]),
            ranges=np.frombuffer(p["ranges"], dtype="<f4"),
            features=x,
            origin=None if origin is None else str(origin),
            seq=None if origin is None else int(p["seq"]),
            earlier=(None if earlier is None
                     else np.frombuffer(earlier, dtype="<f4").reshape(-1, max(1, len(x)))),
            goal=None if p.get("goal") is None else int(p["goal"]),
            reached=None if p.get("reached") is None else int(p["reached"]),
            seen=(None if p.get("goal") is None
                  else np.frombuffer(p.get("seen", b""), dtype="<f8").reshape(-1, 3)),
        )


@dataclass(frozen=True)
class JournalWithdrawal:
    """A tombstone: the teacher session ``origin`` withdrew its labels ``first <= seq < upto``
    (its withdrawal number ``id``, ``reason`` what the person did); kept like any record."""

    index: int
    origin: str
    id: int
    first: int
    upto: int
    ts: float = 0.0
    reason: str = ""

    def names(self, origin: str | None, seq: int | None) -> bool:
        return origin == self.origin and seq is not None and self.first <= seq < self.upto

    def to_payload(self) -> dict:
        return {"i": int(self.index), "ts": float(self.ts),
                "withdraw": {"origin": str(self.origin), "id": int(self.id),
                             "first": int(self.first), "upto": int(self.upto),
                             "reason": str(self.reason)}}

    @classmethod
    def from_payload(cls, p: Mapping) -> JournalWithdrawal:
        w = p["withdraw"]
        return cls(index=int(p["i"]), origin=str(w["origin"]), id=int(w["id"]),
                   first=int(w["first"]), upto=int(w["upto"]), ts=float(p.get("ts", 0.0)),
                   reason=str(w.get("reason", "")))


def _record(p: Mapping) -> JournalRecord | JournalWithdrawal:
    return JournalWithdrawal.from_payload(p) if "withdraw" in p else JournalRecord.from_payload(p)


class LabelSet:
    """Which labels (``origin``, ``seq``) a learner holds: per origin a watermark ``upto`` (every
    seq below it is held) and the few held above it. Bounded: at most ``max_above`` seqs above a
    watermark (beyond that the watermark jumps to the lowest held one, giving up the gap below:
    logged; a teacher resends a missing label every few seconds, so a gap lasts only while a
    label is on its way, except after a teacher died, a label refused as bad input before a
    restart (not journaled), or a learner that joined a teacher's session midway; a gap that
    stays makes every later label a seq above it, and after ``max_above`` of them a label of
    the gap still on its way would be taken as held). Every session with a label in the journal
    is kept, however many there are (deduplication survives any number of sessions: each costs
    a few hundred bytes of memory against at least one journal record, so the journal bounds
    it); at most ``max_origins`` sessions that hold only labels refused as bad input
    (``add(..., kept=False)``: not journaled) are kept beside them, the least recently seen
    forgotten (logged)."""

    def __init__(self, max_above: int = 4096, max_origins: int = 256):
        self.max_above, self.max_origins = int(max_above), int(max_origins)
        self._o: dict[str, tuple[int, set[int]]] = {}  # insertion order = least recent first
        self._loose: dict[str, None] = {}  # origins of refused labels only, least recent first
        self.refused: dict[str, int] = {}  # origin -> its labels refused as bad input (held)

    def __contains__(self, label: tuple[str, int]) -> bool:
        origin, seq = label
        st = self._o.get(origin)
        return st is not None and (seq < st[0] or seq in st[1])

    def add(self, origin: str, seq: int, kept: bool = True) -> bool:
        """Record a label (``kept``: journaled; else refused as bad input, not journaled);
        False when it was held already."""
        if (origin, seq) in self:
            self._touch(origin, kept)
            return False
        if not kept:
            self.refused[origin] = self.refused.get(origin, 0) + 1
        self._put(origin, seq, seq + 1, kept)
        return True

    def add_range(self, origin: str, first: int, upto: int) -> None:
        """Record the labels ``first <= seq < upto`` as held (withdrawn ones, by a withdrawal
        journaled: never to be learned, so never resent)."""
        if upto > first:
            self._put(origin, int(first), int(upto))

    def _put(self, origin: str, first: int, stop: int, kept: bool = True) -> None:
        upto, above = self._o.pop(origin, (0, set()))
        if first <= upto:
            if stop > upto + 1 and above:  # a range past seqs held above: now below
                above = {q for q in above if q >= stop}
            upto = max(upto, stop)
        else:
            above.update(range(first, stop))
        while upto in above:
            above.discard(upto)
            upto += 1
        if len(above) > self.max_above:
            low = min(above)
            log.warning("labels of teacher session %s: %d held above seq %d, never "
                        "received; giving up on seqs %d..%d", origin, len(above), upto,
                        upto, low - 1)
            upto = low
            while upto in above:
                above.discard(upto)
                upto += 1
        loose = origin not in self._o or origin in self._loose
        self._o[origin] = (upto, above)
        self._keep(origin, kept, loose)

    def _keep(self, origin: str, kept: bool, loose: bool) -> None:
        """``origin`` was just seen: a session with a journaled label is kept for good; one
        with refused labels only is among the ``max_origins`` most recent such, or forgotten."""
        self._loose.pop(origin, None)
        if kept or not loose:
            return
        self._loose[origin] = None
        while len(self._loose) > self.max_origins:
            old = next(iter(self._loose))
            log.warning("forgetting the refused labels of teacher session %s (more than %d "
                        "sessions with refused labels only)", old, self.max_origins)
            del self._loose[old]
            del self._o[old]
            self.refused.pop(old, None)

    def _touch(self, origin: str, kept: bool = True) -> None:
        self._o[origin] = self._o.pop(origin)
        self._keep(origin, kept, origin in self._loose)

    def ack(self, origin: str) -> tuple[int, tuple[int, ...]]:
        """(upto, sorted seqs held above it) of an origin."""
        upto, above = self._o.get(origin, (0, set()))
        return upto, tuple(sorted(above))

    def origins(self) -> list[str]:
        return list(self._o)

    def __len__(self) -> int:
        """Labels held (every origin)."""
        return sum(upto + len(above) for upto, above in self._o.values())

    def to_dict(self) -> dict:
        return {o: [upto, sorted(above)] for o, (upto, above) in self._o.items()}

    @classmethod
    def from_dict(cls, d, **kw) -> LabelSet:
        """From ``to_dict`` (a snapshot's provenance); entries of the wrong shape raise
        ValueError."""
        ls = cls(**kw)
        if d is None:
            return ls
        if not isinstance(d, Mapping):
            raise ValueError(f"label set: expected a map, got {type(d).__name__}")
        for o, v in d.items():
            ok = (isinstance(o, str) and isinstance(v, list | tuple) and len(v) == 2
                  and isinstance(v[0], int) and isinstance(v[1], list | tuple)
                  and all(isinstance(x, int) and not isinstance(x, bool) for x in v[1]))
            if not ok:
                raise ValueError(f"label set: entry {o!r}: expected [upto, [seqs]], got {v!r:.80}")
            ls._o[o] = (int(v[0]), {int(x) for x in v[1] if x >= v[0]})
        return ls


class Withdrawals:
    """The withdrawals a learner holds: per teacher session (``origin``) the ranges of labels it
    withdrew (``[first, upto)``, merged) and which withdrawals (their ``id``) are held, as a
    watermark (every id below it) plus the few above it, for ``LearnerAck.withdrawn``. Kept in
    the journal (tombstones) and in a snapshot's provenance (``to_dict``)."""

    def __init__(self, max_above: int = 4096):
        self.max_above = int(max_above)
        self._ranges: dict[str, list[tuple[int, int]]] = {}  # sorted, disjoint, merged
        self._ids: dict[str, tuple[int, set[int]]] = {}

    def holds(self, origin: str, wid: int) -> bool:
        """True when the withdrawal ``wid`` of ``origin`` is held."""
        st = self._ids.get(origin)
        return st is not None and (wid < st[0] or wid in st[1])

    def add(self, origin: str, wid: int, first: int, upto: int) -> bool:
        """Record a withdrawal; False when it was held already (its range is merged anyway)."""
        self._merge(origin, int(first), int(upto))
        if self.holds(origin, wid):
            return False
        low, above = self._ids.get(origin, (0, set()))
        above.add(int(wid))
        while low in above:
            above.discard(low)
            low += 1
        if len(above) > self.max_above:  # ids that never came (a teacher that died): given up
            low = min(above)
            while low in above:
                above.discard(low)
                low += 1
        self._ids[origin] = (low, above)
        return True

    def _merge(self, origin: str, first: int, upto: int) -> None:
        spans = self._ranges.setdefault(origin, [])
        spans.append((first, upto))
        spans.sort()
        merged = [spans[0]]
        for a, b in spans[1:]:
            if a <= merged[-1][1]:
                merged[-1] = (merged[-1][0], max(merged[-1][1], b))
            else:
                merged.append((a, b))
        self._ranges[origin] = merged

    def __contains__(self, label: tuple[str | None, int | None]) -> bool:
        origin, seq = label
        spans = self._ranges.get(origin) if origin is not None else None
        if not spans or seq is None:
            return False
        k = bisect.bisect_right(spans, (seq, float("inf"))) - 1
        return k >= 0 and spans[k][0] <= seq < spans[k][1]

    def acked(self, origin: str) -> int | None:
        """Every withdrawal of ``origin`` with ``id`` below this is held (None: none came)."""
        st = self._ids.get(origin)
        return None if st is None else st[0]

    def ranges(self, origin: str) -> list[tuple[int, int]]:
        return list(self._ranges.get(origin, ()))

    def origins(self) -> list[str]:
        return list(self._ids)

    def labels(self) -> int:
        """How many label numbers the ranges cover (every origin)."""
        return sum(b - a for spans in self._ranges.values() for a, b in spans)

    def __len__(self) -> int:
        """Withdrawals held (every origin)."""
        return sum(low + len(above) for low, above in self._ids.values())

    def to_dict(self) -> dict:
        return {o: {"ranges": [list(r) for r in self._ranges.get(o, ())],
                    "ids": [low, sorted(above)]} for o, (low, above) in self._ids.items()}

    @classmethod
    def from_dict(cls, d, **kw) -> Withdrawals:
        """From ``to_dict`` (a snapshot's provenance); a wrong shape raises ValueError."""
        ws = cls(**kw)
        if d is None:
            return ws
        if not isinstance(d, Mapping):
            raise ValueError(f"withdrawals: expected a map, got {type(d).__name__}")

        def ints(x) -> bool:
            return all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in x)

        for o, v in d.items():
            ranges = v.get("ranges") if isinstance(v, Mapping) else None
            ids = v.get("ids") if isinstance(v, Mapping) else None
            ok = (isinstance(o, str) and isinstance(ranges, list | tuple)
                  and all(isinstance(r, list | tuple) and len(r) == 2 and ints(r) and r[0] < r[1]
                          for r in ranges)
                  and isinstance(ids, list | tuple) and len(ids) == 2 and ints([ids[0]])
                  and isinstance(ids[1], list | tuple) and ints(ids[1]))
            if not ok:
                raise ValueError(f"withdrawals: entry {o!r}: expected {{ranges: [[first, upto]"
                                 f"...], ids: [upto, [ids]]}}, got {v!r:.80}")
            for a, b in ranges:
                ws._merge(o, int(a), int(b))
            ws._ids[o] = (int(ids[0]), {int(x) for x in ids[1] if x >= ids[0]})
        return ws


def journal_path(snapshot: str | os.PathLike) -> Path:
    """Where the journal of a snapshot lives: beside it, ``<snapshot>.journal``."""
    return Path(f"{os.fspath(snapshot)}.journal")


def _frame(payload: bytes) -> bytes:
    return _FRAME.pack(len(payload), zlib.crc32(payload)) + payload


class Journal:
    """An open journal: ``append`` records, iterate ``records(start)``; use as a context manager.

    Create with ``Journal.create(path, header)`` (fails if the file exists) or open an existing
    one with ``Journal.open(path)`` (validates every frame, truncates a torn tail).

    ``write`` (default ``os.write``, same signature) writes the appended records' bytes: the
    seam through which a fault campaign makes them fail as a full disk would
    (campaigns/full_disk.py).
    """

    def __init__(self, path: Path, fd: int, header: dict, offsets: list[int], end: int,
                 fsync_interval: float, truncated: int = 0, write=os.write):
        self.path = path
        self._fd = fd
        self._write = write
        self.header = header
        self.base = int(header.get("base", 0))  # index of the first record held (fold)
        self._offsets = offsets  # file offset of each record's frame (record base + k)
        self._end = end
        self.fsync_interval = float(fsync_interval)
        self._last_sync = time.monotonic()
        self._dirty = False
        self._torn = False  # a failed append may have left a partial frame after _end
        self.truncated_bytes = truncated  # bytes of a torn tail removed by open()

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | os.PathLike, header: Mapping | None = None, *,
               fsync_interval: float = 1.0, write=os.write) -> Journal:
        """A new, empty journal whose header holds ``header`` plus a fresh ``lineage`` id."""
        path = Path(path)
        head = {"kind": KIND, "format": FORMAT, "lineage": uuid.uuid4().hex,
                "created": time.time()}
        head.update(dict(header or {}))
        data = _frame(msgpack.packb(head, use_bin_type=True))
        # the header is written to a temporary file and linked into place, so a journal file
        # never exists without a whole header
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            tfd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                os.write(tfd, data)
                os.fsync(tfd)
            finally:
                os.close(tfd)
            try:
                os.link(tmp, path)
            except FileExistsError:
                raise JournalError(f"journal {path} already exists; open it instead") from None
            finally:
                os.unlink(tmp)
            fd = os.open(path, os.O_RDWR | os.O_APPEND)
        except JournalError:
            raise
        except OSError as exc:
            raise JournalError(f"cannot create journal {path}: {exc}") from exc
        _fsync_dir(path)
        return cls(path, fd, head, [], len(data), fsync_interval, write=write)

    @classmethod
    def open(cls, path: str | os.PathLike, *, fsync_interval: float = 1.0,
             readonly: bool = False, write=os.write) -> Journal:
        """Open an existing journal for appending (or reading), after validating every frame."""
        path = Path(path)
        try:
            fd = os.open(path, os.O_RDONLY if readonly else (os.O_RDWR | os.O_APPEND))
        except FileNotFoundError:
            raise JournalError(f"journal {path} does not exist") from None
        except OSError as exc:
            raise JournalError(f"cannot open journal {path}: {exc}") from exc
        try:
            header, offsets, end, size = _scan(path, fd)
            truncated = size - end
            if truncated:
                if readonly:
                    log.warning("journal %s: torn last record (%d bytes) ignored (read-only)",
                                path, truncated)
                else:
                    log.warning("journal %s: torn last record (%d bytes at offset %d, a write "
                                "cut off by a crash) truncated; %d records kept",
                                path, truncated, end, len(offsets))
                    os.ftruncate(fd, end)
                    os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        return cls(path, fd, header, offsets, end, fsync_interval, truncated, write)

    # ---- reading ------------------------------------------------------------------------
    @property
    def lineage(self) -> str:
        return str(self.header.get("lineage", ""))

    def __len__(self) -> int:
        """Records appended since the journal was created (folded ones included)."""
        return self.base + len(self._offsets)

    def records(self, start: int = 0) -> Iterator[JournalRecord]:
        """Records ``start``, ``start + 1``, ... (re-read from the file, CRC-checked): each a
        ``JournalRecord`` (a labelled vector) or a ``JournalWithdrawal`` (a tombstone; the
        vectors that stand: :meth:`standing`). Records before ``base`` were folded into a
        snapshot (:meth:`fold`) and cannot be read."""
        if start < self.base or start > len(self):
            held = (f"records {self.base}..{len(self) - 1}" if self.base else
                    f"{len(self)} records")
            raise JournalError(f"journal {self.path} holds {held}; cannot start at record "
                               f"{start}" + (" (the earlier ones were folded into a snapshot)"
                                             if start < self.base else ""))
        if start == len(self):
            return
        with open(self.path, "rb") as f:
            f.seek(self._offsets[start - self.base])
            for i in range(start - self.base, len(self._offsets)):
                payload = _read_frame(f, self.path, i + 1, self._offsets[i])
                yield _record(_unpack(payload, self.path, i + 1, self._offsets[i]))

    def standing(self, start: int | None = None, stop: int | None = None,
                 withdrawn: Withdrawals | None = None) -> Iterator[JournalRecord]:
        """The labelled vectors that stand among records ``start .. stop - 1`` (default: all
        the journal holds): every label record that no tombstone among records before
        ``stop`` names, nor ``withdrawn`` (those of a snapshot's provenance)."""
        start = self.base if start is None else start
        stop = len(self) if stop is None else min(stop, len(self))
        gone = [r for r in self.records(self.base) if isinstance(r, JournalWithdrawal)
                and r.index < stop]
        for rec in self.records(start):
            if rec.index >= stop:
                return
            if isinstance(rec, JournalWithdrawal):
                continue
            if rec.origin is not None and (any(w.names(rec.origin, rec.seq) for w in gone)
                                           or (withdrawn is not None
                                               and (rec.origin, rec.seq) in withdrawn)):
                continue
            yield rec

    # ---- writing ------------------------------------------------------------------------
    def append(self, scan_id: int, ts: float, label: str, ranges, yaw: float,
               features, origin: str | None = None, seq: int | None = None,
               earlier=None, goal: int | None = None, reached: int | None = None,
               seen=None) -> int:
        """Append one labeled vector (with the label's ``origin`` and ``seq`` when it has them,
        the ``earlier`` scans' features of a person's label, and a goal behaviour's ``goal``,
        ``reached`` and ``seen``); returns its index. Durable against a killed process on
        return; fsync'd within ``fsync_interval`` seconds."""
        return self._append(JournalRecord(len(self), scan_id, ts, label, ranges, yaw,
                                          features, origin, seq, earlier, goal, reached, seen))

    def append_withdrawal(self, origin: str, wid: int, first: int, upto: int,
                          ts: float = 0.0, reason: str = "") -> int:
        """Append a tombstone: the labels ``first <= seq < upto`` of ``origin`` are withdrawn
        (withdrawal number ``wid``); returns its index. Durable as ``append``."""
        return self._append(JournalWithdrawal(len(self), origin, wid, first, upto, ts, reason))

    def _append(self, rec: JournalRecord | JournalWithdrawal) -> int:
        if self._fd < 0:
            raise JournalError(f"journal {self.path} is closed")
        index = rec.index
        data = _frame(msgpack.packb(rec.to_payload(), use_bin_type=True))
        if self._torn:  # a failed append left bytes that a retry could not remove yet
            self._rollback(None)
        try:
            n = self._write(self._fd, data)
            while n < len(data):  # a short write (disk full / signal): finish or fail loudly
                w = self._write(self._fd, data[n:])
                if w <= 0:
                    raise OSError(errno.ENOSPC, "short write")
                n += w
        except OSError as exc:
            # a partial frame must not stay in the file: the next append would land after it
            # and the journal would no longer open (CRC error in the middle)
            self._torn = True
            self._rollback(exc)
            raise JournalError(f"cannot append record {index} to journal {self.path}: {exc} "
                               f"(nothing was written; append it again)") from exc
        self._offsets.append(self._end)
        self._end += len(data)
        self._dirty = True
        if time.monotonic() - self._last_sync >= self.fsync_interval:
            try:
                self.sync()
            except OSError as exc:  # the record is written (survives a kill); fsync retried
                log.warning("journal %s: fsync failed (%s); retried at the next append, "
                            "snapshot or close", self.path, exc)
        return index

    def _rollback(self, cause: OSError | None) -> None:
        """Cut the file back to the end of the last whole record (after a failed append)."""
        try:
            os.ftruncate(self._fd, self._end)
        except OSError as exc:
            raise JournalError(
                f"journal {self.path}: cannot remove a partly written record at offset "
                f"{self._end} ({exc}{'; after: ' + str(cause) if cause else ''}); nothing is "
                f"appended until it can") from exc
        self._torn = False

    def fold(self, upto: int) -> int:
        """Drop records ``base .. upto - 1`` (a durable snapshot holds them): the file is
        rewritten as a header with ``base = upto`` plus the records from ``upto`` on, fsync'd,
        and renamed over the journal (atomic: a crash leaves the old or the new file, both
        whole). Record indices do not change. Returns the bytes saved."""
        if self._fd < 0:
            raise JournalError(f"journal {self.path} is closed")
        upto = min(int(upto), len(self))
        if upto <= self.base:
            return 0
        self.sync()
        head = dict(self.header, base=upto)
        hdr = _frame(msgpack.packb(head, use_bin_type=True))
        keep_from = self._offsets[upto - self.base] if upto < len(self) else self._end
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.fold")
        try:
            with open(self.path, "rb") as src, open(tmp, "wb") as dst:
                dst.write(hdr)
                src.seek(keep_from)
                left = self._end - keep_from
                while left > 0:
                    chunk = src.read(min(left, 1 << 20))
                    if not chunk:
                        raise OSError(errno.EIO, "journal shorter than expected")
                    dst.write(chunk)
                    left -= len(chunk)
                dst.flush()
                os.fsync(dst.fileno())
            os.replace(tmp, self.path)
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise JournalError(f"cannot fold journal {self.path}: {exc}") from exc
        _fsync_dir(self.path)
        fd = os.open(self.path, os.O_RDWR | os.O_APPEND)
        os.close(self._fd)
        self._fd = fd
        saved = keep_from - len(hdr)
        shift = keep_from - len(hdr)
        self._offsets = [o - shift for o in self._offsets[upto - self.base:]]
        self._end -= shift
        self.header = head
        self.base = upto
        return saved

    def sync(self) -> None:
        """fsync the journal now (called at the fsync cadence, on snapshots and on close)."""
        if self._dirty and self._fd >= 0:
            os.fsync(self._fd)
            self._dirty = False
        self._last_sync = time.monotonic()

    def close(self) -> None:
        if self._fd >= 0:
            try:
                self.sync()
            finally:
                os.close(self._fd)
                self._fd = -1

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Journal({str(self.path)!r}, records={len(self)}, lineage={self.lineage!r})"


# ---- helpers --------------------------------------------------------------------------------
def _fsync_dir(path: Path) -> None:
    try:
        dfd = os.open(path.parent if str(path.parent) else ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)


def _unpack(payload: bytes, path: Path, frame: int, offset: int) -> dict:
    try:
        obj = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack raises several types
        raise JournalCorruptError(
            f"journal {path}: frame {frame} at offset {offset} passes its CRC but does not "
            f"decode ({exc})") from exc
    if not isinstance(obj, dict):
        raise JournalCorruptError(
            f"journal {path}: frame {frame} at offset {offset} is not a map")
    return obj


def _read_frame(f, path: Path, frame: int, offset: int) -> bytes:
    head = f.read(_FRAME.size)
    if len(head) < _FRAME.size:
        raise JournalCorruptError(f"journal {path}: frame {frame} at offset {offset} is missing")
    length, crc = _FRAME.unpack(head)
    payload = f.read(length)
    if len(payload) < length or zlib.crc32(payload) != crc:
        raise JournalCorruptError(
            f"journal {path}: frame {frame} at offset {offset} fails its CRC check")
    return payload


def _scan(path: Path, fd: int) -> tuple[dict, list[int], int, int]:
    """Validate every frame: (header, record offsets, end of the last whole frame, file size)."""
    size = os.fstat(fd).st_size
    offsets: list[int] = []
    header: dict | None = None
    with open(fd, "rb", closefd=False) as f:
        f.seek(0)
        pos = 0
        frame = 0
        while pos < size:
            head = f.read(_FRAME.size)
            if len(head) < _FRAME.size:
                break  # torn frame header
            length, crc = _FRAME.unpack(head)
            if length > _MAX_FRAME:
                raise JournalCorruptError(
                    f"journal {path}: frame {frame} at offset {pos} claims {length} bytes "
                    f"(limit {_MAX_FRAME}); the file is damaged")
            payload = f.read(length)
            if len(payload) < length:
                break  # torn payload: the last write was cut off
            if zlib.crc32(payload) != crc:
                raise JournalCorruptError(
                    f"journal {path}: frame {frame} at offset {pos} fails its CRC check "
                    f"({size - pos} bytes from there to the end); the file is damaged. Nothing "
                    f"was dropped: move the file aside or truncate it at offset {pos} yourself")
            obj = _unpack(payload, path, frame, pos)
            if frame == 0:
                if obj.get("kind") != KIND:
                    raise JournalCorruptError(f"{path} is not an rhbl journal (no header)")
                if obj.get("format") != FORMAT:
                    raise JournalError(f"journal {path} has format {obj.get('format')!r}; "
                                       f"this version reads format {FORMAT}")
                base = obj.get("base", 0)
                if isinstance(base, bool) or not isinstance(base, int) or base < 0:
                    raise JournalCorruptError(
                        f"journal {path}: header field 'base' is {base!r}, expected an integer "
                        f">= 0")
                header = obj
            else:
                want = int(header.get("base", 0)) + frame - 1  # type: ignore[union-attr]
                if obj.get("i") != want:
                    raise JournalCorruptError(
                        f"journal {path}: frame {frame} at offset {pos} holds record "
                        f"{obj.get('i')!r}, expected {want}")
                offsets.append(pos)
            pos += _FRAME.size + length
            frame += 1
    if header is None:
        raise JournalCorruptError(f"journal {path} has no complete header ({size} bytes)")
    return header, offsets, pos, size
