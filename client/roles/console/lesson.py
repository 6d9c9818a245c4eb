"""What a person teaches at the console, per robot: episodes, undo, the tree's agreement with
the person's keys, and where the learned robot got into trouble (pure: no zenoh, no web; the
console's teaching session, ``client.roles.console.tutor``, feeds it and says it to the pages).

- **Episodes** (``Episode``): a stretch of teaching the person starts and stops, like a
  LeRobot recording episode. The first key with no episode recording opens one; ``stop``
  closes it; ``discard`` gives the label range to withdraw (the episode recording, else the
  last one kept); ``rerecord`` the same plus the pose it started from, to put the robot back.
- **Undo** (``undo(seconds)``): the range of labels given in the last ``seconds`` of teaching
  (sim time, back from the latest label still standing: undo again goes further back), not
  withdrawn yet. The caller withdraws it (``client.labels.LabelPublisher.withdraw``) and says
  so with ``withdrawn_range(first, upto)``.
- **Agreement**: each key the person gives is scored against what the tree the console holds
  would have done on that very scan (``scored``); ``agreement()`` is the share that agreed over
  the last ``window`` seconds of sim time: how often the robot would have done what the
  person did.
- **Trouble** (``Trouble``): while the controller drives, its commands go through the one loop
  detector (``client.behaviour.loops.LoopDetector``) and its states through a stall and a
  collision watch; each loop, stall (hardly moving for ``STALL_SECONDS``) and collision leaves a
  ``Marker`` where it happened, and ``stuck`` says the robot loops or stalls now (the page's
  "the robot is stuck here: show it the way"). The controller's own loop guard
  (``client.behaviour.guard.RotationGuard``) keeps such a loop off the bus: its decisions say
  when it stepped in (``Decision.looping``, fed to ``guarded``), which counts as a loop too
  (``stuck`` ``why`` ``guard``, a loop marker where it began) until ``GUARD_SECONDS`` pass
  without it.
- **Asks** (``Asks``): the places a tree's refinement by practice could not fix (``rhbl
  refine`` keeps them in the snapshot, ``lab.refine.ask``): those of the world shown, each
  with where to put the robot, "show me here" on the page; the labels given after the robot
  was put at one count as showing it there.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass

from client.behaviour.loops import LoopDetector

__all__ = ["AGREEMENT_WINDOW", "GUARD_SECONDS", "MAX_ASKS", "STALL_SECONDS", "UNDO_MAX", "Ask",
           "Asks", "Episode", "Marker", "Teaching", "Trouble"]

AGREEMENT_WINDOW = 60.0  # s of sim time the agreement is measured over
UNDO_MAX = 120.0  # s: the longest undo
HISTORY = 36_000  # labels remembered for undo (an hour at 10 Hz)
STALL_SECONDS = 5.0  # s of sim time the controller drives without moving STALL_METRES
STALL_METRES = 0.1
GUARD_SECONDS = 5.0  # s of sim time the guard's loop counts after the guard last stepped in
MARKERS = 200  # markers kept per robot (the newest)
NEAR = 0.3  # m: a marker of the same kind this close counts again instead of a new one
MAX_ASKS = 50  # asks of a tree listed at most (the first ones)
ASK_WHY = ("collision", "band", "failed")


@dataclass
class Episode:
    """One episode: number ``n``, where and when it started, its labels ``first <= seq <
    upto`` (None before its first label), how many stand, and ``state`` ``recording``,
    ``stopped`` or ``discarded``."""

    n: int
    start_pose: tuple[float, float, float] | None = None
    start_ts: float | None = None
    end_ts: float | None = None
    first: int | None = None
    upto: int | None = None
    labels: int = 0
    state: str = "recording"

    def to_json(self) -> dict:
        d = asdict(self)
        d["start_pose"] = None if self.start_pose is None else [round(v, 3)
                                                               for v in self.start_pose]
        return d


@dataclass
class Marker:
    """Where the learned robot got into trouble: ``kind`` ``loop``, ``stall`` or
    ``collision``, at (``x``, ``y``), first at sim time ``ts``, ``count`` times there."""

    kind: str
    x: float
    y: float
    ts: float
    count: int = 1

    def to_json(self) -> dict:
        return {"kind": self.kind, "x": round(self.x, 3), "y": round(self.y, 3),
                "ts": round(self.ts, 2), "count": self.count}


class Teaching:
    """Episodes, undo and agreement of one robot's labels (see the module)."""

    def __init__(self, window: float = AGREEMENT_WINDOW):
        self.window = float(window)
        self.episodes: list[Episode] = []
        self._history: deque[list] = deque(maxlen=HISTORY)  # [seq, ts, episode n, withdrawn]
        self._scores: deque[tuple[float, bool]] = deque()
        self.last_ts: float | None = None  # the latest label's sim time
        self.withdrawn = 0  # labels withdrawn (undo, discard)

    @property
    def current(self) -> Episode | None:
        """The episode recording now, if any."""
        e = self.episodes[-1] if self.episodes else None
        return e if e is not None and e.state == "recording" else None

    # -- episodes --
    def start(self, pose=None, ts: float | None = None) -> Episode:
        """Open a new episode (closing the one recording)."""
        self.stop(ts)
        e = Episode(n=len(self.episodes) + 1,
                    start_pose=None if pose is None else tuple(float(v) for v in pose),
                    start_ts=ts)
        self.episodes.append(e)
        return e

    def stop(self, ts: float | None = None) -> Episode | None:
        e = self.current
        if e is not None:
            e.state = "stopped"
            e.end_ts = ts if ts is not None else self.last_ts
        return e

    def labelled(self, seq: int, ts: float, pose=None) -> Episode:
        """A label was given (``seq`` of the session, for the scan of sim time ``ts``); the
        episode it belongs to (opened now when none records)."""
        e = self.current or self.start(pose, ts)
        if e.start_pose is None and pose is not None:
            e.start_pose, e.start_ts = tuple(float(v) for v in pose), ts
        if e.first is None:
            e.first = seq
        e.upto = seq + 1
        e.labels += 1
        self._history.append([seq, float(ts), e.n, False])
        self.last_ts = float(ts)
        return e

    def discard(self) -> tuple[Episode, int, int] | None:
        """The episode to discard (recording now, else the last one not discarded) and its
        label range; None when there is none with labels."""
        e = self.current or next((x for x in reversed(self.episodes)
                                  if x.state == "stopped"), None)
        if e is None or e.first is None or not e.labels:
            return None
        return e, e.first, e.upto

    def discarded(self, e: Episode) -> None:
        e.state = "discarded"
        if e.end_ts is None:
            e.end_ts = self.last_ts

    def undo(self, seconds: float) -> tuple[int, int] | None:
        """The labels of the last ``seconds`` of teaching still standing (back from the latest
        label standing: undo again goes further back): ``(first, upto)``, or None when there
        are none. ValueError outside 0 < seconds <= UNDO_MAX."""
        if not (isinstance(seconds, int | float) and not isinstance(seconds, bool)
                and 0 < seconds <= UNDO_MAX):
            raise ValueError(f"undo: seconds must be a number in (0, {UNDO_MAX:g}], got "
                             f"{seconds!r}")
        latest = next((h[1] for h in reversed(self._history) if not h[3]), None)
        if latest is None:
            return None
        cutoff = latest - float(seconds)
        seqs = [h[0] for h in reversed(self._history) if h[1] > cutoff + 1e-9 and not h[3]]
        if not seqs:
            return None
        return min(seqs), max(seqs) + 1

    def withdrawn_range(self, first: int, upto: int) -> int:
        """The labels ``first <= seq < upto`` were withdrawn; how many stood before."""
        n = 0
        by_n = {e.n: e for e in self.episodes}
        for h in reversed(self._history):
            if h[0] < first:
                break
            if h[0] < upto and not h[3]:
                h[3] = True
                n += 1
                by_n[h[2]].labels -= 1
        self.withdrawn += n
        return n

    # -- agreement --
    def scored(self, ts: float, agree: bool) -> None:
        """The tree would (``agree``) or would not have done what the person did at ``ts``."""
        self._scores.append((float(ts), bool(agree)))
        self._trim(float(ts))

    def _trim(self, now: float) -> None:
        while self._scores and (self._scores[0][0] < now - self.window
                                or self._scores[0][0] > now + 1e-6):
            self._scores.popleft()  # older than the window, or the clock restarted

    def agreement(self, now: float | None = None) -> tuple[float | None, int]:
        """(share of the keys of the last ``window`` s the tree agreed with, how many keys)."""
        if now is not None:
            self._trim(float(now))
        n = len(self._scores)
        return (sum(a for _, a in self._scores) / n if n else None), n

    def summary(self, now: float | None = None) -> dict:
        value, n = self.agreement(now)
        cur = self.current
        return {"episodes": [e.to_json() for e in self.episodes[-8:]],
                "episode": None if cur is None else cur.n,
                "withdrawn": self.withdrawn,
                "agreement": None if value is None else round(value, 4),
                "scored": n, "window": self.window}


class Trouble:
    """Where the learned robot looped, stalled or collided (see the module)."""

    def __init__(self, stall_seconds: float = STALL_SECONDS, stall_metres: float = STALL_METRES,
                 guard_seconds: float = GUARD_SECONDS):
        self.stall_seconds, self.stall_metres = float(stall_seconds), float(stall_metres)
        self.guard_seconds = float(guard_seconds)
        self._guard_ts: float | None = None  # sim time the controller's guard last stepped in
        self._now: float | None = None  # the latest State's sim time
        self.detector = LoopDetector()
        self.markers: list[Marker] = []
        self._poses: deque[tuple[float, float, float]] = deque()  # (ts, x, y) while it drives
        self._driving = False
        self._stalled = self._looped = self._collided = False
        self.changed = False  # a marker or the stuck state changed since the last look

    @property
    def guarding(self) -> bool:
        """The controller's loop guard stepped in within the last ``guard_seconds``."""
        return (self._guard_ts is not None and self._now is not None
                and self._guard_ts - 1e-6 <= self._now <= self._guard_ts + self.guard_seconds)

    @property
    def stuck(self) -> dict | None:
        """``{"why": "guard"|"loop"|"stall", "x", "y"}`` while the controller loops (its guard
        holds it from a loop, or its commands alternate) or stalls now."""
        guarding = self.guarding
        if not self._driving or not (guarding or self.detector.looping or self._stalled):
            return None
        why = "guard" if guarding else "loop" if self.detector.looping else "stall"
        _, x, y = self._poses[-1] if self._poses else (0.0, math.nan, math.nan)
        return {"why": why, "x": round(x, 3), "y": round(y, 3)}

    def state(self, ts: float, pose, stall: bool, controller_drives: bool) -> None:
        """A State of the robot: its sim time, true pose, stall flag, and whether the
        controller drives it."""
        was = self.guarding
        self._now = float(ts)
        if not controller_drives:
            if self._driving:
                self._driving = False
                self.detector.reset()
                self._poses.clear()
                self._stalled = self._looped = self._collided = False
                self._guard_ts = None
                self.changed = True
            return
        self._driving = True
        if self.guarding != was:
            self.changed = True
        x, y = float(pose[0]), float(pose[1])
        if self._poses and ts < self._poses[-1][0]:
            self._poses.clear()  # the server restarted
        self._poses.append((float(ts), x, y))
        while self._poses and self._poses[0][0] < ts - 2 * self.stall_seconds:
            self._poses.popleft()
        if stall and not self._collided:
            self._mark("collision", ts, x, y)
        self._collided = bool(stall)
        window = [p for p in self._poses if p[0] >= ts - self.stall_seconds]
        still = (self._poses[0][0] <= ts - self.stall_seconds
                 and max(math.hypot(px - window[0][1], py - window[0][2])
                         for _, px, py in window) < self.stall_metres)
        if still and not self._stalled and not self.detector.looping and not self.guarding:
            self._mark("stall", ts, x, y)
        if still != self._stalled:
            self._stalled = still
            self.changed = True

    def guarded(self, ts: float, looping: bool) -> None:
        """A decision of the controller for the scan of sim time ``ts``: whether its loop
        guard stepped in lately (``Decision.looping``). The first of a stretch leaves a loop
        marker where the robot is."""
        if not self._driving or not looping:
            return
        if self._guard_ts is not None and ts < self._guard_ts - 1e-6:
            self._guard_ts = None  # the server restarted
        if not self.guarding:
            _, x, y = self._poses[-1] if self._poses else (0.0, math.nan, math.nan)
            if math.isfinite(x):
                self._mark("loop", ts, x, y)
            self.changed = True
        self._guard_ts = float(ts)
        if self._now is None or self._now < ts:
            self._now = float(ts)

    def command(self, ts: float, action: str) -> None:
        """The action the controller commanded for the scan of sim time ``ts`` (while it
        drives: ``state`` says so)."""
        if not self._driving:
            return
        was = self.detector.looping
        now = self.detector.observe(ts, action)
        if now and not was:
            start = self.detector.current.start
            _, x, y = min(self._poses, key=lambda p: abs(p[0] - start)) if self._poses else (
                0.0, math.nan, math.nan)
            if math.isfinite(x):
                self._mark("loop", ts, x, y)
        if now != was:
            self.changed = True

    def _mark(self, kind: str, ts: float, x: float, y: float) -> None:
        for m in self.markers:
            if m.kind == kind and math.hypot(m.x - x, m.y - y) < NEAR:
                m.count += 1
                self.changed = True
                return
        self.markers.append(Marker(kind, x, y, float(ts)))
        del self.markers[:-MARKERS]
        self.changed = True

    def clear(self) -> None:
        """Forget the markers and the current state (a reset of the scene, a teleport)."""
        self.markers.clear()
        self.detector.reset()
        self._guard_ts = None
        self._poses.clear()
        self._stalled = self._looped = self._collided = False
        self.changed = True

    def summary(self) -> dict:
        return {"markers": [m.to_json() for m in self.markers], "stuck": self.stuck}


@dataclass
class Ask:
    """A place the tree's refinement could not fix: ``n`` (its number on the page, from 1),
    where to put the robot (``pose``), ``why`` the practice episode failed there
    (``collision``, ``band``: it left the wall's band, ``failed``), and how many labels the
    person gave since putting the robot there (``shown``)."""

    n: int
    pose: tuple[float, float, float]
    why: str
    shown: int = 0

    def to_json(self) -> dict:
        return {"n": self.n, "pose": [round(v, 3) for v in self.pose], "why": self.why,
                "shown": self.shown}


class Asks:
    """The asks of the tree the console holds, in the world it shows (see the module)."""

    def __init__(self):
        self.here: list[Ask] = []
        self.elsewhere = 0  # asks of other worlds, or of this one scaled (practice only)
        self.asking: Ask | None = None  # the ask the robot was last put at by the page
        self._shown: dict[tuple, int] = {}  # pose -> labels (kept across newer trees)
        self.changed = False

    @staticmethod
    def of(meta) -> list:
        """The asks of the latest refinement a snapshot's metadata records (a list of dicts;
        anything else: none)."""
        rec = meta.get("refinement") if isinstance(meta, dict) else None
        last = rec[-1] if isinstance(rec, list) and rec else None
        asks = last.get("asks") if isinstance(last, dict) else None
        return asks if isinstance(asks, list) else []

    def update(self, meta, world: str | None) -> None:
        """The asks of a newly fetched tree (its metadata ``meta``) in ``world`` (the world's
        name: an ask's world names it, or is a file of that name): a malformed one is left out."""
        here, elsewhere = [], 0
        for a in self.of(meta):
            pose = a.get("pose") if isinstance(a, dict) else None
            if (not isinstance(pose, list) or len(pose) != 3
                    or not all(isinstance(v, int | float) and not isinstance(v, bool)
                               and math.isfinite(v) for v in pose)):
                continue
            name = a.get("world")
            scale = a.get("scale", 1.0)
            if (world is None or not isinstance(name, str) or scale != 1.0
                    or world not in (name, name.rsplit("/", 1)[-1].removesuffix(".toml"))):
                elsewhere += 1
                continue
            if len(here) >= MAX_ASKS:
                continue
            why = a.get("why") if a.get("why") in ASK_WHY else "failed"
            key = tuple(round(float(v), 3) for v in pose)
            here.append(Ask(len(here) + 1, key, why, self._shown.get(key, 0)))
        if [x.to_json() for x in here] != [x.to_json() for x in self.here] \
                or elsewhere != self.elsewhere:
            self.changed = True
        self.here, self.elsewhere = here, elsewhere
        if self.asking is not None:
            self.asking = next((x for x in here if x.pose == self.asking.pose), None)

    def place(self, n) -> Ask:
        """The ask numbered ``n`` (the page put the robot there: labels count for it from
        now). ValueError naming what was wrong."""
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= len(self.here):
            raise ValueError(f"'ask' must be the number of an ask, 1..{len(self.here)}, got "
                             f"{n!r:.40}" if self.here else "the tree asks for nothing here")
        self.asking = self.here[n - 1]
        self.changed = True
        return self.asking

    def moved(self) -> None:
        """The robot was put somewhere else (a start, dragged, reset)."""
        self.asking = None

    def labelled(self) -> None:
        """A label was given: it shows the ask the robot was put at, if any."""
        a = self.asking
        if a is not None:
            a.shown += 1
            self._shown[a.pose] = a.shown
            self.changed = True

    def summary(self) -> dict:
        return {"asks": [a.to_json() for a in self.here], "asks_elsewhere": self.elsewhere,
                "asking": None if self.asking is None else self.asking.n}
