"""One episode record for every driver: a run of the teacher, a corrective round or a tree from
a start pose, stepped in-process (``lab.harness``) or recorded from the server over zenoh
(``lab.demo``). Lists hold one entry per step unless said otherwise.

    ep = Episode(start=(x, y, yaw), kind="learner")
    ep.poses, ep.stalls, ep.actions, ep.side, ep.teacher_actions, ep.drivers, ep.ts, ep.ids
    ep.metrics(goal)          # lab.metrics.episode_metrics of this episode
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lab import metrics

__all__ = ["DT", "Episode"]

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

    def metrics(self, goal=None) -> dict:
        """Every per-episode metric (``lab.metrics.episode_metrics``)."""
        return metrics.episode_metrics(
            self.poses, self.stalls, self.actions, self.dt,
            side=self.side if self.side else None, goal=goal,
            teacher_actions=self.teacher_actions or None, start=self.start)
