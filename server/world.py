"""The simulated world: world files, pymunk physics, a differential-drive robot, odometry, laser.

Pure and deterministic: no zenoh, no clocks, no threads. The zenoh node (``server.node``) and the
in-process harness (``lab``) both drive the same :class:`World`::

    spec = load_world(server.world_path("room"))
    world = World(spec, robots=1, seed=0)
    world.set_command(0, 0.3, 0.0)
    world.step(0.1)
    ranges = world.scan(0)          # float32, LASER.count beams, ranges[0] at the robot's right

Conventions (docs/protocol.md): SI units, x forward, y left, angles counter-clockwise, yaw in
(-pi, pi].

Robot model. A Pioneer 3DX (0.511 x 0.4 m) is modelled for collisions as a circle of radius
``ROBOT.radius`` = 0.25 m (between its half width and half length), a dynamic pymunk body whose
velocity is set to the commanded vx along its heading at every physics substep (its angular
velocity to va once a step: nothing else changes it); walls are static segments.
Contact handling, chosen deliberately (the prototype's dominant failure was a robot pinned against
a wall): the physics removes the part of the motion that would go into the wall, so the robot never
passes through a wall; contacts are frictionless, so a robot driving at a wall at an angle slides
along it (like a bumper scraping); turning in place and backing away always work. ``stall`` is true
after a step in which the robot touched a wall (or another robot) while its command pushed into it.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pymunk
from pymunk import _chipmunk_cffi

from protocol.messages import MAX_BEACONS, MAX_VA, MAX_VX
from server import fiducial, laser

__all__ = [
    "BEACON_COLOURS",
    "FIDUCIAL",
    "LASER",
    "ROBOT",
    "Beacon",
    "FiducialSpec",
    "Goal",
    "LaserSpec",
    "Pose",
    "RobotSpec",
    "Wall",
    "World",
    "WorldError",
    "WorldSpec",
    "free_pose",
    "load_world",
    "parse_world",
    "sample_pose",
    "wrap_angle",
]

TASKS = ("wall-following", "maze", "doorways", "dead-end", "corridor-centring", "wandering",
         "red-green")


def wrap_angle(a: float) -> float:
    """Wrap an angle in radians into (-pi, pi]."""
    a = math.fmod(a, 2.0 * math.pi)
    if a <= -math.pi:
        a += 2.0 * math.pi
    elif a > math.pi:
        a -= 2.0 * math.pi
    return a


class Pose(NamedTuple):
    """A planar pose: metres and radians (a tuple, so ``(x, y, yaw)`` compares equal)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class RobotSpec:
    """Pioneer 3DX-like differential-drive robot (collision shape: a circle of ``radius``)."""

    length: float = 0.511
    width: float = 0.4
    radius: float = 0.25
    max_vx: float = MAX_VX  # m/s (the protocol's limits: docs/protocol.md section 2)
    max_va: float = MAX_VA  # rad/s (100 deg/s)
    mass: float = 9.0  # kg (only matters robot against robot)


@dataclass(frozen=True)
class LaserSpec:
    """SICK-like laser at the robot's centre, facing forward: 360 beams over 180 degrees."""

    count: int = 360
    min_angle: float = -math.pi / 2.0
    max_angle: float = math.pi / 2.0
    max_range: float = 8.0
    offset: float = 0.0  # m ahead of the robot's centre (0: at the centre)

    @property
    def resolution(self) -> float:
        return (self.max_angle - self.min_angle) / (self.count - 1)

    def bearings(self) -> np.ndarray:
        """Bearing of each beam in the robot frame (rad), ``min_angle + i * resolution``."""
        return self.min_angle + np.arange(self.count, dtype=np.float64) * self.resolution


@dataclass(frozen=True)
class FiducialSpec:
    """The fiducial finder (Player's ``fiducial`` interface, Stage's fiducial finder model) at
    the robot's centre, facing forward: a beacon is seen when its centre is within
    ``max_range`` of the sensor, within ``fov`` (centred on the heading) and no wall crosses the
    line from the sensor to its centre first; its id is reported within ``max_range_id``, 0
    (seen, not identified) beyond it. Other robots do not hide a beacon."""

    min_range: float = 0.0  # m: a beacon nearer is reported at this range (as Stage does)
    max_range: float = 8.0  # m (the laser's range)
    max_range_id: float = 8.0  # m (Stage's default is 5 m; here a room's width)
    fov: float = math.pi  # rad (180 degrees, the laser's field of view)
    offset: float = 0.0  # m ahead of the robot's centre
    size: tuple[float, float] = (0.1, 0.1)  # m, the sensor's footprint (length, width)


ROBOT = RobotSpec()
LASER = LaserSpec()
FIDUCIAL = FiducialSpec()

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
        return float(_point_segment_distance(np.array([x, y]), segs).min())

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


def _point_segment_distance(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
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
        d = float(_point_segment_distance(np.asarray(p[:2]), segs).min())
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


# ---------------------------------------------------------------------------------- simulation

_WALL_RADIUS = 0.02  # m, physics half-thickness of a wall segment (the laser sees the centre line)
_MAX_SUBSTEP = 0.025  # s
# the step calls Chipmunk's functions itself (pymunk's cffi library, which its Body and Space
# methods call): cpSpaceStep is what Space.step runs, without its bookkeeping for shapes added
# or removed and callbacks registered during a step, which the world never does (no collision
# handlers, no post-step callbacks); the bodies' getters and setters are those the properties
# call, without the attribute lookup and the Vec2d of every access (the step sets every
# robot's velocity at every substep). About half of a step's time.
_cp = _chipmunk_cffi.lib
_body_set_angular_velocity = pymunk.Body.angular_velocity.fset


def _body_position(body: pymunk.Body) -> tuple[float, float]:
    """``body.position`` as a tuple."""
    p = _cp.cpBodyGetPosition(body._body)
    return p.x, p.y


def _body_angle(body: pymunk.Body) -> float:
    """``body.angle``."""
    return _cp.cpBodyGetAngle(body._body)


_NO_CENTRES = np.zeros((0, 2))  # a world of one robot: the laser sees walls only
_ROW0 = np.zeros(1, dtype=np.intp)


class _Robot:
    __slots__ = ("body", "shape", "cmd", "odom", "stall", "vel", "last")

    def __init__(self, space: pymunk.Space, pose: tuple[float, float, float]) -> None:
        self.body = pymunk.Body(ROBOT.mass, float("inf"), body_type=pymunk.Body.DYNAMIC)
        self.body.position = (pose[0], pose[1])
        self.body.angle = pose[2]
        self.shape = pymunk.Circle(self.body, ROBOT.radius)
        self.shape.friction = 0.0
        self.shape.elasticity = 0.0
        space.add(self.body, self.shape)
        self.cmd = (0.0, 0.0)
        self.odom = [pose[0], pose[1], wrap_angle(pose[2])]
        self.stall = False
        self.vel = (0.0, 0.0, 0.0)
        self.last = (pose[0], pose[1], pose[2])


class World:
    """A world with ``robots`` robots. Deterministic for a given seed and command sequence."""

    def __init__(
        self,
        spec: WorldSpec,
        robots: int = 1,
        seed: int = 0,
        range_noise: float = 0.0,
        odom_noise: float = 0.0,
    ) -> None:
        if robots < 1:
            raise ValueError(f"robots must be >= 1, got {robots}")
        if range_noise < 0 or odom_noise < 0:
            raise ValueError("range_noise and odom_noise must be >= 0")
        self.spec = spec
        self.n_robots = int(robots)
        self.seed = int(seed)
        self.range_noise = float(range_noise)
        self.odom_noise = float(odom_noise)
        self._segs = spec.segments()
        self._bearings = LASER.bearings()
        # the robots' lasers: their beam directions kept per robot while its heading holds
        # (keyed by the heading alone, so they outlive a reset)
        self._laser = laser.Laser(self._segs, self._bearings, LASER.max_range, ROBOT.radius,
                                  robots=self.n_robots)
        self._finder = fiducial.FiducialFinder(self._segs, spec.beacons, FIDUCIAL)
        self._rows = np.arange(self.n_robots, dtype=np.intp)
        self.reset()

    # -- lifecycle --------------------------------------------------------------------------

    def reset(
        self,
        poses: list[tuple[float, float, float]] | None = None,
        seed: int | None = None,
    ) -> None:
        """Rebuild the physics with robots at ``poses`` (default: the spec's start poses)."""
        if seed is not None:
            self.seed = int(seed)
        if poses is None:
            starts = self.spec.start_poses
            poses = [starts[i % len(starts)] for i in range(self.n_robots)]
        if len(poses) != self.n_robots:
            raise ValueError(f"reset needs {self.n_robots} poses, got {len(poses)}")
        self._rng = np.random.default_rng(self.seed)
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.collision_slop = 0.001
        space.iterations = 10
        # correct any overlap at once (pymunk's default leaves a substep's worth of penetration)
        space.collision_bias = 1e-60
        for x0, y0, x1, y1 in self._segs:
            seg = pymunk.Segment(space.static_body, (x0, y0), (x1, y1), _WALL_RADIUS)
            seg.friction = 0.0
            seg.elasticity = 0.0
            space.add(seg)
        self._space = space
        self._robots = []
        for p in poses:
            if len(p) != 3 or not all(math.isfinite(float(v)) for v in p):
                raise ValueError(f"a pose is (x, y, yaw) of finite numbers, got {p!r}")
            self._robots.append(_Robot(space, (float(p[0]), float(p[1]), float(p[2]))))
        self.time = 0.0
        self.steps = 0

    # -- commands ---------------------------------------------------------------------------

    def set_command(self, i: int, vx: float, va: float) -> None:
        """Command robot ``i``; clamped to ``ROBOT`` limits. Non-finite values raise ValueError."""
        vx = float(vx)
        va = float(va)
        if not (math.isfinite(vx) and math.isfinite(va)):
            raise ValueError(f"velocity command must be finite, got vx={vx!r}, va={va!r}")
        vx = min(max(vx, -ROBOT.max_vx), ROBOT.max_vx)
        va = min(max(va, -ROBOT.max_va), ROBOT.max_va)
        self._robots[i].cmd = (vx, va)

    def command(self, i: int) -> tuple[float, float]:
        return self._robots[i].cmd

    def stop(self, i: int) -> None:
        self._robots[i].cmd = (0.0, 0.0)

    # -- stepping ---------------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance ``dt`` sim seconds (physics substeps of at most 25 ms)."""
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        n = max(1, math.ceil(dt / _MAX_SUBSTEP - 1e-9))
        h = dt / n
        robots = self._robots
        position, angle = _body_position, _body_angle
        set_angular_velocity = _body_set_angular_velocity
        cos, sin = math.cos, math.sin
        for r in robots:
            r.stall = False
            b = r.body
            x, y = position(b)
            r.last = (x, y, angle(b))
            # a robot's moment of inertia is infinite and the space undamped: nothing but this
            # changes its angular velocity, so it is set once a step
            set_angular_velocity(b, r.cmd[1])
        space = self._space._space  # Chipmunk's (see _cp)
        bodies = [(r.body._body, r.cmd[0]) for r in robots]
        space_step, get_angle, set_body_velocity = (_cp.cpSpaceStep, _cp.cpBodyGetAngle,
                                                    _cp.cpBodySetVelocity)
        for _ in range(n):
            for b, vx in bodies:
                a = get_angle(b)
                set_body_velocity(b, (vx * cos(a), vx * sin(a)))
            space_step(space, h)
        for r in robots:
            self._update_odometry(r, dt)
            self._check_stall(r)
        self.time += dt
        self.steps += 1

    def _update_odometry(self, r: _Robot, dt: float) -> None:
        # the step's motion as a rigid transform in the robot's frame at the step's start,
        # composed onto the odometry pose: exact without noise, whatever the path was
        b = r.body
        x, y = _body_position(b)
        a = _body_angle(b)
        px, py, pa = r.last
        dxw, dyw = x - px, y - py
        c, s = math.cos(pa), math.sin(pa)
        dxr = c * dxw + s * dyw
        dyr = -s * dxw + c * dyw
        da = a - pa
        r.vel = (dxr / dt, dyr / dt, da / dt)
        if self.odom_noise > 0.0:
            k = self.odom_noise
            nz = self._rng.normal(0.0, 1.0, 3)
            dist = math.hypot(dxr, dyr)
            dxr += k * dist * nz[0]
            dyr += k * dist * nz[1]
            da += k * (abs(da) + 0.2 * dist) * nz[2]
        o = r.odom
        c, s = math.cos(o[2]), math.sin(o[2])
        o[0] += c * dxr - s * dyr
        o[1] += s * dxr + c * dyr
        o[2] = wrap_angle(o[2] + da)

    def _check_stall(self, r: _Robot) -> None:
        vx, _ = r.cmd
        if vx == 0.0:
            return
        b = r.body
        a = _body_angle(b)
        cmd_dir = (vx * math.cos(a), vx * math.sin(a))
        hit = False

        def visit(arb: pymunk.Arbiter) -> None:
            nonlocal hit
            n = arb.normal
            if arb.shapes[0] is not r.shape:
                n = -n
            # n points from the robot towards what it touches
            if cmd_dir[0] * n.x + cmd_dir[1] * n.y > 1e-6:
                hit = True

        b.each_arbiter(visit)
        r.stall = hit

    # -- observation ------------------------------------------------------------------------

    def pose(self, i: int) -> tuple[float, float, float]:
        """True pose (x, y, yaw) of robot ``i``."""
        b = self._robots[i].body
        x, y = _body_position(b)
        return (float(x), float(y), wrap_angle(float(_body_angle(b))))

    def odom(self, i: int) -> tuple[float, float, float]:
        """Odometry pose of robot ``i`` (integrated from its start pose, optionally noisy)."""
        o = self._robots[i].odom
        return (float(o[0]), float(o[1]), float(o[2]))

    def set_odom(self, i: int, pose: tuple[float, float, float]) -> None:
        if len(pose) != 3 or not all(math.isfinite(float(v)) for v in pose):
            raise ValueError(f"odometry pose is (x, y, yaw) of finite numbers, got {pose!r}")
        self._robots[i].odom = [float(pose[0]), float(pose[1]), wrap_angle(float(pose[2]))]

    def reset_odom(self, i: int) -> None:
        self.set_odom(i, (0.0, 0.0, 0.0))

    def pose_problem(self, i: int, pose: tuple[float, float, float]) -> str | None:
        """Why robot ``i`` cannot be placed at ``pose`` (None: it can). A pose must be finite,
        inside the walls' bounding box, more than the robot radius from every wall (the rule
        for start poses) and not overlap another robot."""
        if len(pose) != 3 or not all(math.isfinite(float(v)) for v in pose):
            return f"a pose is (x, y, yaw) of finite numbers, got {pose!r}"
        x, y = float(pose[0]), float(pose[1])
        x0, y0, x1, y1 = self.spec.bounds()
        if not (x0 < x < x1 and y0 < y < y1):
            return (f"({x:.3f}, {y:.3f}) is outside the world "
                    f"(walls span x {x0:g}..{x1:g}, y {y0:g}..{y1:g})")
        d = float(_point_segment_distance(np.asarray([x, y]), self._segs).min())
        if d <= ROBOT.radius:
            return (f"({x:.3f}, {y:.3f}) is {d:.3f} m from a wall: not free (the robot's "
                    f"radius is {ROBOT.radius} m)")
        for j, r in enumerate(self._robots):
            if j == i:
                continue
            ox, oy = r.body.position
            dd = math.hypot(x - ox, y - oy)
            if dd < 2 * ROBOT.radius:
                return f"({x:.3f}, {y:.3f}) overlaps robot {j} ({dd:.3f} m away)"
        return None

    def set_pose(self, i: int, pose: tuple[float, float, float], reset_odom: bool = True) -> None:
        """Teleport robot ``i`` to the true ``pose`` (simulation only): zero velocity and
        command, clear stall; with ``reset_odom`` the odometry becomes ``pose`` too. Raises
        ValueError (saying why) if the pose is not free (:meth:`pose_problem`)."""
        problem = self.pose_problem(i, pose)
        if problem is not None:
            raise ValueError(problem)
        x, y, yaw = float(pose[0]), float(pose[1]), wrap_angle(float(pose[2]))
        r = self._robots[i]
        b = r.body
        b.position = (x, y)
        b.angle = yaw
        b.velocity = (0.0, 0.0)
        b.angular_velocity = 0.0
        self._space.reindex_shapes_for_body(b)
        r.cmd = (0.0, 0.0)
        r.stall = False
        r.vel = (0.0, 0.0, 0.0)
        r.last = (x, y, yaw)
        if reset_odom:
            r.odom = [x, y, yaw]

    def velocity(self, i: int) -> tuple[float, float, float]:
        """Actual mean velocity (vx, vy, va) of robot ``i`` over the last step, in its frame."""
        return self._robots[i].vel

    def stall(self, i: int) -> bool:
        """True if robot ``i`` pushed into a wall or robot during the last step."""
        return self._robots[i].stall

    def at_goal(self, i: int) -> bool:
        """True if robot ``i``'s centre is inside the goal circle (False without a goal)."""
        g = self.spec.goal
        if g is None:
            return False
        x, y, _ = self.pose(i)
        return math.hypot(x - g.center[0], y - g.center[1]) <= g.radius

    def scan(self, i: int) -> np.ndarray:
        """Ray-cast robot ``i``'s laser: float32 ranges, ``ranges[0]`` at ``LASER.min_angle``."""
        if self.n_robots > 1:
            return self.scans([i])[0]
        # one robot (training, evaluation): what scans([i]) computes, without its batching
        b = self._robots[i].body
        x, y = _body_position(b)
        yaw = wrap_angle(_body_angle(b))
        origin = np.array([[x + LASER.offset * math.cos(yaw), y + LASER.offset * math.sin(yaw)]])
        out = self._laser.cast(origin, np.array([yaw]), _ROW0, _NO_CENTRES)[0]
        return self._add_noise(out) if self.range_noise > 0.0 else out

    def scans(self, indices: list[int] | None = None) -> np.ndarray:
        """Ray-cast the lasers of robots ``indices`` (default: all) together: float32 array
        (len(indices), LASER.count); row k equals ``scan(indices[k])`` (and draws range noise in
        the same order as those calls would). One compiled call casts every laser against the
        walls and the other robots (``server.laser``), each only over what it can see, so a
        tick's cost grows with the robots seen, not with the square of the fleet."""
        rows = self._rows if indices is None else np.asarray(indices, dtype=np.intp).reshape(-1)
        n = len(rows)
        if n == 0:
            return np.empty((0, LASER.count), dtype=np.float32)
        origins = np.empty((n, 2))
        yaws = np.empty(n)
        robots = self._robots
        for k in range(n):
            b = robots[rows[k]].body
            x, y = _body_position(b)
            yaw = wrap_angle(_body_angle(b))
            origins[k, 0] = x + LASER.offset * math.cos(yaw)
            origins[k, 1] = y + LASER.offset * math.sin(yaw)
            yaws[k] = yaw
        if self.n_robots > 1:
            centres = np.asarray([_body_position(r.body) for r in robots], dtype=np.float64)
        else:
            centres = _NO_CENTRES
        out = self._laser.cast(origins, yaws, rows, centres)
        if self.range_noise > 0.0:
            for k in range(n):
                out[k] = self._add_noise(out[k])
        return out

    def fiducials(self, indices: list[int] | None = None) -> list[fiducial.Seen]:
        """What the fiducial finders of robots ``indices`` (default: all) see: one
        ``server.fiducial.Seen`` (ids, ranges, bearings of the beacons in view) per robot, from
        their true poses (no noise). Empty in a world without beacons."""
        rows = self._rows if indices is None else np.asarray(indices, dtype=np.intp).reshape(-1)
        if not self.spec.beacons:
            return self._finder.detect(np.zeros((len(rows), 3)))
        return self._finder.detect(np.asarray([self.pose(int(i)) for i in rows]))

    def _add_noise(self, ranges: np.ndarray) -> np.ndarray:
        if self.range_noise > 0.0:
            ranges = ranges + self._rng.normal(0.0, self.range_noise, LASER.count)
            np.clip(ranges, 0.0, LASER.max_range, out=ranges)
        return ranges.astype(np.float32, copy=False)

    def _scan_walls(self, ox: float, oy: float, yaw: float):
        """Ranges to the walls from (ox, oy) facing ``yaw`` (wrapped to (-pi, pi]): (float32
        ranges, float32 cosines and sines of the beams' world angles; ``server.laser``: robot
        0's laser, walls only)."""
        yaw = wrap_angle(float(yaw))
        ranges = self._laser.cast(np.array([[ox, oy]], dtype=np.float64),
                                  np.array([yaw], dtype=np.float64), _ROW0, _NO_CENTRES)[0]
        return (ranges, *self._laser.directions(0))
