"""A Player-like client library over zenoh (docs/protocol.md; the model: docs/architecture.md).

::

    from client.player import PlayerClient
    from process.session import make_config

    with PlayerClient(make_config(connect=["tcp/127.0.0.1:7447"]), robot="r0",
                      source="controller") as client:
        pos, laser = client.position2d, client.laser
        while client.read(timeout=1.0):
            if laser[0] < 0.5:                    # the beam at the robot's right
                pos.set_speed(0.0, 0.5)
            else:
                pos.set_speed(0.3, 0.0)

``read()`` blocks until the server published a new tick (a scan; a state if no laser proxy is
used) and refreshes every proxy from the latest messages; in between, proxies do not change.
Messages are decoded as they arrive (a few microseconds) and only the latest is kept, so a slow
reader never stalls the session.

What the processes need (``rhbl controller``, ``rhbl teacher``, ``rhbl console`` are built on
it): a ``ScanChannel`` (``client.scans(depth)``: the scans through a zenoh ring channel, the
latest only with ``depth`` 1, decoded in the reader's thread: the controller's hot path),
publisher options (``express``, ``block``: a command is never dropped under congestion) and
``answer(scan, vx, va)``, the command that answers a scan (its id and sim time: a lock-step
server steps once every driver answered). Malformed messages are dropped and counted
(``client.decoder``, ``protocol.decoding``).
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any

import numpy as np
import zenoh

from process.session import make_config
from protocol import keys
from protocol.codec import DecodeError, ProtocolError
from protocol.decoding import Decoder
from protocol.messages import (
    Ack,
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
    VelCmdPacker,
    WorldInfo,
)

__all__ = ["FiducialLog", "FiducialProxy", "LaserProxy", "PlayerClient", "Position2dProxy", "RequestError", "ScanChannel",
           "SimulationProxy"]

log = logging.getLogger(__name__)


class RequestError(ProtocolError):
    """A request got a NACK (``reason``), no reply, or a malformed reply."""


class PlayerClient:
    """A connection to the robot ``robot`` of a ``rhbl server``.

    ``config`` is a ``zenoh.Config`` (default: a client of ``tcp/127.0.0.1:7447``), or pass an
    open ``session`` to share it. ``source`` names this client in its commands (``teacher``,
    ``controller``, ...; the server's arbitration rule uses it); with ``per_source_key`` the
    commands go to ``.../cmd/vel/<source>``. The command publisher's options: ``express``
    (sent at once, not batched) and ``block`` (congestion control BLOCK: never dropped).
    """

    def __init__(
        self,
        config: zenoh.Config | None = None,
        robot: str = "r0",
        source: str = "client",
        session: zenoh.Session | None = None,
        index: int = 0,
        per_source_key: bool = True,
        express: bool = False,
        block: bool = False,
    ) -> None:
        self.robot = keys.check_chunk(robot, "robot")
        self.source = source
        self.index = index
        self._own_session = session is None
        self.session = session if session is not None else zenoh.open(config or make_config())
        self._cond = threading.Condition()
        self._latest: dict[str, Any] = {}
        self._arrived: dict[str, int] = {"state": 0, "scan": 0}
        self._read_mark = 0
        self._proxies: list[_Proxy] = []
        self._channels: list[ScanChannel] = []
        self._subs: dict[str, Any] = {}
        self.decoder = Decoder(log)  # malformed messages dropped, counted by kind
        cmd_key = keys.cmd_vel_key(robot, index, source if per_source_key and source else None)
        opts: dict[str, Any] = {"express": True} if express else {}
        if block:
            opts["congestion_control"] = zenoh.CongestionControl.BLOCK
        self._cmd_pub = self.session.declare_publisher(cmd_key, **opts)
        self._packer = VelCmdPacker(source)
        self._position2d: Position2dProxy | None = None
        self._laser: LaserProxy | None = None
        self._fiducial: FiducialProxy | None = None
        self._simulation: SimulationProxy | None = None

    # -- subscriptions ----------------------------------------------------------------------

    def _subscribe(self, kind: str) -> None:
        if kind in self._subs:
            return
        key, cls = {
            "state": (keys.state_key(self.robot, self.index), State),
            "scan": (keys.scan_key(self.robot, self.index), Scan),
            "fiducial": (keys.fiducial_key(self.robot, self.index), Fiducial),
            "driver": (keys.driver_key(self.robot, self.index), DriverState),
        }[kind]

        def on_sample(sample: zenoh.Sample, kind=kind, cls=cls) -> None:
            msg = self.decoder.decode(cls, sample.payload.to_bytes())
            if msg is None:
                return
            with self._cond:
                self._latest[kind] = msg
                if kind in self._arrived:
                    self._arrived[kind] += 1
                self._cond.notify_all()

        self._subs[kind] = self.session.declare_subscriber(key, on_sample)

    def _tick_kind(self) -> str:
        return "scan" if "scan" in self._subs else "state"

    # -- Player API -------------------------------------------------------------------------

    @property
    def position2d(self) -> Position2dProxy:
        if self._position2d is None:
            self._position2d = Position2dProxy(self)
        return self._position2d

    @property
    def laser(self) -> LaserProxy:
        if self._laser is None:
            self._laser = LaserProxy(self)
        return self._laser

    @property
    def fiducial(self) -> FiducialProxy:
        """The fiducial finder (Player's ``fiducial``; served in a world with beacons)."""
        if self._fiducial is None:
            self._fiducial = FiducialProxy(self)
        return self._fiducial

    @property
    def simulation(self) -> SimulationProxy:
        """The simulator's sim-only requests (Player's ``simulation`` interface)."""
        if self._simulation is None:
            self._simulation = SimulationProxy(self)
        return self._simulation

    def set_pose(self, x: float, y: float, yaw: float, reset_odom: bool = True) -> Ack:
        """Teleport the robot (simulation only); see :meth:`SimulationProxy.set_pose2d`."""
        return self.simulation.set_pose2d(x, y, yaw, reset_odom=reset_odom)

    def read(self, timeout: float | None = 1.0) -> bool:
        """Wait for a new tick (at most ``timeout`` s) and refresh every proxy.

        Returns True when new data arrived, False on timeout (proxies then keep old values)."""
        kind = self._tick_kind()

        def fresh() -> bool:
            return self._arrived[kind] > self._read_mark

        def in_step() -> bool:
            # the server publishes a tick's State and Scan with the same ``ts``; they may land in
            # either order, so a read waits (within ``timeout``) until both are of one tick
            if not fresh():
                return False
            state, scan = self._latest.get("state"), self._latest.get("scan")
            if "state" in self._subs and "scan" in self._subs and (
                    state is None or scan is None or state.ts < scan.ts):
                return False
            # the tick's beacons, sent before its scan: waited for once any came (a world
            # without beacons sends none)
            fid = self._latest.get("fiducial")
            return fid is None or scan is None or fid.seq >= scan.id

        with self._cond:
            self._cond.wait_for(in_step, timeout)
            ok = fresh()
            if ok:
                self._read_mark = self._arrived[kind]
            latest = dict(self._latest)
        if ok:
            for p in self._proxies:
                p._refresh(latest)
        return bool(ok)

    def peek(self) -> bool:
        """Refresh the proxies from what has arrived, without waiting; True if anything new."""
        return self.read(timeout=0.0)

    def driver(self) -> str | None:
        """The command source driving the robot, from the server's driver messages (None: not
        known yet, ``""``: nobody)."""
        self._subscribe("driver")
        with self._cond:
            msg = self._latest.get("driver")
        return None if msg is None else msg.source

    @property
    def dropped(self) -> int:
        """Malformed messages dropped so far (every kind; ``decoder.counts`` by kind)."""
        return self.decoder.total

    def scans(self, depth: int = 1) -> ScanChannel:
        """The robot's scans through a channel of ``depth``: 1, the latest only (a reader never
        acts on a backlog); more, a short queue (the oldest dropped when it is full). Decoded in
        the reader's thread; undeclared by ``close``."""
        channel = ScanChannel(self, depth)
        self._channels.append(channel)
        return channel

    def fiducials(self, depth: int = 64) -> FiducialLog:
        """The robot's fiducial messages of the last ``depth`` ticks by scan id (``at(scan.id)``:
        what the fiducial finder saw at that scan), to pair with the scans of a ``ScanChannel``
        (a behaviour's ``beacon`` features: ``PayloadReader.see``); undeclared by ``close``."""
        log_ = FiducialLog(self, depth)
        self._channels.append(log_)
        return log_

    def send_command(
        self, vx: float, va: float, state: bool = True, scan_id: int | None = None,
        ts: float | None = None,
    ) -> None:
        """Publish a velocity command (prefer :meth:`Position2dProxy.set_speed` or
        :meth:`answer`)."""
        if not (math.isfinite(vx) and math.isfinite(va)):
            raise ValueError(f"speeds must be finite, got vx={vx!r}, va={va!r}")
        # VelCmd(vx=vx, va=va, state=state, source=self.source, ...).encode(), its fixed parts
        # packed once (again if the source was changed)
        if self._packer.source != self.source:
            self._packer = VelCmdPacker(self.source)
        self._cmd_pub.put(self._packer.pack(vx, va, state, scan_id, ts))

    def answer(self, scan: Scan, vx: float, va: float) -> None:
        """Command ``(vx, va)`` as the answer to ``scan``: the command names its id and sim
        time (a lock-step server steps once every driver answered its scan)."""
        self.send_command(vx, va, True, scan.id, scan.ts)

    def request(
        self, iface: str, name: str, payload: bytes | None = None, timeout: float = 2.0
    ) -> bytes:
        """Send a request and return the reply payload; raise :class:`RequestError` on a NACK
        (with its reason) or when nobody answers within ``timeout`` s. ``iface`` ``"sim"``
        names a simulation-only request (``rhbl/<robot>/sim/req/<name>``)."""
        key = (keys.sim_request_key(self.robot, name) if iface == "sim"
               else keys.request_key(self.robot, iface, name, self.index))
        replies = self.session.get(key, payload=payload, timeout=timeout)
        for reply in replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            raw = reply.err.payload.to_bytes()
            try:
                reason = Nack.decode(raw).reason
            except DecodeError:
                reason = raw[:200].decode("utf-8", "replace")
            raise RequestError(f"{key}: NACK: {reason}")
        raise RequestError(f"{key}: no reply within {timeout} s (is the server up?)")

    def wait_for_server(self, timeout: float = 5.0) -> bool:
        """Wait until the robot's first state arrived (True) or ``timeout`` s passed."""
        self._subscribe("state")
        with self._cond:
            return bool(self._cond.wait_for(lambda: "state" in self._latest, timeout))

    def close(self) -> None:
        for ch in self._channels:
            ch.close()
        self._channels.clear()
        for s in self._subs.values():
            try:
                s.undeclare()
            except Exception:  # the session may be closed already
                log.debug("undeclare failed", exc_info=True)
        self._subs.clear()
        try:
            self._cmd_pub.undeclare()
        except Exception:
            log.debug("undeclare failed", exc_info=True)
        if self._own_session:
            self.session.close()

    def __enter__(self) -> PlayerClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ScanChannel:
    """The scans of a client's robot through a zenoh ring channel (``PlayerClient.scans``).

    ``recv()`` blocks for the next scan and decodes it here, in the reader's thread (None: it
    was malformed, dropped and counted by the client's decoder); ``try_recv()`` the same
    without blocking (None also when nothing is there); ``latest()`` takes everything waiting
    and returns the last."""

    def __init__(self, client: PlayerClient, depth: int = 1) -> None:
        if int(depth) < 1:
            raise ValueError(f"a scan channel holds at least one scan, got depth {depth}")
        self._decoder = client.decoder
        self.key = keys.scan_key(client.robot, client.index)
        self._sub = client.session.declare_subscriber(self.key,
                                                      zenoh.handlers.RingChannel(int(depth)))
        self._recv, self._try = self._sub.handler.recv, self._sub.handler.try_recv

    def recv(self) -> Scan | None:
        return self.decode(self.recv_payload())

    def recv_payload(self) -> bytes:
        """The next scan's payload, not decoded (blocks; ``decode`` it, or read it in place with
        a ``client.behaviour.features.PayloadReader``)."""
        return self._recv().payload.to_bytes()

    def decode(self, data: bytes) -> Scan | None:
        """The scan of the payload ``data`` (None: malformed, dropped and counted)."""
        return self._decoder.decode(Scan, data)

    def try_recv(self) -> Scan | None:
        sample = self._try()
        return None if sample is None else self.decode(sample.payload.to_bytes())

    def latest(self) -> Scan | None:
        """Take every scan waiting; the last of them (None: none, or it was malformed)."""
        last = None
        while (sample := self._try()) is not None:
            last = sample
        return None if last is None else self.decode(last.payload.to_bytes())

    def close(self) -> None:
        try:
            self._sub.undeclare()
        except Exception:  # the session may be closed already
            log.debug("undeclare failed", exc_info=True)


class FiducialLog:
    """The fiducial messages of a client's robot, the last ``depth`` of them by ``seq`` (the id of
    the scan of the same tick; ``PlayerClient.fiducials``): ``at(scan_id, timeout=0)`` the
    message of that tick, waiting up to ``timeout`` s for it (None: not here: too old, not come,
    or a world without beacons; the server sends it before its scan, but the two arrive on
    separate subscribers), ``seen(scan_id, timeout=0)`` its items (``()`` when none),
    ``latest``. Decoded on arrival (a malformed one dropped and
    counted by the client's decoder); any thread."""

    def __init__(self, client: PlayerClient, depth: int = 64) -> None:
        if int(depth) < 1:
            raise ValueError(f"a fiducial log holds at least one message, got depth {depth}")
        from collections import OrderedDict

        self.depth = int(depth)
        self._decoder = client.decoder
        self._lock = threading.Condition()
        self._by_seq: OrderedDict[int, Fiducial] = OrderedDict()
        self.latest: Fiducial | None = None
        self.key = keys.fiducial_key(client.robot, client.index)
        self._sub = client.session.declare_subscriber(self.key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        msg = self._decoder.decode(Fiducial, sample.payload.to_bytes())
        if msg is None:
            return
        with self._lock:
            self._by_seq[msg.seq] = msg
            self._by_seq.move_to_end(msg.seq)
            while len(self._by_seq) > self.depth:
                self._by_seq.popitem(last=False)
            self.latest = msg
            self._lock.notify_all()

    def at(self, scan_id: int, timeout: float = 0.0) -> Fiducial | None:
        with self._lock:
            if timeout > 0:  # waited for unless a later tick's came (then it never will)
                self._lock.wait_for(lambda: scan_id in self._by_seq or (
                    self.latest is not None and self.latest.seq > scan_id), timeout)
            return self._by_seq.get(scan_id)

    def seen(self, scan_id: int, timeout: float = 0.0) -> tuple[FiducialItem, ...]:
        msg = self.at(scan_id, timeout)
        return () if msg is None else msg.items

    def close(self) -> None:
        try:
            self._sub.undeclare()
        except Exception:  # the session may be closed already
            log.debug("undeclare failed", exc_info=True)


class _Proxy:
    KINDS: tuple[str, ...] = ()

    def __init__(self, client: PlayerClient) -> None:
        self.client = client
        for k in self.KINDS:
            client._subscribe(k)
        client._proxies.append(self)

    def _refresh(self, latest: dict[str, Any]) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        if self in self.client._proxies:
            self.client._proxies.remove(self)


class Position2dProxy(_Proxy):
    """The robot base: odometry pose ``x``, ``y``, ``yaw``; velocity ``vx``, ``vy``, ``va``;
    ``stall``; ``set_speed(vx, va)``; geometry and odometry requests."""

    KINDS = ("state",)

    def __init__(self, client: PlayerClient) -> None:
        super().__init__(client)
        self.state: State | None = None
        self._geom: Geometry | None = None

    def _refresh(self, latest):
        if "state" in latest:
            self.state = latest["state"]

    def _field(self, name: str, index: int | None = None, default: Any = 0.0):
        if self.state is None:
            return default
        v = getattr(self.state, name)
        return v if index is None else v[index]

    x = property(lambda self: self._field("pos", 0))
    y = property(lambda self: self._field("pos", 1))
    yaw = property(lambda self: self._field("pos", 2))
    vx = property(lambda self: self._field("vel", 0))
    vy = property(lambda self: self._field("vel", 1))
    va = property(lambda self: self._field("vel", 2))
    stall = property(lambda self: bool(self._field("stall", default=False)))
    ts = property(lambda self: self._field("ts"))
    seq = property(lambda self: self._field("seq", default=0))
    driver = property(lambda self: self._field("driver", default=""))

    @property
    def pose(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.yaw)

    @property
    def truth(self) -> tuple[float, float, float] | None:
        """The true pose (a simulation extra), None if not known."""
        return None if self.state is None else self.state.truth

    def set_speed(self, vx: float, va: float, scan_id: int | None = None) -> None:
        """Command forward speed ``vx`` (m/s) and turn rate ``va`` (rad/s, counter-clockwise).
        The command names the last read scan (for lock-step) unless ``scan_id`` is given."""
        if scan_id is None and self.client._laser is not None:
            scan_id = self.client._laser.id if self.client._laser.scan is not None else None
        self.client.send_command(vx, va, True, scan_id)

    def stop(self) -> None:
        self.set_speed(0.0, 0.0)

    def set_motor_enable(self, state: bool) -> None:
        self.client.request("position2d", "motor_power", MotorPower(state=bool(state)).encode())

    def get_geom(self) -> Geometry:
        if self._geom is None:
            self._geom = Geometry.decode(self.client.request("position2d", "get_geom"))
        return self._geom

    @property
    def size(self) -> tuple[float, float]:
        return self.get_geom().size

    def set_odom(self, x: float, y: float, yaw: float) -> None:
        Ack.decode(self.client.request("position2d", "set_odom", SetOdom((x, y, yaw)).encode()))

    def reset_odom(self) -> None:
        Ack.decode(self.client.request("position2d", "reset_odom"))


class LaserProxy(_Proxy):
    """The laser: ``ranges`` (float32 array, ``ranges[0]`` at ``min_angle``, the robot's right),
    ``count``, indexing, ``min_angle``, ``max_angle``, ``resolution``, ``max_range``,
    ``bearings``, the scan ``id`` and the odometry ``pose`` at the scan."""

    KINDS = ("scan",)

    def __init__(self, client: PlayerClient) -> None:
        super().__init__(client)
        self.scan: Scan | None = None

    def _refresh(self, latest):
        if "scan" in latest:
            self.scan = latest["scan"]

    @property
    def ranges(self) -> np.ndarray:
        return self.scan.ranges if self.scan is not None else np.zeros(0, dtype=np.float32)

    @property
    def count(self) -> int:
        return 0 if self.scan is None else self.scan.count

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i):
        return self.ranges[i]

    def _meta(self, name: str, default: float = 0.0):
        return default if self.scan is None else getattr(self.scan, name)

    min_angle = property(lambda self: self._meta("min_angle"))
    max_angle = property(lambda self: self._meta("max_angle"))
    resolution = property(lambda self: self._meta("resolution"))
    max_range = property(lambda self: self._meta("max_range"))
    id = property(lambda self: self._meta("id", 0))
    ts = property(lambda self: self._meta("ts"))
    pose = property(lambda self: self._meta("pose", (0.0, 0.0, 0.0)))

    @property
    def bearings(self) -> np.ndarray:
        """Bearing (rad, robot frame, counter-clockwise) of every beam."""
        return self.min_angle + np.arange(self.count) * self.resolution

    def bearing(self, i: int) -> float:
        return self.min_angle + i * self.resolution

    def get_config(self) -> LaserConfig:
        return LaserConfig.decode(self.client.request("laser", "get_config"))

    def get_geom(self) -> Geometry:
        return Geometry.decode(self.client.request("laser", "get_geom"))


class FiducialProxy(_Proxy):
    """The fiducial finder (libplayerc's ``playerc_fiducial``): ``items`` (the beacons in view,
    each a ``FiducialItem`` of ``id``, ``range``, ``bearing`` and its ``x``, ``y`` in the sensor
    frame), ``count``, indexing, ``find(id)``, the message's ``seq`` (the id of the scan of the
    same tick) and ``ts``; ``get_geom()`` the sensor's geometry, ranges and field of view
    (``FiducialGeometry``). Nothing in view: no items; a world without beacons publishes none,
    so ``fiducial`` stays None."""

    KINDS = ("fiducial",)

    def __init__(self, client: PlayerClient) -> None:
        super().__init__(client)
        self.fiducial: Fiducial | None = None
        self._geom: FiducialGeometry | None = None

    def _refresh(self, latest):
        if "fiducial" in latest:
            self.fiducial = latest["fiducial"]

    @property
    def items(self) -> tuple[FiducialItem, ...]:
        return () if self.fiducial is None else self.fiducial.items

    @property
    def count(self) -> int:
        return len(self.items)

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i) -> FiducialItem:
        return self.items[i]

    def find(self, beacon_id: int) -> FiducialItem | None:
        """The beacon ``beacon_id`` if it is in view (None: not seen, or not identified)."""
        return None if self.fiducial is None else self.fiducial.find(beacon_id)

    seq = property(lambda self: 0 if self.fiducial is None else self.fiducial.seq)
    ts = property(lambda self: 0.0 if self.fiducial is None else self.fiducial.ts)

    def get_geom(self) -> FiducialGeometry:
        """The sensor's pose and size on the robot, ``min_range``, ``max_range``,
        ``max_range_id``, ``fov`` and ``rate`` (asked once, then kept)."""
        if self._geom is None:
            self._geom = FiducialGeometry.decode(self.client.request("fiducial", "get_geom"))
        return self._geom


class SimulationProxy:
    """Simulation-only requests (Player/Stage's ``simulation`` interface): teleport the robot
    and read its true pose. Refused (:class:`RequestError`) by a secured router unless this
    client's credentials may use ``rhbl/*/sim/req/**`` (docs/deployment.md)."""

    def __init__(self, client: PlayerClient) -> None:
        self.client = client

    def set_pose2d(self, x: float, y: float, yaw: float, reset_odom: bool = True,
                   timeout: float = 2.0) -> Ack:
        """Teleport the robot to the true pose (x, y, yaw) if it is free: velocity zeroed,
        stall cleared, odometry set to the pose when ``reset_odom``. The reply's ``extra``
        holds ``pose``, ``scan_id`` (the first scan taken at the new pose) and ``ts``.
        A pose in a wall (or outside the world) is refused: :class:`RequestError` with the
        server's reason."""
        msg = SetPose((float(x), float(y), float(yaw)), reset_odom=bool(reset_odom))
        return Ack.decode(self.client.request("sim", "set_pose", msg.encode(), timeout=timeout))

    def get_pose2d(self, timeout: float = 2.0) -> tuple[float, float, float]:
        """The true pose (x, y, yaw) in the world frame."""
        return self.get_pose(timeout).pose

    def get_pose(self, timeout: float = 2.0) -> SimPose:
        """The true pose, the odometry and the sim time (:class:`SimPose`)."""
        return SimPose.decode(self.client.request("sim", "get_pose", timeout=timeout))

    def get_world(self, timeout: float = 2.0) -> WorldInfo:
        """The world's walls, goal and start poses (``WorldInfo``), e.g. to draw it."""
        return WorldInfo.decode(self.client.request("sim", "get_world", timeout=timeout))
