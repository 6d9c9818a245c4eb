"""World files: walls, goal, beacons and start poses read from TOML (docs/protocol.md section
10), validated into a :class:`WorldSpec`; poses drawn in a world's free space.

    spec = load_world(server.world_path("room"))    # WorldError naming the file and key
    spec = parse_world({"name": ..., "robot": {...}, "walls": [...]})   # from a mapping
    pose = free_pose(spec, rng)                      # anywhere in the free space

``server.world.World`` simulates a robot in one.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from protocol.messages import MAX_BEACONS
from server.robot import ROBOT, Pose

__all__ = ["BEACON_COLOURS", "TASKS", "Beacon", "Goal", "Wall", "WorldError", "WorldSpec",
           "free_pose", "load_world", "parse_world", "point_segment_distance", "sample_pose"]

TASKS = ("wall-following", "maze", "doorways", "dead-end", "corridor-centring", "wandering",
         "red-green")

# the colours a beacon may name (``colour = "red"``), else ``[r, g, b]`` of 0..255
BEACON_COLOURS: dict[str, tuple[int, int, int]] = {
    "red": (220, 40, 40), "green": (40, 170, 60), "blue": (40, 90, 220),
    "yellow": (230, 200, 30), "orange": (240, 140, 20), "purple": (140, 60, 190),
    "cyan": (30, 190, 200), "magenta": (210, 50, 170), "white": (245, 245, 245),
    "black": (20, 20, 20), "grey": (128, 128, 128),
}
_DEFAULT_BEACON_SIZE = 0.2  # m


class WorldError(ValueError):
    """A world file is missing, unreadable or malformed (the message names file and key)."""


@dataclass(frozen=True)
class Wall:
    points: tuple[tuple[float, float], ...]
    closed: bool = False

    def segments(self) -> list[tuple[float, float, float, float]]:
        pts = list(self.points)
        if self.closed and len(pts) > 2:
            pts.append(pts[0])
        return [(a[0], a[1], b[0], b[1]) for a, b in zip(pts[:-1], pts[1:], strict=True)]


@dataclass(frozen=True)
class Goal:
    center: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class Beacon:
    """A fiducial beacon (``[[beacons]]`` of a world file): ``id`` (>= 1; 0 is what a fiducial
    finder reports for a beacon it sees but cannot identify), the centre ``pos`` [x, y] (m),
    ``colour`` [r, g, b] (0..255) and ``size`` (m, its diameter)."""

    id: int
    pos: tuple[float, float]
    colour: tuple[int, int, int] = BEACON_COLOURS["orange"]
    size: float = _DEFAULT_BEACON_SIZE


@dataclass(frozen=True)
class WorldSpec:
    """A parsed world file. ``pose`` is the default start; ``starts`` extra start poses."""

    name: str
    # an older world file's ``task`` (a shipped behaviour's name), kept as a hint only: worlds
    # name no task, a behaviour names its worlds (client.behaviour.spec.for_world); None mostly
    task: str | None
    pose: tuple[float, float, float]
    starts: tuple[tuple[float, float, float], ...] = ()
    walls: tuple[Wall, ...] = ()
    goal: Goal | None = None
    path: Path | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)
    beacons: tuple[Beacon, ...] = ()

    def beacon(self, beacon_id: int) -> Beacon | None:
        """The beacon of id ``beacon_id`` (None: the world has none)."""
        for b in self.beacons:
            if b.id == beacon_id:
                return b
        return None

    @property
    def start_poses(self) -> list[tuple[float, float, float]]:
        """``[pose] + starts``, duplicates removed, in order."""
        out: list[tuple[float, float, float]] = []
        for p in (self.pose, *self.starts):
            if p not in out:
                out.append(p)
        return out

    def segments(self) -> np.ndarray:
        """All wall segments as an (S, 4) float64 array of x0, y0, x1, y1."""
        segs = [s for w in self.walls for s in w.segments()]
        return np.asarray(segs, dtype=np.float64).reshape(-1, 4)

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all walls."""
        s = self.segments()
        xs = np.concatenate([s[:, 0], s[:, 2]])
        ys = np.concatenate([s[:, 1], s[:, 3]])
        return float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())

    def clearance(self, x: float, y: float) -> float:
        """Distance from (x, y) to the nearest wall segment (inf in a world without walls)."""
        segs = self.segments()
        if len(segs) == 0:
            return float("inf")
        return float(point_segment_distance(np.array([x, y]), segs).min())

    def inside(self, x: float, y: float) -> bool:
        """True when (x, y) lies in the free space the closed wall polylines bound: inside an
        odd number of them (the even-odd rule over all of them: inside the outer wall and
        outside every box, pillar or island drawn as a closed polyline within it; a world with
        no closed wall: everywhere)."""
        count = 0
        closed = [w for w in self.walls if w.closed]
        for w in closed:
            inside = False
            for x0, y0, x1, y1 in w.segments():
                if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                    inside = not inside
            count += inside
        return not closed or count % 2 == 1

    def scaled(self, factor: float) -> WorldSpec:
        """A copy uniformly scaled about the origin by ``factor``: wall points, start poses
        (headings kept) and the goal centre (radius kept); named ``<name>x<factor>``, no path."""
        if not (factor > 0 and math.isfinite(factor)):
            raise ValueError(f"scale factor must be a finite number > 0, got {factor}")

        def pose(p):
            return (p[0] * factor, p[1] * factor, p[2])

        walls = tuple(Wall(tuple((x * factor, y * factor) for x, y in w.points), w.closed)
                      for w in self.walls)
        goal = None if self.goal is None else Goal(
            (self.goal.center[0] * factor, self.goal.center[1] * factor), self.goal.radius)
        beacons = tuple(replace(b, pos=(b.pos[0] * factor, b.pos[1] * factor))
                        for b in self.beacons)
        return replace(self, name=f"{self.name}x{factor:g}", pose=pose(self.pose),
                       starts=tuple(pose(p) for p in self.starts), walls=walls, goal=goal,
                       beacons=beacons, path=None)


# ------------------------------------------------------------------------- free-space poses


def free_pose(spec: WorldSpec, rng: np.random.Generator, clearance: float = 0.45,
              tries: int = 200) -> Pose | None:
    """A pose anywhere in the world's free space: position uniform over the walls' bounding
    box, inside the closed walls and at least ``clearance`` metres from every wall, heading
    uniform. Needs no map-specific code (any world file). None if none was found."""
    x0, y0, x1, y1 = spec.bounds()
    for _ in range(tries):
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        if spec.clearance(x, y) >= clearance and spec.inside(x, y):
            return Pose(round(x, 3), round(y, 3), round(float(rng.uniform(-math.pi, math.pi)), 4))
    return None


def sample_pose(spec: WorldSpec, visited, rng: np.random.Generator, jitter: float = 0.3,
                turn: float = math.pi, clearance: float = 0.45, tries: int = 50) -> Pose | None:
    """A pose near one of ``visited`` (so it lies in the reachable free space of any world, no
    map-specific code): position jittered by ``jitter`` metres (normal), heading turned by up to
    +/- ``turn`` rad (uniform; pi = any heading), at least ``clearance`` metres from every wall.
    None when ``visited`` is empty or no such pose was found."""
    if not len(visited):
        return None
    for _ in range(tries):
        x, y, yaw = visited[int(rng.integers(len(visited)))]
        x += float(rng.normal(0.0, jitter))
        y += float(rng.normal(0.0, jitter))
        yaw += float(rng.uniform(-turn, turn))
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        if spec.clearance(x, y) >= clearance:
            return Pose(round(x, 3), round(y, 3), round(yaw, 4))
    return None


# ---------------------------------------------------------------------------------- loading


def _err(src: str, key: str, expected: str, got: Any) -> WorldError:
    return WorldError(f"{src}: key '{key}': expected {expected}, got {got!r}")


def _number(src: str, key: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _err(src, key, "a finite number", v)
    return float(v)


def _vec(src: str, key: str, v: Any, n: int, what: str) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n:
        raise _err(src, key, f"{what} (a list of {n} numbers)", v)
    return tuple(_number(src, f"{key}[{i}]", x) for i, x in enumerate(v))


def point_segment_distance(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    a = segs[:, 0:2]
    e = segs[:, 2:4] - a
    ee = np.einsum("ij,ij->i", e, e)
    t = np.clip(np.einsum("ij,ij->i", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    d = a + t[:, None] * e - p
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def _parse_walls(src: str, walls_raw: Any) -> list[Wall]:
    if not isinstance(walls_raw, list) or not walls_raw:
        raise _err(
            src, "walls", "at least one [[walls]] table with points = [[x, y], ...]", walls_raw
        )
    walls = []
    for i, w in enumerate(walls_raw):
        key = f"walls[{i}]"
        if not isinstance(w, dict):
            raise _err(src, key, "a table with points = [[x, y], ...]", w)
        pts_raw = w.get("points")
        if not isinstance(pts_raw, list) or len(pts_raw) < 2:
            raise _err(src, f"{key}.points", "a list of at least 2 [x, y] points", pts_raw)
        pts = tuple(
            _vec(src, f"{key}.points[{j}]", p, 2, "[x, y] in m") for j, p in enumerate(pts_raw)
        )
        closed = w.get("closed", False)
        if not isinstance(closed, bool):
            raise _err(src, f"{key}.closed", "true or false", closed)
        walls.append(Wall(points=pts, closed=closed))  # type: ignore[arg-type]
    return walls


def _parse_goal(src: str, goal_raw: Any) -> Goal | None:
    if goal_raw is None:
        return None
    if not isinstance(goal_raw, dict):
        raise _err(src, "goal", "a [goal] table with center and radius", goal_raw)
    center = _vec(src, "goal.center", goal_raw.get("center"), 2, "[x, y] in m")
    radius = _number(src, "goal.radius", goal_raw.get("radius"))
    if radius <= 0:
        raise _err(src, "goal.radius", "a positive number (m)", radius)
    return Goal(center=center, radius=radius)  # type: ignore[arg-type]


def _parse_colour(src: str, key: str, v: Any, default: tuple[int, int, int]):
    if v is None:
        return default
    if isinstance(v, str):
        if v.lower() not in BEACON_COLOURS:
            raise _err(src, key, f"a colour name (one of {sorted(BEACON_COLOURS)}) or "
                       f"[r, g, b] of integers 0..255", v)
        return BEACON_COLOURS[v.lower()]
    if (not isinstance(v, list) or len(v) != 3
            or any(isinstance(c, bool) or not isinstance(c, int) or not 0 <= c <= 255
                   for c in v)):
        raise _err(src, key, "[r, g, b] of integers 0..255 or a colour name", v)
    return (int(v[0]), int(v[1]), int(v[2]))


_PALETTE = ("orange", "blue", "purple", "cyan", "magenta", "yellow")


def _parse_beacons(src: str, raw: Any, walls: list[Wall]) -> tuple[Beacon, ...]:
    """``[[beacons]]``: each ``id`` (an integer >= 1, unique), ``pos`` [x, y] within the walls'
    bounding box (on a wall is fine: a beacon mounted there), optional ``colour`` (a name or
    [r, g, b]) and ``size`` (m, > 0, default 0.2)."""
    if raw is None:
        return ()
    if not isinstance(raw, list) or len(raw) > MAX_BEACONS:
        raise _err(src, "beacons", f"a list of at most {MAX_BEACONS} [[beacons]] tables "
                   f"with id and pos", raw if not isinstance(raw, list) else f"{len(raw)}")
    probe = WorldSpec(name="-", task=None, pose=(0.0, 0.0, 0.0), walls=tuple(walls))
    x0, y0, x1, y1 = probe.bounds()
    out: list[Beacon] = []
    seen: set[int] = set()
    for i, b in enumerate(raw):
        key = f"beacons[{i}]"
        if not isinstance(b, dict):
            raise _err(src, key, "a table with id = <integer>, pos = [x, y]", b)
        unknown = sorted(set(b) - {"id", "pos", "colour", "size"})
        if unknown:
            raise _err(src, f"{key}.{unknown[0]}", "one of id, pos, colour, size", unknown[0])
        bid = b.get("id")
        if isinstance(bid, bool) or not isinstance(bid, int) or not 1 <= bid < 2**31:
            raise _err(src, f"{key}.id", "an integer >= 1 (0 means a beacon not identified)",
                       bid)
        if bid in seen:
            raise _err(src, f"{key}.id", "an id no other beacon has", bid)
        seen.add(bid)
        x, y = _vec(src, f"{key}.pos", b.get("pos"), 2, "[x, y] in m")
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            raise _err(src, f"{key}.pos", f"a point within the walls' bounds (x {x0:g}..{x1:g}, "
                       f"y {y0:g}..{y1:g})", [x, y])
        size = _number(src, f"{key}.size", b.get("size", _DEFAULT_BEACON_SIZE))
        if not 0 < size <= 5.0:
            raise _err(src, f"{key}.size", "a size in m, > 0 and <= 5", size)
        colour = _parse_colour(src, f"{key}.colour", b.get("colour"),
                               BEACON_COLOURS[_PALETTE[(bid - 1) % len(_PALETTE)]])
        out.append(Beacon(id=bid, pos=(x, y), colour=colour, size=size))
    return tuple(out)


def parse_world(
    data: dict[str, Any], source: str = "<world>", path: Path | None = None
) -> WorldSpec:
    """Validate a world mapping (as read from TOML) into a :class:`WorldSpec`."""
    src = source
    if not isinstance(data, dict):
        raise _err(src, "<top>", "a table", data)
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise _err(src, "name", "a non-empty string", name)
    task = data.get("task")  # an older file's: accepted as a hint (a behaviour names its worlds)
    if task is not None and task not in TASKS:
        raise _err(src, "task", f"one of {list(TASKS)} or no task at all", task)
    robot = data.get("robot")
    if not isinstance(robot, dict):
        raise _err(src, "robot", "a [robot] table with pose = [x, y, yaw]", robot)
    if "pose" not in robot:
        raise _err(src, "robot.pose", "[x, y, yaw] (m, m, rad)", None)
    pose = _vec(src, "robot.pose", robot["pose"], 3, "[x, y, yaw] in m, m, rad")
    starts_raw = robot.get("starts", [])
    if not isinstance(starts_raw, list):
        raise _err(src, "robot.starts", "a list of [x, y, yaw] poses", starts_raw)
    starts = tuple(
        _vec(src, f"robot.starts[{i}]", s, 3, "[x, y, yaw] in m, m, rad")
        for i, s in enumerate(starts_raw)
    )
    walls = _parse_walls(src, data.get("walls"))
    goal = _parse_goal(src, data.get("goal"))
    if task == "maze" and goal is None:
        raise _err(src, "goal", "a [goal] table (required for task = 'maze')", None)
    beacons = _parse_beacons(src, data.get("beacons"), walls)
    known = {"name", "task", "robot", "walls", "goal", "beacons"}
    spec = WorldSpec(
        name=name,
        task=task,
        pose=pose,  # type: ignore[arg-type]
        starts=starts,  # type: ignore[arg-type]
        walls=tuple(walls),
        goal=goal,
        path=path,
        extra={k: v for k, v in data.items() if k not in known},
        beacons=beacons,
    )
    segs = spec.segments()
    for key, p in [("robot.pose", pose)] + [
        (f"robot.starts[{i}]", s) for i, s in enumerate(starts)
    ]:
        d = float(point_segment_distance(np.asarray(p[:2]), segs).min())
        if d <= ROBOT.radius:
            raise _err(
                src,
                key,
                f"a pose at least {ROBOT.radius} m (robot radius) from every wall",
                f"{list(p)} at {d:.3f} m from a wall",
            )
    return spec


def load_world(path: str | Path) -> WorldSpec:
    """Read and validate a TOML world file. Raises :class:`WorldError` naming file and key."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise WorldError(f"{p}: world file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise WorldError(f"{p}: not valid TOML: {e}") from None
    except UnicodeDecodeError as e:  # found by campaigns.fuzz: tomllib lets it through
        raise WorldError(f"{p}: not valid TOML (not UTF-8 text: {e})") from None
    except OSError as e:
        raise WorldError(f"{p}: cannot read: {e}") from None
    return parse_world(data, source=str(p), path=p)

