"""Bus messages -> Foxglove's well-known schemas: what a robotics viewer (Foxglove, Lichtblick)
draws without a plugin. The one home of this conversion: the recorder writes these messages
into a recording's viewer channels (``client.recording.mcap_file``), ``rhbl foxglove`` serves them live.

    feed = ViewerFeed()
    for vm in feed.world("r0", world_info, time_ns):        # walls + goal + robot body
        ...
    for vm in feed.update("scan", "r0", scan, time_ns):      # laser, pose, transform, path
        ...

Each ``ViewerMessage`` carries its topic, its schema (name, encoding, data) and the encoded
message. Topics (frame ``world`` = the world file's coordinates; frame ``<robot>`` = the robot):

| topic | schema | what |
|---|---|---|
| ``/world`` | ``foxglove.SceneUpdate`` | walls (lines), the goal (a disc), the beacons (discs of their colour, with their id), each robot's body (in its frame) |
| ``/tf`` | ``foxglove.FrameTransform`` | ``world`` -> ``<robot>`` at every scan (the true pose) |
| ``/<robot>/laser`` | ``foxglove.LaserScan`` | the scan, in the robot's frame |
| ``/<robot>/pose`` | ``foxglove.PoseInFrame`` | the robot's pose in ``world`` |
| ``/<robot>/path`` | ``foxglove.PosesInFrame`` | the path so far (once per sim second; last 2000 poses 5 cm apart) |
| ``/<robot>/fiducials`` | ``foxglove.SceneUpdate`` | the beacons its fiducial finder sees (a line to each, a ring round it, its id), in the robot's frame (a world with beacons) |
| ``/<robot>/status`` | JSON | who drives, the tree's size (nodes, height, vectors), sim time (on change, at least once per sim second) |
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import foxglove.messages as fm

__all__ = ["STATUS_SCHEMA", "ViewerFeed", "ViewerMessage", "viewer_topics"]

WORLD_FRAME = "world"
PATH_POINTS = 2000  # poses kept in the path message
PATH_STEP = 0.05  # m moved (or 0.1 rad turned) before the path gets a new pose
PATH_PERIOD = 1.0  # sim seconds between path messages

STATUS_SCHEMA = {
    "title": "rhbl.RobotStatus",
    "description": "who drives the robot and the size of the learner's tree (rhbl viewer channel)",
    "type": "object",
    "properties": {
        "robot": {"type": "string"},
        "sim_time": {"type": "number", "description": "sim seconds"},
        "driver": {"type": "string", "description": "the command source driving ('' = nobody)"},
        "nodes": {"type": "integer", "description": "tree nodes (learner notice)"},
        "height": {"type": "integer"},
        "vectors": {"type": "integer", "description": "labeled vectors learned"},
    },
}
_STATUS_SCHEMA_BYTES = json.dumps(STATUS_SCHEMA).encode()


@dataclass(frozen=True)
class ViewerMessage:
    topic: str
    schema_name: str
    schema_encoding: str  # "protobuf" or "jsonschema"
    schema_data: bytes
    encoding: str  # message encoding: "protobuf" or "json"
    data: bytes
    time_ns: int


def viewer_topics(robot: str) -> list[str]:
    return ["/world", "/tf", f"/{robot}/laser", f"/{robot}/pose", f"/{robot}/path",
            f"/{robot}/fiducials", f"/{robot}/status"]


_SCHEMAS: dict[type, tuple[str, str, bytes]] = {}


def _proto(topic: str, msg, time_ns: int) -> ViewerMessage:
    cls = type(msg)
    sch = _SCHEMAS.get(cls)
    if sch is None:
        s = cls.get_schema()
        sch = _SCHEMAS[cls] = (s.name, s.encoding, bytes(s.data))
    return ViewerMessage(topic, sch[0], sch[1], sch[2], "protobuf", msg.encode(), time_ns)


def _stamp(time_ns: int) -> fm.Timestamp:
    return fm.Timestamp(sec=int(time_ns // 1_000_000_000), nsec=int(time_ns % 1_000_000_000))


def _quat(yaw: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def _pose(x: float, y: float, yaw: float, z: float = 0.0) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=float(x), y=float(y), z=z), orientation=_quat(float(yaw)))


def _colour(text: str) -> fm.Color:
    """A ``#rrggbb`` colour (grey when it is not one)."""
    try:
        if len(text) != 7 or text[0] != "#":
            raise ValueError(text)
        r, g, b = (int(text[i:i + 2], 16) / 255.0 for i in (1, 3, 5))
    except (TypeError, ValueError):
        r = g = b = 0.5
    return fm.Color(r=r, g=g, b=b, a=1.0)


@dataclass
class _Robot:
    path: list = field(default_factory=list)
    last_path_ts: float = -1e9
    status: dict = field(default_factory=dict)
    last_status_ts: float = -1e9
    body_sent: bool = False


class ViewerFeed:
    """Stateful conversion (the path, the status) of one bus's messages, robot by robot."""

    def __init__(self, path_points: int = PATH_POINTS, path_period: float = PATH_PERIOD):
        self.path_points = int(path_points)
        self.path_period = float(path_period)
        self.robots: dict[str, _Robot] = {}
        self.worlds: dict[str, object] = {}  # robot -> WorldInfo

    def _robot(self, robot: str) -> _Robot:
        r = self.robots.get(robot)
        if r is None:
            r = self.robots[robot] = _Robot()
        return r

    # -- the world --
    def world(self, robot: str, info, time_ns: int) -> list[ViewerMessage]:
        """The scene of a ``WorldInfo``: walls, goal and the robot's body (``/world``)."""
        self.worlds[robot] = info
        stamp = _stamp(time_ns)
        wall_points = []
        for x0, y0, x1, y1 in info.walls:
            wall_points += [fm.Point3(x=x0, y=y0, z=0.0), fm.Point3(x=x1, y=y1, z=0.0)]
        walls = fm.SceneEntity(
            timestamp=stamp, frame_id=WORLD_FRAME, id=f"walls:{info.name}",
            lines=[fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList,
                                    pose=_pose(0, 0, 0), thickness=0.04, scale_invariant=False,
                                    points=wall_points,
                                    color=fm.Color(r=0.3, g=0.3, b=0.3, a=1.0))],
            metadata=[fm.KeyValuePair(key="world", value=info.name),
                      fm.KeyValuePair(key="task", value=info.task)])
        entities = [walls]
        if info.goal is not None:
            gx, gy, gr = info.goal
            entities.append(fm.SceneEntity(
                timestamp=stamp, frame_id=WORLD_FRAME, id="goal",
                cylinders=[fm.CylinderPrimitive(pose=_pose(gx, gy, 0.0, 0.01),
                                                size=fm.Vector3(x=2 * gr, y=2 * gr, z=0.02),
                                                bottom_scale=1.0, top_scale=1.0,
                                                color=fm.Color(r=0.1, g=0.8, b=0.2, a=0.5))]))
        for b in getattr(info, "beacons", ()):
            entities.append(self._beacon(b, stamp))
        entities.append(self._body(robot, stamp))
        self._robot(robot).body_sent = True
        return [_proto("/world", fm.SceneUpdate(entities=entities), time_ns)]

    @staticmethod
    def _beacon(b, stamp) -> fm.SceneEntity:
        """A beacon of the world: a disc of its colour and size, its id above it."""
        colour = _colour(b.colour)
        x, y = b.pos
        return fm.SceneEntity(
            timestamp=stamp, frame_id=WORLD_FRAME, id=f"beacon:{b.id}",
            cylinders=[fm.CylinderPrimitive(pose=_pose(x, y, 0.0, 0.15),
                                            size=fm.Vector3(x=b.size, y=b.size, z=0.3),
                                            bottom_scale=1.0, top_scale=1.0, color=colour)],
            texts=[fm.TextPrimitive(pose=_pose(x, y, 0.0, 0.45), billboard=True, font_size=14.0,
                                    scale_invariant=True, text=str(b.id),
                                    color=fm.Color(r=1.0, g=1.0, b=1.0, a=1.0))],
            metadata=[fm.KeyValuePair(key="beacon", value=str(b.id))])

    @staticmethod
    def _body(robot: str, stamp) -> fm.SceneEntity:
        """The robot's body, in its own frame (it moves with ``/tf``): a disc of the collision
        radius (0.25 m) and an arrow forward."""
        return fm.SceneEntity(
            timestamp=stamp, frame_id=robot, id=f"robot:{robot}", frame_locked=True,
            cylinders=[fm.CylinderPrimitive(pose=_pose(0, 0, 0, 0.1),
                                            size=fm.Vector3(x=0.5, y=0.5, z=0.2),
                                            bottom_scale=1.0, top_scale=1.0,
                                            color=fm.Color(r=0.2, g=0.4, b=0.9, a=0.8))],
            arrows=[fm.ArrowPrimitive(pose=_pose(0, 0, 0, 0.21), shaft_length=0.3,
                                      shaft_diameter=0.05, head_length=0.1, head_diameter=0.12,
                                      color=fm.Color(r=1.0, g=1.0, b=1.0, a=1.0))])

    # -- the stream --
    def update(self, kind: str, robot: str, msg, time_ns: int) -> list[ViewerMessage]:
        """Viewer messages for one decoded bus message of ``kind`` (``client.recording.mcap_file``'s
        kinds: scan, state, driver, notice, ...); [] for kinds that draw nothing."""
        if kind == "scan":
            return self._scan(robot, msg, time_ns)
        if kind == "state":
            return self._status(robot, time_ns, driver=msg.driver, sim_time=msg.ts)
        if kind == "driver":
            return self._status(robot, time_ns, driver=msg.source, sim_time=msg.ts)
        if kind == "notice":
            return self._status(robot, time_ns, nodes=msg.nodes, height=msg.height,
                                vectors=msg.vectors)
        if kind == "world":
            return self.world(robot, msg, time_ns)
        if kind == "fiducial":
            return self._fiducials(robot, msg, time_ns)
        return []

    def _fiducials(self, robot: str, fid, time_ns: int) -> list[ViewerMessage]:
        """What the robot's fiducial finder sees, in its frame: a line from the sensor to each
        beacon in view, a ring round it and its id (an entity with none: nothing in view)."""
        stamp = _stamp(time_ns)
        seen = fm.Color(r=1.0, g=0.85, b=0.1, a=1.0)
        lines, texts = [], []
        for item in fid.items:
            px, py = item.x, item.y
            ring = [fm.Point3(x=px + 0.25 * math.cos(a), y=py + 0.25 * math.sin(a), z=0.3)
                    for a in (k * math.tau / 16 for k in range(17))]
            lines += [fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList,
                                       pose=_pose(0, 0, 0), thickness=0.02,
                                       scale_invariant=False, color=seen,
                                       points=[fm.Point3(x=0.0, y=0.0, z=0.3),
                                               fm.Point3(x=px, y=py, z=0.3)]),
                      fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip,
                                       pose=_pose(0, 0, 0), thickness=0.04,
                                       scale_invariant=False, color=seen, points=ring)]
            texts.append(fm.TextPrimitive(
                pose=_pose(px, py, 0.0, 0.6), billboard=True, font_size=14.0,
                scale_invariant=True, color=seen,
                text=f"{item.id or '?'} {item.range:.2f} m {math.degrees(item.bearing):+.0f} deg"))
        entity = fm.SceneEntity(timestamp=stamp, frame_id=robot, id=f"fiducials:{robot}",
                                frame_locked=True, lines=lines, texts=texts)
        return [_proto(f"/{robot}/fiducials", fm.SceneUpdate(entities=[entity]), time_ns)]

    def _scan(self, robot: str, scan, time_ns: int) -> list[ViewerMessage]:
        x, y, yaw = scan.truth if scan.truth is not None else scan.pose
        stamp = _stamp(time_ns)
        r = self._robot(robot)
        out = []
        if not r.body_sent:  # no world (not a simulator): the robot's body alone
            r.body_sent = True
            out.append(_proto("/world", fm.SceneUpdate(entities=[self._body(robot, stamp)]),
                              time_ns))
        out.append(_proto("/tf", fm.FrameTransform(
            timestamp=stamp, parent_frame_id=WORLD_FRAME, child_frame_id=robot,
            translation=fm.Vector3(x=float(x), y=float(y), z=0.0), rotation=_quat(float(yaw))),
            time_ns))
        out.append(_proto(f"/{robot}/laser", fm.LaserScan(
            timestamp=stamp, frame_id=robot, pose=_pose(0, 0, 0),
            start_angle=float(scan.min_angle),
            end_angle=float(scan.min_angle + (scan.count - 1) * scan.resolution),
            ranges=scan.ranges.tolist(), intensities=[]), time_ns))
        pose = _pose(x, y, yaw)
        out.append(_proto(f"/{robot}/pose", fm.PoseInFrame(timestamp=stamp, frame_id=WORLD_FRAME,
                                                            pose=pose), time_ns))
        last = r.path[-1] if r.path else None
        if (last is None or math.hypot(x - last[0], y - last[1]) >= PATH_STEP
                or abs(math.remainder(yaw - last[2], math.tau)) >= 0.1):
            r.path.append((float(x), float(y), float(yaw)))
            del r.path[:-self.path_points]
        if scan.ts - r.last_path_ts >= self.path_period or scan.ts < r.last_path_ts:
            r.last_path_ts = scan.ts
            out.append(_proto(f"/{robot}/path", fm.PosesInFrame(
                timestamp=stamp, frame_id=WORLD_FRAME,
                poses=[_pose(*p) for p in r.path]), time_ns))
        return out

    def _status(self, robot: str, time_ns: int, **changes) -> list[ViewerMessage]:
        r = self._robot(robot)
        sim_time = changes.pop("sim_time", None)
        changed = any(r.status.get(k) != v for k, v in changes.items())
        if sim_time is not None:
            r.status["sim_time"] = float(sim_time)
            # also once per sim second: a viewer that joins late sees who drives
            changed = changed or not 0 <= sim_time - r.last_status_ts < 1.0
        if not changed:
            return []
        if sim_time is not None:
            r.last_status_ts = float(sim_time)
        r.status.update(changes)
        doc = {"robot": robot, **r.status}
        return [ViewerMessage(f"/{robot}/status", "rhbl.RobotStatus", "jsonschema",
                              _STATUS_SCHEMA_BYTES, "json", json.dumps(doc).encode(), time_ns)]
