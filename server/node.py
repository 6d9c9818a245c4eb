"""The zenoh node of the simulator: publishes state and scans, takes commands and requests.

One :class:`ServerNode` owns a :class:`server.world.World` and a zenoh session. ``run()`` ticks
at a fixed rate in sim time (``rate`` Hz): each tick applies the arbitrated commands, steps the
world by ``1/rate`` s and publishes every robot's state and scan (and, in a world with beacons,
what its fiducial finder sees, before the scan). Pacing:

- real time (``speedup=1``) or N times real time (``speedup=N``), or as fast as possible
  (``speedup=0``);
- lock-step (``lockstep=True``): after publishing scan ``k`` the next tick starts only when every
  robot got a command answering scan ``k`` (``scan_id == k``) from its driving source (from any
  source when none holds it), or after ``lockstep_timeout`` real seconds.

Commands: free-running, zenoh queues each robot's commands and the tick takes them all before
applying (a command is offered at the sim time it would have had on arrival: only the tick moves
sim time); in lock-step each command is handled on arrival, as the wait for answers needs.

Everything arriving from the network is validated; a bad message is dropped with a log line
and counted in ``counters`` (never raised, never applied).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import math
import os
import re
import socket
import threading
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

import zenoh

from protocol import keys
from protocol.codec import DecodeError
from protocol.decoding import Decoder
from protocol.messages import (
    COMMAND_MAX_PAYLOAD,
    Ack,
    BeaconInfo,
    DriverState,
    Fiducial,
    FiducialGeometry,
    FiducialItem,
    Geometry,
    LaserConfig,
    MotorPower,
    Nack,
    Scan,
    SetOdom,
    SetPose,
    SimPose,
    State,
    VelCmd,
    WorldInfo,
)
from server.arbiter import Arbiter, priority_of
from server.world import FIDUCIAL, LASER, ROBOT, World, WorldSpec

__all__ = [
    "DuplicateRobotError",
    "ServerNode",
    "default_ident",
    "hosted_robots",
    "keep_freed_memory",
]

log = logging.getLogger(__name__)

_LASER_SIZE = (0.156, 0.155)  # m, a SICK LMS200's footprint
_DRIVER_REPEAT = 1.0  # s sim time between repeated driver messages
_CMD_QUEUE = 1024  # commands queued per robot between two ticks (zenoh waits when it is full)


def world_info(spec: WorldSpec) -> WorldInfo:
    """The ``get_world`` reply of a world: its walls as segments, goal, start poses and
    beacons."""
    goal = None if spec.goal is None else (*spec.goal.center, spec.goal.radius)
    beacons = tuple(BeaconInfo(b.id, b.pos, "#{:02x}{:02x}{:02x}".format(*b.colour), b.size)
                    for b in spec.beacons)
    return WorldInfo(name=spec.name, task=spec.task or "",  # "": the world names no task
                     walls=tuple(tuple(s) for s in spec.segments().tolist()),
                     goal=goal, starts=tuple(tuple(p) for p in spec.start_poses),
                     beacons=beacons)


def fiducial_geometry(rate: float) -> FiducialGeometry:
    """The fiducial finder's ``get_geom`` reply (``server.world.FIDUCIAL``)."""
    return FiducialGeometry(pose=(FIDUCIAL.offset, 0.0, 0.0), size=FIDUCIAL.size,
                            min_range=FIDUCIAL.min_range, max_range=FIDUCIAL.max_range,
                            max_range_id=FIDUCIAL.max_range_id, fov=FIDUCIAL.fov, rate=rate)


def _undeclare(declared: Any) -> None:
    with contextlib.suppress(Exception):  # already gone with the session
        declared.undeclare()


def keep_freed_memory(trim: int = 256 << 20) -> bool:
    """Let the C library's allocator keep freed memory for reuse (glibc's ``mallopt``; False
    where there is none). A tick of a fleet allocates and frees arrays of a few hundred kB to a
    few MB (``World.scans``); by default glibc hands such blocks back to the kernel when they
    are freed (``munmap``, trimming the heap), so every tick paid again for the pages (page
    faults): at 300 robots about a third of the tick's CPU time. Blocks up to 32 MB now come
    from the heap, and up to ``trim`` bytes of free heap are kept. Process-wide; a
    :class:`ServerNode` calls it."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # malloc.h
    return bool(mallopt(m_mmap_threshold, 32 << 20)) and bool(mallopt(m_trim_threshold, trim))


class DuplicateRobotError(ValueError):
    """A robot name this server would host is already hosted by another server."""


def default_ident() -> str:
    """A server's default id, unique on a zenoh network: ``<host>-<pid>`` (as a key chunk)."""
    host = re.sub(r"[^A-Za-z0-9_.\-]", "-", socket.gethostname()) or "host"
    return f"{host}-{os.getpid()}"


def hosted_robots(session: zenoh.Session, timeout: float = 1.0) -> dict[str, list[str]]:
    """Which server hosts which robot, from the servers' liveliness tokens
    ``rhbl/alive/server/<ident>/<robot>``: ``{robot: [ident, ...]}``."""
    out: dict[str, list[str]] = {}
    for reply in session.liveliness().get(keys.alive_key("server", "**"), timeout=timeout):
        if reply.ok is None:
            continue
        k = keys.parse(reply.ok.key_expr)
        if k.role == "server" and k.name:
            out.setdefault(k.name, []).append(k.ident)
    return out


class _RobotIO:
    def __init__(self, name: str, index: int, watchdog: float) -> None:
        self.name = name
        self.index = index
        self.arbiter = Arbiter(timeout=watchdog)
        self.motors = True
        self.answers: dict[str, int] = {}  # source -> last scan_id it answered
        self.scan_id = 0  # id of the last published scan
        self.seq = 0
        self.driver = ""
        self.driver_sent = -math.inf
        self.pubs: dict[str, Any] = {}
        self.cmd_queue: Any = None  # the command subscriber's queue (not in lock-step)


class ServerNode:
    """Serve ``world`` over ``session`` for robots named ``names`` (one per world robot)."""

    def __init__(
        self,
        session: zenoh.Session,
        world: World,
        names: Sequence[str] | None = None,
        rate: float = 10.0,
        speedup: float = 1.0,
        lockstep: bool = False,
        lockstep_timeout: float = 1.0,
        watchdog: float = 0.5,
        ident: str | None = None,
        refuse_duplicates: bool = True,
    ) -> None:
        if names is None:
            names = [keys.robot_name(i) for i in range(world.n_robots)]
        names = list(names)
        if len(names) != world.n_robots or len(set(names)) != len(names):
            raise ValueError(f"need {world.n_robots} distinct robot names, got {names}")
        for n in names:
            keys.check_chunk(n, "robot name")
        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be a positive number of Hz, got {rate!r}")
        if not (speedup >= 0 and math.isfinite(speedup)):
            raise ValueError(f"speedup must be >= 0 (0: as fast as possible), got {speedup!r}")
        if not lockstep_timeout > 0:
            raise ValueError(f"lockstep timeout must be > 0 s, got {lockstep_timeout!r}")
        self.session = session
        self.world = world
        keep_freed_memory()
        self.rate = float(rate)
        self.dt = 1.0 / self.rate
        self.speedup = float(speedup)
        self.lockstep = bool(lockstep)
        self.lockstep_timeout = float(lockstep_timeout)
        self.watchdog = float(watchdog)
        self.ident = keys.check_chunk(default_ident() if ident is None else ident,
                                      "server ident")
        self.counters: Counter[str] = Counter()
        # refusals (malformed or not allowed), counted in ``counters`` ("rejected": all of them)
        self.drops = Decoder(log, counts=self.counters, total="rejected", verb="rejected")
        self.ticks = 0
        self.lockstep_timeouts = 0
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._robots = [_RobotIO(n, i, self.watchdog) for i, n in enumerate(names)]
        self._by_name = {r.name: r for r in self._robots}
        self._world_info = world_info(world.spec)
        self._beacons = bool(world.spec.beacons)
        if refuse_duplicates:
            self._refuse_duplicates()
        # every declaration, undeclared in reverse order by close() (on every path)
        self._scope = contextlib.ExitStack()
        try:
            self._declare()
        except BaseException:
            self._scope.close()
            raise

    def _refuse_duplicates(self) -> None:
        """Raise :class:`DuplicateRobotError` if another server already hosts one of our robots
        (its token ``rhbl/alive/server/<ident>/<robot>`` is visible). Two servers starting in
        the same instant can both pass; each then logs the other's token (``_on_liveliness``)."""
        hosted = hosted_robots(self.session)
        taken = {r.name: hosted[r.name] for r in self._robots if r.name in hosted}
        if taken:
            which = "; ".join(f"robot {name!r} is hosted by server {', '.join(sorted(ids))}"
                              for name, ids in sorted(taken.items()))
            raise DuplicateRobotError(
                f"refusing to start: {which} (robot names are unique on a zenoh network; "
                f"name this server's robots differently with --robot, or use a --namespace)")

    # -- zenoh declarations ---------------------------------------------------------------

    def _declare(self) -> None:
        s = self.session
        for r in self._robots:
            r.pubs["state"] = self._keep(s.declare_publisher(keys.state_key(r.name)))
            r.pubs["scan"] = self._keep(s.declare_publisher(keys.scan_key(r.name)))
            if self._beacons:  # the fiducial finder: published in a world with beacons
                r.pubs["fiducial"] = self._keep(
                    s.declare_publisher(keys.fiducial_key(r.name)))
            r.pubs["driver"] = self._keep(s.declare_publisher(keys.driver_key(r.name)))
            if self.lockstep:  # an answer wakes the lock-step wait at once
                self._keep(
                    s.declare_subscriber(
                        keys.cmd_vel_subscription(r.name),
                        lambda sample, r=r: self._on_cmd(r, sample),
                    )
                )
            else:  # queued by zenoh, taken by the tick (_take_commands): no callback each
                r.cmd_queue = self._keep(
                    s.declare_subscriber(
                        keys.cmd_vel_subscription(r.name), zenoh.handlers.FifoChannel(_CMD_QUEUE)
                    )
                )
            for iface, name in [
                ("position2d", "get_geom"),
                ("position2d", "set_odom"),
                ("position2d", "reset_odom"),
                ("position2d", "motor_power"),
                ("laser", "get_geom"),
                ("laser", "get_config"),
                ("fiducial", "get_geom"),
            ]:
                self._keep(
                    s.declare_queryable(
                        keys.request_key(r.name, iface, name),
                        lambda q, r=r, iface=iface, name=name: self._on_query(r, iface, name, q),
                    )
                )
            for name in ("set_pose", "get_pose", "get_world"):  # simulation-only requests
                self._keep(
                    s.declare_queryable(
                        keys.sim_request_key(r.name, name),
                        lambda q, r=r, name=name: self._on_query(r, "sim", name, q),
                    )
                )
        # one token per hosted robot, rhbl/alive/server/<ident>/<robot>, says who hosts what;
        # the tokens before the liveliness subscriber: closing undeclares the subscriber first,
        # so the node does not see its own tokens go
        for r in self._robots:
            self._keep(s.liveliness().declare_token(
                f"{keys.alive_key('server', self.ident)}/{r.name}"))
        self._keep(
            s.liveliness().declare_subscriber(keys.every_token(), self._on_liveliness)
        )

    def _keep(self, declared: Any) -> Any:
        self._scope.callback(_undeclare, declared)
        return declared

    def close(self) -> None:
        """Undeclare everything, the token first (the session stays open; its owner closes it).
        Idempotent."""
        self._stop.set()
        self._scope.close()
        with self._cond:  # drop the command queues: a zenoh thread waiting on a full one ends
            for r in self._robots:
                r.cmd_queue = None

    def __enter__(self) -> ServerNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- input ------------------------------------------------------------------------------

    def _reject(self, what: str, reason: str) -> None:
        self.drops.drop(what, reason)

    def _on_cmd(self, r: _RobotIO, sample: zenoh.Sample) -> None:
        try:
            key = str(sample.key_expr)
            msg = self.drops.decode(VelCmd, sample.payload.to_bytes(), what="cmd", where=key,
                                    max_size=COMMAND_MAX_PAYLOAD)
            if msg is None:
                return
            key_source = keys.source_of_cmd_key(key)
            if key_source is not None and key_source != msg.source:
                self._reject(
                    "cmd_source",
                    f"{key}: field 'source' {msg.source!r} does not match the key's "
                    f"source {key_source!r}",
                )
                return
            with self._cond:
                now = self.world.time
                r.arbiter.offer(msg.source, msg.vx, msg.va, msg.state, now)
                if msg.scan_id is not None:
                    r.answers[msg.source] = msg.scan_id
                self.counters["cmd_accepted"] += 1
                self._cond.notify_all()
        except Exception as e:  # never let a message kill the node
            self._reject("cmd", f"{sample.key_expr}: unexpected {type(e).__name__}: {e}")

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        try:
            k = keys.parse(sample.key_expr)
            if sample.kind != zenoh.SampleKind.DELETE:
                if k.role == "server" and k.name in self._by_name and k.ident != self.ident:
                    self.counters["duplicate_robot"] += 1
                    log.error("robot %r is also hosted by server %r: two servers publish its "
                              "scans (stop one)", k.name, k.ident)
                return
            if not k.ident:
                return
            role = k.role
            # a process's ident is "<robot>-<pid>": release only that robot's holds (every
            # robot's when the ident names none of ours)
            mine = [r for r in self._robots if k.names_robot(r.name)] or self._robots
            with self._cond:
                # the commands it sent before it went are still queued: take them first, or the
                # next tick would take them after the release and drive on until the watchdog
                self._take_commands(mine)
                for r in mine:
                    r.arbiter.release_role(role)
                self._cond.notify_all()
            log.info("liveliness token %s gone: released role %r", sample.key_expr, role)
        except Exception as e:
            log.warning("liveliness sample not understood: %s", e)

    def _on_query(self, r: _RobotIO, iface: str, name: str, query: zenoh.Query) -> None:
        try:
            reply = self._answer(r, iface, name, query)
            query.reply(query.key_expr, reply.encode())
            self.counters["request"] += 1
        except (DecodeError, ValueError) as e:
            self.counters["request_nack"] += 1
            self._reject("request", f"{iface}/{name}: {e}")
            try:
                query.reply_err(Nack(reason=str(e)).encode())
            except Exception as e2:
                log.warning("could not send NACK: %s", e2)
        except Exception as e:
            self._reject("request", f"{iface}/{name}: unexpected {type(e).__name__}: {e}")
            with contextlib.suppress(Exception):
                query.reply_err(Nack(reason=f"internal error: {type(e).__name__}").encode())

    def _answer(self, r: _RobotIO, iface: str, name: str, query: zenoh.Query):
        payload = query.payload.to_bytes() if query.payload is not None else b""
        if len(payload) > COMMAND_MAX_PAYLOAD:
            raise DecodeError(f"{name}: payload of {len(payload)} bytes exceeds the limit")
        i = r.index
        if iface == "sim":
            return self._answer_sim(r, name, payload)
        if iface == "fiducial":
            return fiducial_geometry(self.rate)
        if iface == "laser":
            if name == "get_geom":
                return Geometry(pose=(LASER.offset, 0.0, 0.0), size=_LASER_SIZE)
            return LaserConfig(
                min_angle=LASER.min_angle,
                max_angle=LASER.max_angle,
                resolution=LASER.resolution,
                max_range=LASER.max_range,
                count=LASER.count,
                rate=self.rate,
            )
        if name == "get_geom":
            return Geometry(
                pose=(0.0, 0.0, 0.0), size=(ROBOT.length, ROBOT.width), radius=ROBOT.radius
            )
        if name == "set_odom":
            if not payload:
                raise DecodeError("set_odom: missing payload, expected {v, pose: [x, y, yaw]}")
            msg = SetOdom.decode(payload)
            with self._cond:
                self.world.set_odom(i, msg.pose)
            return Ack(info="odometry set")
        if name == "reset_odom":
            with self._cond:
                self.world.reset_odom(i)
            return Ack(info="odometry reset to (0, 0, 0)")
        if name == "motor_power":
            if not payload:
                raise DecodeError("motor_power: missing payload, expected {v, state: bool}")
            msg = MotorPower.decode(payload)
            with self._cond:
                r.motors = msg.state
            return Ack(info=f"motors {'on' if msg.state else 'off'}")
        raise ValueError(f"unknown request {iface}/{name}")  # pragma: no cover

    def _answer_sim(self, r: _RobotIO, name: str, payload: bytes):
        i = r.index
        if name == "get_world":
            return self._world_info
        if name == "get_pose":
            with self._cond:
                return SimPose(pose=self.world.pose(i), odom=self.world.odom(i),
                               ts=self.world.time)
        if name == "set_pose":
            if not payload:
                raise DecodeError(
                    "set_pose: missing payload, expected {v, pose: [x, y, yaw], reset_odom: bool}"
                )
            msg = SetPose.decode(payload)
            with self._cond:
                self.world.set_pose(i, msg.pose, reset_odom=msg.reset_odom)  # ValueError: NACK
                # publish the new pose at once (same ts, next scan id): clients see it without
                # waiting for a tick, and in lock-step the next tick waits for answers to it
                self._publish([r])
                self._cond.notify_all()
                pose, scan_id, ts = self.world.pose(i), r.scan_id, self.world.time
            self.counters["set_pose"] += 1
            log.info("%s: set_pose to (%.3f, %.3f, %.3f)%s", r.name, *pose,
                     ", odometry reset" if msg.reset_odom else "")
            return Ack(info="pose set", extra={"pose": list(pose), "scan_id": scan_id, "ts": ts})
        raise ValueError(f"unknown request sim/{name}")  # pragma: no cover

    # -- the loop ---------------------------------------------------------------------------

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def _publish(self, robots: Sequence[_RobotIO] | None = None) -> None:
        w = self.world
        ts = w.time
        robots = self._robots if robots is None else robots
        scans = w.scans([r.index for r in robots])  # all lasers cast together (server.laser)
        seen = w.fiducials([r.index for r in robots]) if self._beacons else None
        for k, r in enumerate(robots):
            i = r.index
            r.seq += 1
            r.scan_id += 1
            pos = w.odom(i)
            truth = w.pose(i)
            r.pubs["state"].put(
                State(
                    ts=ts,
                    seq=r.seq,
                    pos=pos,
                    vel=w.velocity(i),
                    stall=w.stall(i),
                    driver=r.driver,
                    truth=truth,
                ).encode()
            )
            if seen is not None:  # before the scan: a client holding scan k has its beacons
                f = seen[k]
                items = tuple(map(FiducialItem, f.ids, f.ranges, f.bearings))
                r.pubs["fiducial"].put(Fiducial(ts=ts, seq=r.scan_id, items=items, pose=pos,
                                                truth=truth).encode())
            r.pubs["scan"].put(
                Scan(
                    ts=ts,
                    id=r.scan_id,
                    ranges=scans[k],
                    pose=pos,
                    min_angle=LASER.min_angle,
                    max_angle=LASER.max_angle,
                    resolution=LASER.resolution,
                    max_range=LASER.max_range,
                    truth=truth,
                ).encode()
            )

    def _apply_commands(self) -> None:
        now = self.world.time
        for r in self._robots:
            vx, va, driver = r.arbiter.command(now)
            if len(r.answers) > 8:  # forget sources that hold the robot no more (bounded)
                r.answers = {s: k for s, k in r.answers.items() if r.arbiter.holds(s)}
            if not r.motors:
                vx = va = 0.0
            self.world.set_command(r.index, vx, va)
            if driver != r.driver or now - r.driver_sent >= _DRIVER_REPEAT:
                if driver != r.driver:
                    log.info("%s: driver %r -> %r", r.name, r.driver, driver)
                r.driver = driver
                r.driver_sent = now
                r.pubs["driver"].put(
                    DriverState(source=driver, ts=now, priority=priority_of(driver)).encode()
                )

    def _answered(self) -> bool:
        now = self.world.time
        for r in self._robots:
            h = r.arbiter.driver(now)
            if h is None or r.answers.get(h.source) != r.scan_id:
                return False
        return True

    def _take_commands(self, robots: list[_RobotIO] | None = None) -> None:
        """Handle the commands queued since the last tick (free-running: a callback for each of
        thousands of commands a second took the interpreter's lock from the tick every time).
        A command is offered at the same sim time as from a callback: the tick alone moves it.
        Also before a hold is released (``_on_liveliness``), for the ``robots`` concerned."""
        for r in self._robots if robots is None else robots:
            queue = r.cmd_queue
            if queue is None:
                continue
            try:
                while (sample := queue.try_recv()) is not None:
                    self._on_cmd(r, sample)
            except zenoh.ZError as e:  # undeclared under a tick: the node is closing
                r.cmd_queue = None
                if not self._stop.is_set():
                    log.warning("%s: the command queue is gone: %s", r.name, e)

    def tick(self) -> None:
        """One tick: take the queued commands, apply the arbitrated ones, step, publish."""
        with self._cond:
            self._take_commands()
            self._apply_commands()
            self.world.step(self.dt)
            self.ticks += 1
            self._publish()

    def run(self, duration: float | None = None) -> None:
        """Tick until :meth:`stop` (or ``duration`` sim seconds). Publishes the initial state
        and scan first (so a lock-step client has a scan to answer)."""
        with self._cond:
            self._publish()
        period = self.dt / self.speedup if self.speedup > 0 else 0.0
        next_t = time.monotonic() + period
        end = None if duration is None else self.world.time + duration - 1e-9
        while not self._stop.is_set():
            if end is not None and self.world.time >= end:
                break
            if self.lockstep:
                deadline = time.monotonic() + self.lockstep_timeout
                with self._cond:
                    while not self._stop.is_set() and not self._answered():
                        left = deadline - time.monotonic()
                        if left <= 0:
                            self.lockstep_timeouts += 1
                            break
                        self._cond.wait(min(left, 0.1))
            elif period > 0:
                delay = next_t - time.monotonic()
                if delay > 0:
                    if self._stop.wait(delay):
                        break
                elif delay < -1.0:  # far behind (suspended?): do not try to catch up
                    next_t = time.monotonic()
                next_t += period
            if self._stop.is_set():
                break
            self.tick()
