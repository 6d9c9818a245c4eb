"""One episode record for every driver: a run of the teacher, a corrective round or a tree from
a start pose, stepped in-process (``lab.harness``) or collected from the bus over zenoh
(``EpisodeCollector``, ``rhbl demo``). Lists hold one entry per step unless said otherwise.

    ep = Episode(start=(x, y, yaw), kind="learner")
    ep.poses, ep.stalls, ep.actions, ep.side, ep.teacher_actions, ep.drivers, ep.ts, ep.ids
    ep.metrics(goal)          # lab.metrics.episode_metrics of this episode

    collector = EpisodeCollector("r0", actions, side)   # a sink of client.recording.tap.BusTap
    ep = collector.begin("teacher", pose); ...; collector.end()
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

from lab import metrics
from protocol.decoding import Decoder
from protocol.messages import Scan, State, TeacherAction, TreeNotice, VelCmd

__all__ = ["DT", "Episode", "EpisodeCollector"]

log = logging.getLogger(__name__)

DT = 0.1  # s: 10 Hz, as the processes run


@dataclass
class Episode:
    start: tuple[float, float, float]
    dt: float = DT
    kind: str = ""  # "training" | "teacher" | "round" | "learner" | ...
    round: int = 0  # the corrective round it belongs to (0: none)
    poses: list = field(default_factory=list)  # true pose after each step
    stalls: list = field(default_factory=list)  # the step pushed into a wall
    actions: list = field(default_factory=list)  # the executed action's name
    side: list = field(default_factory=list)  # followed-side wall distance (a side-following task)
    gaps: list = field(default_factory=list)  # left minus right wall distance (a centring task)
    teacher_actions: list = field(default_factory=list)  # the teacher's choice on these states
    drivers: list = field(default_factory=list)  # who drove ("teacher", "controller"), if known
    ts: list = field(default_factory=list)  # sim time of each step, if known (a recording)
    ids: list = field(default_factory=list)  # the server's scan id of each step (a recording)
    labels: list = field(default_factory=list)  # teacher labels given (not per step)
    segments: list = field(default_factory=list)  # training: start pose of each demonstration
    learned: int = 0  # training: labelled vectors the learner took
    wall_time: float = 0.0

    @property
    def sim_time(self) -> float:
        """Sim seconds covered: from the first to the last step's time when recorded, else
        steps x dt."""
        if self.ts:
            return (self.ts[-1] - self.ts[0]) if len(self.ts) > 1 else 0.0
        return len(self.poses) * self.dt

    @property
    def teacher_ticks(self) -> int:
        """Steps the teacher drove (in a corrective round: took over)."""
        return sum(1 for d in self.drivers if d == "teacher")

    def metrics(self, goal=None, rules: dict | None = None, targets=None) -> dict:
        """Every per-episode metric (``lab.metrics.episode_metrics``; ``rules``: a behaviour's
        success rule, whose parameters some metrics take; ``targets``: its goals in order,
        ``lab.goals.targets``)."""
        return metrics.episode_metrics(
            self.poses, self.stalls, self.actions, self.dt,
            side=self.side if self.side else None, goal=goal,
            teacher_actions=self.teacher_actions or None, start=self.start, rules=rules,
            gaps=self.gaps, targets=targets)


@dataclass
class _Arrivals:
    """What arrives for the current episode besides its scans, keyed until it ends."""

    stalls: dict = field(default_factory=dict)  # ts -> stall
    cmds: dict = field(default_factory=dict)  # scan id -> (source, vx, va) (teacher's first)
    drivers: dict = field(default_factory=dict)  # ts -> driving source (State.driver)
    first_id: int = 0  # scans before this one (the old pose, before a teleport) are ignored
    last_id: int | None = None  # scans after this one are not the episode's (``stop``)
    label_ids: list = field(default_factory=list)  # the scan of each of the episode's labels


class EpisodeCollector:
    """A bus tap's sink (``client.recording.tap.Sink``): the server's scans, states and
    commands of ``robot`` go into the current episode (``begin`` .. ``end``); the teacher's
    labels, the commands per source and the learner's last notice are counted throughout.
    The tap's thread delivers; the owner calls ``tap.sync()`` before ``begin`` and ``end`` so an
    episode holds exactly what arrived between them."""

    def __init__(self, robot: str, actions, side: str | None):
        self.robot = robot
        self.episode: Episode | None = None
        self.raw = _Arrivals()
        self.names = {tuple(v): k for k, v in actions.items()}  # (vx, va) -> action name
        self.side = side  # the followed side (Episode.side), None: not recorded
        self.lock = threading.Lock()
        self.notice: dict = {}
        self.sources: dict[str, int] = {}  # commands seen per source (in an episode or not)
        self.labels = 0  # teacher labels seen (in an episode or not)
        self.last_label_scan: int | None = None  # the scan of the episode's latest label
        self.decoder = Decoder(log, level=logging.DEBUG)  # a malformed message is left out
        self._on = {"scan": self._on_scan, "state": self._on_state, "cmd": self._on_cmd,
                    "notice": self._on_notice, "label": self._on_label}

    # -- the sink --
    def write(self, key, data, recv_ns, kind=None, robot=None, sim_time=None) -> None:
        on = self._on.get(kind)
        if on is not None and robot == self.robot:
            on(data)

    def write_alive(self, key, alive, recv_ns) -> None:
        pass

    def maybe_flush(self, now=None) -> None:
        pass

    def close(self) -> None:
        pass

    # -- what it keeps --
    def _on_scan(self, data: bytes) -> None:
        ep = self.episode
        if ep is None:
            return
        s = self.decoder.decode(Scan, data)
        if s is None:
            return
        with self.lock:
            last = self.raw.last_id
            if ep is self.episode and s.id >= self.raw.first_id and (last is None
                                                                     or s.id <= last):
                ep.ts.append(s.ts)
                ep.poses.append(s.truth if s.truth is not None else s.pose)
                if self.side is not None:
                    ep.side.append(metrics.side_distance(s.ranges, self.side))
                ep.ids.append(s.id)

    def _on_state(self, data: bytes) -> None:
        if self.episode is None:
            return
        st = self.decoder.decode(State, data)
        if st is None:
            return
        with self.lock:  # (``trim`` rebuilds the episode's states meanwhile)
            raw = self.raw
            raw.stalls[round(st.ts, 6)] = bool(st.stall)
            raw.drivers[round(st.ts, 6)] = st.driver

    def _on_label(self, data: bytes) -> None:
        self.labels += 1
        if self.episode is None:
            return
        act = self.decoder.decode(TeacherAction, data)
        with self.lock:
            ep, raw = self.episode, self.raw
            if ep is None or (act is not None and not raw.first_id <= act.scan_id <= (
                    act.scan_id if raw.last_id is None else raw.last_id)):
                return  # none open now, or a label of a scan that is not the episode's
            ep.labels.append(None if act is None else act.action)  # offered to the learner
            raw.label_ids.append(None if act is None else act.scan_id)
            self.last_label_scan = None if act is None else act.scan_id

    def _on_cmd(self, data: bytes) -> None:
        c = self.decoder.decode(VelCmd, data)
        if c is None:
            return
        self.sources[c.source] = self.sources.get(c.source, 0) + 1
        with self.lock:  # (``trim`` rebuilds the episode's commands meanwhile)
            ep, raw = self.episode, self.raw
            if ep is not None and c.scan_id is not None:
                # the teacher outranks the controller (the server's arbitration)
                old = raw.cmds.get(c.scan_id)
                if old is None or old[0] != "teacher" or c.source == "teacher":
                    raw.cmds[c.scan_id] = (c.source, c.vx, c.va)

    def _on_notice(self, data: bytes) -> None:
        n = self.decoder.decode(TreeNotice, data)
        if n is not None:
            self.notice = {"nodes": n.nodes, "height": n.height, "vectors": n.vectors}

    # -- episodes --
    def begin(self, kind: str, start, round_: int = 0) -> Episode:
        with self.lock:
            self.raw = _Arrivals()
            self.last_label_scan = None
            self.episode = Episode(start=tuple(start), dt=DT, kind=kind, round=round_)
            return self.episode

    def trim(self, ep: Episode, first_id: int) -> None:
        """Forget what ``ep`` recorded before scan ``first_id`` (scans of the old pose that
        arrived between ``begin`` and a teleport)."""
        with self.lock:
            raw = self.raw
            raw.first_id = first_id  # and a late scan of the old pose is not recorded either
            keep = [k for k, i in enumerate(ep.ids) if i >= first_id]
            for f in ("ts", "poses", "side", "ids"):
                col = getattr(ep, f)
                if col:
                    setattr(ep, f, [col[k] for k in keep])
            raw.cmds = {i: c for i, c in raw.cmds.items() if i >= first_id}
            mine = [k for k, i in enumerate(raw.label_ids) if i is None or i >= first_id]
            ep.labels = [ep.labels[k] for k in mine]  # labels of the old pose's scans go too
            raw.label_ids = [raw.label_ids[k] for k in mine]
            if ep.ts:
                raw.stalls = {t: v for t, v in raw.stalls.items() if t >= round(ep.ts[0], 6)}
                raw.drivers = {t: v for t, v in raw.drivers.items() if t >= round(ep.ts[0], 6)}

    def stop(self, ep: Episode) -> int | None:
        """``ep`` takes no scan after those it has (its last scan's id, None if none): the
        labels of its scans may still come (a teacher behind the server), until ``end``."""
        with self.lock:
            last = ep.ids[-1] if ep.ids else None
            if ep is self.episode and last is not None:
                self.raw.last_id = last
            return last

    def end(self) -> None:
        """Close the current episode: each recorded scan gets the action executed on it (the
        teacher's over the controller's; "none" if no command came), its stall and its driver."""
        with self.lock:
            ep, raw = self.episode, self.raw
            self.episode = None
            if ep is None:
                return
            for ts, sid in zip(ep.ts, ep.ids, strict=True):
                cmd = raw.cmds.get(sid)
                ep.actions.append(self.names.get((cmd[1], cmd[2]), "none") if cmd else "none")
                ep.stalls.append(raw.stalls.get(round(ts, 6), False))
                ep.drivers.append(raw.drivers.get(round(ts, 6)))
