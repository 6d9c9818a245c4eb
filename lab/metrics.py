"""Behaviour metrics: pure functions over a recorded trajectory (no simulator, no zenoh).

The in-process evaluator and the zenoh demo (from recorded server state messages) compute the same
numbers with these functions. Inputs are plain sequences: ``poses`` (N, 3) of (x, y, yaw) true
poses, ``stalls`` (N,) bools, ``actions`` (N,) action names, ``side`` (N,) distance in metres from
the robot to the nearest wall on the followed side at each step, ``dt`` the step in seconds.

    collisions(stalls) -> int                         # stall onsets (False -> True transitions)
    distance(poses) -> float                          # metres travelled (sum of step lengths)
    side_distance(ranges, side="right", sector_deg=60.0) -> float
                                                      # nearest wall on one side of a 180-deg scan
    wall_band_fraction(side, lo=0.3, hi=1.2) -> float # fraction of steps with lo <= side <= hi
    goal_reached(poses, goal, dt) -> (bool | None, float | None)
                                                      # goal = ((x, y), radius) or None
    oscillations(actions, a="rot-left", b="rot-right") -> int
                                                      # a/b alternations (runs of the same action
                                                      # count once; other actions break the chain)
    oscillation_loops(actions, poses, dt, min_alternations=4, window_s=6.0) -> list[dict]
                                                      # where loops happened: {"step", "time",
                                                      #  "pose": [x, y, yaw], "alternations"}
    teacher_agreement(actions, teacher_actions) -> float | None
    progress_stuck(poses, dt, window_s=30.0, min_progress=0.5) -> bool
    covered_area(poses, cell=0.5) -> float            # m^2 of the cells of ``cell`` m entered
    goals_in_order(poses, targets, dt) -> [times]     # targets ((x, y, radius), ...) in order:
                                                      # when each was reached after the one before
    centred_fraction(gaps, tolerance=0.3) -> float    # fraction of steps with |left - right| <= it
    wall_success(m, teacher_distance, band=0.8, ratio=0.7) -> bool
    maze_success(m) -> bool
    judge(rules, m, teacher_m=None) -> bool           # a behaviour's success rule (every rule holds)
    episode_metrics(poses, stalls, actions, dt, side=None, goal=None, teacher_actions=None,
                    start=None, rules=None, gaps=None) -> dict
                                                      # every per-episode field of evaluate's JSON
    summarize(values) -> {"mean", "std", "min", "max", "n"}
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from client.behaviour.loops import LoopDetector

__all__ = [
    "BAND",
    "centred_fraction",
    "collisions",
    "covered_area",
    "distance",
    "episode_metrics",
    "goal_reached",
    "goals_in_order",
    "judge",
    "maze_success",
    "oscillation_loops",
    "oscillations",
    "progress_stuck",
    "side_distance",
    "summarize",
    "teacher_agreement",
    "wall_band_fraction",
    "wall_success",
]

BAND = (0.3, 1.2)


def collisions(stalls: Sequence[bool]) -> int:
    """Number of stall onsets: a step that stalls after one that did not (or the first step)."""
    s = np.asarray(stalls, dtype=bool)
    if s.size == 0:
        return 0
    return int(s[0]) + int(np.count_nonzero(s[1:] & ~s[:-1]))


def distance(poses) -> float:
    """Metres travelled: the sum of the straight lines between consecutive poses."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3) if len(poses) else np.zeros((0, 3))
    if len(p) < 2:
        return 0.0
    return float(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1])).sum())


def side_distance(ranges, side: str = "right", sector_deg: float = 60.0,
                  fov_deg: float = 180.0) -> float:
    """Nearest wall on one side: min range over the beams within ``sector_deg`` of that side's
    edge of a ``fov_deg`` scan (ranges[0] is the robot's right)."""
    r = np.asarray(ranges)
    if r.dtype.kind != "f":  # a float32 scan's minimum is the same number as a float64 copy's
        r = r.astype(np.float64)
    k = int(round(sector_deg / fov_deg * (r.size - 1)))
    part = r[: k + 1] if side == "right" else r[r.size - 1 - k:]
    return float(part.min())


def wall_band_fraction(side: Sequence[float], lo: float = BAND[0], hi: float = BAND[1]) -> float:
    """Fraction of steps whose followed-side wall distance lies in [lo, hi]."""
    d = np.asarray(side, dtype=np.float64)
    if d.size == 0:
        return 0.0
    return float(np.count_nonzero((d >= lo) & (d <= hi)) / d.size)


def goal_reached(poses, goal, dt: float) -> tuple[bool | None, float | None]:
    """(reached, time of the first step inside the goal circle); (None, None) without a goal.
    ``goal`` is ((x, y), radius) or any object with ``center`` and ``radius``."""
    if goal is None:
        return None, None
    if hasattr(goal, "center"):
        (gx, gy), radius = goal.center, goal.radius
    else:
        (gx, gy), radius = goal
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return False, None
    inside = np.hypot(p[:, 0] - gx, p[:, 1] - gy) <= radius
    if not inside.any():
        return False, None
    i = int(np.argmax(inside))
    return True, round((i + 1) * dt, 6)


def _runs(actions: Sequence[str]) -> list[tuple[str, int]]:
    """(action, first step) of each run of equal consecutive actions."""
    out: list[tuple[str, int]] = []
    for i, a in enumerate(actions):
        if not out or out[-1][0] != a:
            out.append((a, i))
    return out


def oscillations(actions: Sequence[str], a: str = "rot-left", b: str = "rot-right") -> int:
    """Number of direct a<->b switches (a run of a followed immediately by a run of b, or the
    reverse). A robot that rotates left, then right, then left has 2."""
    runs = _runs(actions)
    return sum(1 for (p, _), (q, _) in zip(runs, runs[1:], strict=False) if {p, q} == {a, b})


def oscillation_loops(actions: Sequence[str], poses, dt: float, min_alternations: int = 4,
                      window_s: float = 6.0, a: str = "rot-left", b: str = "rot-right") -> list[dict]:
    """Where rotate-left/rotate-right loops happened: groups of at least ``min_alternations``
    a<->b switches each within ``window_s`` of the previous (``client.behaviour.loops``, the
    one definition, which the console and a controller apply live). Each loop gives the step,
    time and pose where it began (pass that pose to ``rhbl train --resume ... --start``)."""
    detector = LoopDetector(min_alternations, window_s, a, b)
    for i, action in enumerate(actions):
        detector.observe(i * dt, action)
    detector.flush()
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3) if len(poses) else np.zeros((0, 3))
    loops: list[dict] = []
    for loop in detector.loops:
        step = max(0, int(round(loop.start / dt)))
        pose = [round(float(v), 3) for v in p[step]] if len(p) > step else None
        loops.append({"step": step, "time": round(step * dt, 3), "pose": pose,
                      "alternations": loop.alternations})
    return loops


def teacher_agreement(actions: Sequence[str], teacher_actions: Sequence[str] | None) -> float | None:
    """Fraction of steps on which the teacher would have chosen the learner's action."""
    if teacher_actions is None:
        return None
    n = min(len(actions), len(teacher_actions))
    if n == 0:
        return None
    same = sum(1 for x, y in zip(actions[:n], teacher_actions[:n], strict=True) if x == y)
    return same / n


def progress_stuck(poses, dt: float, window_s: float = 30.0, min_progress: float = 0.5) -> bool:
    """True when some ``window_s`` window moved the robot less than ``min_progress`` metres from
    where the window began (the prototype's 'never < 0.5 m of progress in 30 s')."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3) if len(poses) else np.zeros((0, 3))
    w = int(round(window_s / dt))
    if len(p) <= w:
        return False
    xy = p[:, :2]
    for s in range(0, len(p) - w, max(1, w // 6)):
        seg = xy[s: s + w + 1]
        if np.hypot(*(seg - seg[0]).T).max() < min_progress:
            return True
    return False


def wall_success(m: dict, teacher_distance: float | None, band: float = 0.8,
                 ratio: float = 0.7) -> bool:
    """Wall following succeeds: no collision, wall band fraction >= ``band`` and distance at
    least ``ratio`` of the teacher's from the same start."""
    ok = m["collisions"] == 0 and m["wall_band_fraction"] >= band
    if teacher_distance is not None:
        ok = ok and m["distance"] >= ratio * teacher_distance
    return bool(ok)


def maze_success(m: dict) -> bool:
    """Maze succeeds: goal reached with no collision (within the episode's time)."""
    return bool(m["goal_reached"]) and m["collisions"] == 0


def covered_area(poses, cell: float = 0.5) -> float:
    """Ground covered: square metres of the distinct ``cell`` x ``cell`` m grid cells the robot
    was in at some step."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3) if len(poses) else np.zeros((0, 3))
    if len(p) == 0:
        return 0.0
    cells = np.unique(np.floor(p[:, :2] / cell).astype(np.int64), axis=0)
    return float(len(cells) * cell * cell)


def centred_fraction(gaps: Sequence[float], tolerance: float = 0.3) -> float:
    """Fraction of steps whose ``gaps`` (the nearest wall on the left minus the nearest on the
    right, metres) lie within +/- ``tolerance``: the robot centred between the walls."""
    g = np.asarray(gaps, dtype=np.float64)
    if g.size == 0:
        return 0.0
    return float(np.count_nonzero(np.abs(g) <= tolerance) / g.size)


def goals_in_order(poses, targets, dt: float) -> list[float]:
    """The times (s) at which the robot's centre came within each target's radius (``targets``:
    ``(x, y, radius)`` in the order they are to be reached), each after the one before; as many
    times as targets reached in order (a goal passed out of order does not count)."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3) if len(poses) else np.zeros((0, 3))
    times: list[float] = []
    i = 0
    for x, y, radius in targets:
        inside = np.hypot(p[i:, 0] - x, p[i:, 1] - y) <= radius
        if not inside.any():
            break
        i += int(np.argmax(inside))
        times.append(round((i + 1) * dt, 6))
    return times


def judge(rules: dict, m: dict, teacher_m: dict | None = None) -> bool:
    """A behaviour's success rule (``client.behaviour.spec.RULES``: rule -> its parameters) on
    an episode's metrics ``m`` (``episode_metrics`` given the same ``rules``): True when every
    rule holds. ``teacher_m``: the scripted expert's metrics from the same start, for
    ``distance``'s ``of_teacher`` (None: not compared). The one success rule of every
    behaviour; ``time-limit`` is the episode's length, which the driver keeps."""
    for rule, p in rules.items():
        if rule == "time-limit":
            continue
        if rule == "no-collision":
            ok = m["collisions"] == 0
        elif rule == "distance":
            ok = m["distance"] >= p["metres"]
            if teacher_m is not None and p["of_teacher"] > 0:
                ok = ok and m["distance"] >= p["of_teacher"] * teacher_m["distance"]
        elif rule == "progress":
            ok = not m["stuck"]
        elif rule == "wall-band":
            ok = m["wall_band_fraction"] is not None and m["wall_band_fraction"] >= p["fraction"]
        elif rule == "centred":
            ok = m.get("centred_fraction") is not None and m["centred_fraction"] >= p["fraction"]
        elif rule == "goal":
            ok = bool(m["goal_reached"])
        elif rule == "coverage":
            ok = m.get("covered_area") is not None and m["covered_area"] >= p["area"]
        elif rule == "goals":
            ok = m.get("goals_total") is not None and m["goals_reached"] >= m["goals_total"]
        else:
            raise ValueError(f"no success rule {rule!r}")
        if not ok:
            return False
    return True


def episode_metrics(poses, stalls, actions, dt: float, side=None, goal=None,
                    teacher_actions=None, start=None, band=BAND, rules: dict | None = None,
                    gaps=None, targets=None) -> dict:
    """Every per-episode field of ``rhbl evaluate --json`` (except ``success``). ``rules`` (a
    behaviour's success rule) sets the band of ``wall-band``, the window of ``progress`` and
    adds ``centred_fraction`` (from ``gaps``, per step: left minus right wall distance) and
    ``covered_area`` when it has ``centred`` or ``coverage``; ``targets`` (a goal behaviour's
    beacons in the order of its goals, ``(x, y, radius)``) adds ``goals_reached``,
    ``goals_total`` and ``goal_times`` (``goals_in_order``)."""
    rules = rules or {}
    if "wall-band" in rules:
        band = (rules["wall-band"]["near"], rules["wall-band"]["far"])
    progress = rules.get("progress", {"window": 30.0, "metres": 0.5})
    reached, t_goal = goal_reached(poses, goal, dt)
    if reached:
        # the episode is judged up to the goal: count stalls before it only
        k = int(round(t_goal / dt))
        stalls, actions = list(stalls)[:k], list(actions)[:k]
    n = len(actions)
    return {
        "start": [round(float(v), 4) for v in start] if start is not None else None,
        "seconds": round(len(poses) * dt, 6),
        "collisions": collisions(stalls),
        "distance": round(distance(poses), 4),
        "wall_band_fraction": round(wall_band_fraction(side, *band), 4) if side is not None else None,
        "goal_reached": reached,
        "time_to_goal": t_goal,
        "oscillations": oscillations(actions),
        "oscillation_loops": oscillation_loops(actions, poses, dt),
        "teacher_agreement": (round(v, 4) if (v := teacher_agreement(
            actions, None if teacher_actions is None else list(teacher_actions)[:n])) is not None else None),
        "stuck": progress_stuck(poses, dt, progress["window"], progress["metres"]),
    } | ({"centred_fraction": round(centred_fraction(gaps or (), rules["centred"]["tolerance"]), 4)}
         if "centred" in rules else {}) | (
        {"covered_area": round(covered_area(poses, rules["coverage"]["cell"]), 4)}
        if "coverage" in rules else {}) | (_goal_fields(poses, targets, dt)
                                           if targets is not None else {})


def _goal_fields(poses, targets, dt: float) -> dict:
    times = goals_in_order(poses, targets, dt)
    return {"goals_reached": len(times), "goals_total": len(targets), "goal_times": times}


def summarize(values: Sequence[float]) -> dict:
    v = np.asarray([x for x in values if x is not None and not (isinstance(x, float) and math.isnan(x))],
                   dtype=np.float64)
    if v.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None, "n": 0}
    return {"mean": float(v.mean()), "std": float(v.std()), "min": float(v.min()),
            "max": float(v.max()), "n": int(v.size)}
