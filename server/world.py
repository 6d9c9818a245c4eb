"""The simulated world: pymunk physics, a differential-drive robot, odometry, laser, fiducials.

Pure and deterministic: no zenoh, no clocks, no threads. The zenoh node (``server.node``) and the
in-process harness (``lab``) both drive the same :class:`World`::

    spec = load_world(server.world_path("room"))
    world = World(spec, robots=1, seed=0)
    world.set_command(0, 0.3, 0.0)
    world.step(0.1)
    ranges = world.scan(0)          # float32, LASER.count beams, ranges[0] at the robot's right

Conventions (docs/protocol.md): SI units, x forward, y left, angles counter-clockwise, yaw in
(-pi, pi]. The robot and its sensors are ``server.robot``'s, the world files ``server.worldfile``'s
(both also importable from here, as they always were).

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

import numpy as np
import pymunk
from pymunk import _chipmunk_cffi

from server import fiducial, laser
from server.robot import (
    FIDUCIAL,
    LASER,
    ROBOT,
    FiducialSpec,
    LaserSpec,
    Pose,
    RobotSpec,
    wrap_angle,
)
from server.worldfile import (
    BEACON_COLOURS,
    TASKS,
    Beacon,
    Goal,
    Wall,
    WorldError,
    WorldSpec,
    free_pose,
    load_world,
    parse_world,
    point_segment_distance,
    sample_pose,
)

__all__ = [
    "BEACON_COLOURS",
    "FIDUCIAL",
    "LASER",
    "ROBOT",
    "TASKS",
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
        d = float(point_segment_distance(np.asarray([x, y]), self._segs).min())
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
