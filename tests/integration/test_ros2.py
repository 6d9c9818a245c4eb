"""ROS 2 over zenoh, against code nobody here wrote (docs/ros2.md).

Real processes on loopback: ``rhbl server``, ``rhbl ros2``, ``rhbl controller --ros2`` and
``rhbl record --ros2``. What they put on rmw_zenoh's keys is read by a raw zenoh subscriber on
keys built here from ``rosbags``' type hashes, decoded by ``rosbags`` and by
``mcap-ros2-support``'s decoder (from the .msg text ``rosbags`` gives), and compared with the
server's own scans and states; the liveliness tokens are read against rmw_zenoh's format
(written out here from its ``liveliness_utils.cpp``); Twists are encoded by ``rosbags``; the
ROS 2 robot a tree drives is ``ros2_robot.Ros2StyleRobot`` (rosbags, the simulator's world and
laser kernels, none of ``protocol.ros2``).
"""

from __future__ import annotations

import json
import math
import re
import signal
import struct
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xxhash

zenoh = pytest.importorskip("zenoh")

from mcap.reader import make_reader  # noqa: E402
from mcap.records import Schema  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rosbags.rosbag2 import Reader as BagReader  # noqa: E402
from waiting import eventually, patience  # noqa: E402

from client.behaviour.learning import TreePolicy  # noqa: E402
from lab.children import Child, free_port, rhbl_argv  # noqa: E402
from lab.evaluate import evaluate, success  # noqa: E402
from lab.harness import make_learner, resolve_world  # noqa: E402
from lab.recipe import RECIPES  # noqa: E402
from lab.train import train  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import MAX_VX, Scan, State  # noqa: E402
from protocol.ros2.graph import LivelinessToken  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros2_robot import (  # noqa: E402
    LASER_SCAN,
    ODOMETRY,
    STORE,
    TWIST,
    OtherLaser,
    Ros2StyleRobot,
    ros2_key,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
TF, CLOCK = "tf2_msgs/msg/TFMessage", "rosgraph_msgs/msg/Clock"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
KEYS = {"/r0/scan": LASER_SCAN, "/r0/odom": ODOMETRY, "/tf": TF, "/clock": CLOCK}
T = STORE.types

# rmw_zenoh's liveliness token (liveliness_utils.cpp: Entity::make and keyexpr_to_entity):
# @ros2_lv/<domain>/<zid>/<nid>/<id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>
# [/<topic>/<type>/<type hash>/<qos>] with '/' in names replaced by '%'
TOKEN = re.compile(
    r"^@ros2_lv/(?P<domain>\d+)/(?P<zid>[0-9a-f]{1,32})/(?P<nid>\d+)/(?P<id>\d+)/"
    r"(?P<kind>NN|MP|MS|SS|SC)/(?P<enclave>[^/]+)/(?P<ns>[^/]+)/(?P<node>[^/]+)"
    r"(?:/(?P<topic>[^/]+)/(?P<type>[^/]+)/(?P<hash>RIHS01_[0-9a-f]{64})/(?P<qos>[^/]+))?$")


def _decode_independently(typename: str, data: bytes):
    """(rosbags' message, mcap-ros2-support's) of CDR ``data``."""
    schema = Schema(id=1, name=typename, encoding="ros2msg",
                    data=STORE.generate_msgdef(typename, ros_version=2)[0].encode())
    return (STORE.deserialize_cdr(data, typename),
            DecoderFactory().decoder_for("cdr", schema)(data))


def _twist_cdr(vx: float, va: float) -> bytes:
    vec = T["geometry_msgs/msg/Vector3"]
    return bytes(STORE.serialize_cdr(T[TWIST](linear=vec(x=vx, y=0.0, z=0.0),
                                              angular=vec(x=0.0, y=0.0, z=va)), TWIST))


def _attachment(seq: int) -> bytes:
    return struct.pack("<qqB", seq, time.time_ns(), 16) + b"\x07" * 16


class Bus:
    """What a raw client session saw: samples per key (payload, attachment, arrival order) and
    liveliness tokens; waits on a condition, never a fixed time."""

    def __init__(self, session):
        self.session = session
        self.cond = threading.Condition()
        self.samples: dict[str, list[tuple[bytes, bytes | None]]] = {}
        self.tokens: set[str] = set()
        self.states: list[State] = []
        self.scans: list[Scan] = []
        self.subs = [
            session.declare_subscriber("0/**", self._on_ros),
            session.declare_subscriber(keys.state_key("r0"), self._on_state),
            session.declare_subscriber(keys.scan_key("r0"), self._on_scan),
            session.liveliness().declare_subscriber("@ros2_lv/0/**", self._on_token,
                                                    history=True),
        ]

    def _on_ros(self, s) -> None:
        att = s.attachment.to_bytes() if s.attachment is not None else None
        with self.cond:
            self.samples.setdefault(str(s.key_expr), []).append((s.payload.to_bytes(), att))
            self.cond.notify_all()

    def _on_state(self, s) -> None:
        with self.cond:
            self.states.append(State.decode(s.payload.to_bytes()))
            self.cond.notify_all()

    def _on_scan(self, s) -> None:
        with self.cond:
            self.scans.append(Scan.decode(s.payload.to_bytes()))
            self.cond.notify_all()

    def _on_token(self, s) -> None:
        with self.cond:
            if s.kind == zenoh.SampleKind.PUT:
                self.tokens.add(str(s.key_expr))
            else:
                self.tokens.discard(str(s.key_expr))
            self.cond.notify_all()

    def wait(self, what, timeout: float = 30.0, why: str = ""):
        with self.cond:
            assert self.cond.wait_for(what, patience(timeout)), why or "timed out"

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()


def _bridge(endpoint: str, tmp: Path, name: str = "ros2", *extra: str) -> Child:
    c = Child(name, rhbl_argv("ros2", "--connect", endpoint, "--stats", str(tmp / f"{name}.json"),
                              *extra), cwd=ROOT, stop_signal=signal.SIGINT, escalate=False)
    c.stats = tmp / f"{name}.json"
    return c.start()


def _graph(session) -> set[str]:
    """The ROS 2 graph's liveliness tokens now (rmw_zenoh's, domain 0). The query ends when the
    router has answered; the timeout only bounds a router too busy to answer."""
    return {str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/0/**", timeout=10.0)
            if r.ok is not None}


def _zid(token: str) -> str:
    """The zenoh session id in an rmw_zenoh liveliness token's key."""
    return LivelinessToken.parse(token).zid


def _bridging(session, bus, *args, others: tuple[Child, ...] = ()) -> Child:
    """``_bridge(*args)``, once it bridges: its two cmd_vel subscriptions are in the graph and
    a LaserScan of its own /r0/scan publisher (the GID in the sample's attachment: XXH3-128 of
    that publisher's token) is on the bus, told apart from the ``others`` bridges of the same
    server by their zenoh session ids (and from any other session by the tokens that were there
    before it started). The new bridge's session id becomes its ``zid``."""
    # a session opened a moment ago may answer a liveliness query with nothing yet: the
    # server's token seen first, then the graph as it is
    eventually(lambda: [r for r in session.liveliness().get(keys.alive_key("server", "**"),
                                                            timeout=1.0) if r.ok is not None],
               30, "the server's token seen by the test's session")
    # the sessions already in the graph (another bridge of the same server: a module's): by
    # their zenoh session ids, from two queries (a reply one query misses on a loaded machine
    # must not make another bridge's tokens look like the new one's)
    before = {_zid(k) for k in _graph(session) | _graph(session)} | {b.zid for b in others}
    bridge = _bridge(*args)
    eventually(lambda: [r for r in session.liveliness().get(keys.alive_key("ros2", "*"),
                                                            timeout=1.0)
                        if r.ok is not None and str(r.ok.key_expr).endswith(f"-{bridge.pid}")],
               60, "the new bridge's process token (rhbl/alive/ros2/<robot>-<pid>)",
               alive=[bridge])

    def new_tokens() -> list[str]:
        return sorted(k for k in _graph(session) if _zid(k) not in before)

    tokens = eventually(new_tokens, 60, "the new bridge's cmd_vel subscriptions and /r0/scan "
                        "publisher in the ROS 2 graph", alive=[bridge],
                        until=lambda new: sum("/MS/" in k and "cmd_vel" in k for k in new) >= 2
                        and any("/MP/" in k and "%r0%scan/" in k for k in new))
    zids = {_zid(k) for k in tokens}
    assert len(zids) == 1, tokens  # one session: the new bridge's
    bridge.zid = zids.pop()
    scan_token = next(k for k in tokens if "/MP/" in k and "%r0%scan/" in k)
    gid = xxhash.xxh3_128_intdigest(scan_token.encode()).to_bytes(16, "little")
    key = ros2_key(0, "/r0/scan", LASER_SCAN)

    def from_it() -> bool:
        with bus.cond:
            return any(att is not None and att[17:33] == gid for _, att in bus.samples.get(key, []))

    eventually(from_it, 60, f"a LaserScan from the new bridge's publisher {scan_token}",
               alive=[bridge])
    return bridge


def _stop(child: Child) -> dict:
    assert child.stop() == 0, child.output()
    return json.loads(child.stats.read_text())


@pytest.fixture(scope="module")
def server(start_module_server):
    return start_module_server("room")


@pytest.fixture(scope="module")
def bridged(server, tmp_path_factory):
    """A bridge of the module's server, seen from its start by a raw subscriber."""
    tmp = tmp_path_factory.mktemp("ros2")
    with zenoh.open(make_config(mode="client", connect=[server.endpoint])) as session:
        bus = Bus(session)
        bridge = _bridging(session, bus, server.endpoint, tmp)
        yield bus, bridge
        bus.close()
        bridge.stop()


def test_the_bridges_samples_decode_to_the_servers_scans_and_poses(bridged):
    bus, bridge = bridged
    ros_keys = {topic: ros2_key(0, topic, typename) for topic, typename in KEYS.items()}
    bus.wait(lambda: all(len(bus.samples.get(k, [])) >= 10 for k in ros_keys.values()),
             why=f"samples on {ros_keys}: got {sorted(bus.samples)}")
    with bus.cond:
        samples = {t: list(bus.samples[k]) for t, k in ros_keys.items()}
        scans = {round(s.ts, 6): s for s in bus.scans}
        states = {round(s.ts, 6): s for s in bus.states}
    # the type hashes in the keys are the ones rosbags computes
    for topic, typename in KEYS.items():
        assert ros_keys[topic].rsplit("/", 1)[1] == STORE.hash_rihs01(typename)
    compared = 0
    for data, _ in samples["/r0/scan"]:
        ours, theirs = _decode_independently(LASER_SCAN, data)
        t = round(ours.header.stamp.sec + ours.header.stamp.nanosec * 1e-9, 6)
        scan = scans.get(t)
        if scan is None:
            continue  # before the raw subscriber's first rhbl scan
        for m in (ours, theirs):
            ranges = np.asarray(m.ranges, dtype=np.float32)
            echo = scan.ranges < scan.max_range
            assert np.array_equal(ranges[echo], scan.ranges[echo])
            assert np.isinf(ranges[~echo]).all()  # REP-117: no echo
            assert m.angle_min == np.float32(scan.min_angle)
            assert m.angle_increment == np.float32(scan.resolution)
            assert m.angle_max == np.float32(scan.max_angle)
            assert (m.range_max, m.scan_time, m.header.frame_id) == (
                np.float32(scan.max_range), np.float32(0.1), "r0/base_link")
        compared += 1
    assert compared >= 5, "too few scans of the server matched"
    compared = 0
    for (odom_data, _), (tf_data, _) in zip(samples["/r0/odom"], samples["/tf"], strict=False):
        for odom in _decode_independently(ODOMETRY, odom_data):
            t = round(odom.header.stamp.sec + odom.header.stamp.nanosec * 1e-9, 6)
            state = states.get(t)
            if state is None:
                break
            p, q = odom.pose.pose.position, odom.pose.pose.orientation
            assert (p.x, p.y) == pytest.approx(state.pos[:2], abs=1e-12)
            assert math.atan2(2 * q.w * q.z, 1 - 2 * q.z * q.z) == pytest.approx(state.pos[2],
                                                                               abs=1e-9)
            v = odom.twist.twist
            assert (v.linear.x, v.linear.y, v.angular.z) == pytest.approx(state.vel, abs=1e-12)
            assert (odom.header.frame_id, odom.child_frame_id) == ("r0/odom", "r0/base_link")
        else:
            for tf in _decode_independently(TF, tf_data):
                (x,) = tf.transforms
                assert (x.header.frame_id, x.child_frame_id) == ("r0/odom", "r0/base_link")
                assert (x.transform.translation.x, x.transform.translation.y) == \
                    pytest.approx(state.pos[:2], abs=1e-12)
            compared += 1
    # /clock is best effort with depth 1 (rclcpp's clock QoS): a busy subscriber may miss some,
    # so each one is held to a state of the server, not to the odometry beside it
    clocks = 0
    for clock_data, _ in samples["/clock"]:
        for clock in _decode_independently(CLOCK, clock_data):
            t = round(clock.clock.sec + clock.clock.nanosec * 1e-9, 6)
            if t in states:
                clocks += 1
            else:
                assert not min(states) < t < max(states), f"a /clock time {t} no state had"
    assert clocks >= 5, "too few /clock samples matched the server's states"
    assert compared >= 5, "too few states of the server matched"


def test_the_bridges_tokens_and_attachments_are_rmw_zenohs(bridged):
    bus, bridge = bridged
    bus.wait(lambda: len(bus.tokens) >= 7, why=f"tokens: {bus.tokens}")
    zid = re.search(r"ros2 up \(pid \d+, zid ([0-9a-f]+)\)", bridge.output()).group(1)
    parsed = {}
    for key in bus.tokens:
        m = TOKEN.match(key)
        assert m, f"not rmw_zenoh's token format: {key}"
        assert (m["domain"], m["zid"], m["enclave"], m["ns"], m["node"]) == (
            "0", zid, "%", "%r0", "rhbl_bridge")
        parsed[key] = m
    kinds = sorted((m["kind"], (m["topic"] or "").replace("%", "/"), m["type"] or "")
                   for m in parsed.values())
    assert kinds == [
        ("MP", "/clock", "rosgraph_msgs::msg::dds_::Clock_"),
        ("MP", "/r0/odom", "nav_msgs::msg::dds_::Odometry_"),
        ("MP", "/r0/scan", "sensor_msgs::msg::dds_::LaserScan_"),
        ("MP", "/tf", "tf2_msgs::msg::dds_::TFMessage_"),
        ("MS", "/r0/cmd_vel", "geometry_msgs::msg::dds_::TwistStamped_"),
        ("MS", "/r0/cmd_vel", "geometry_msgs::msg::dds_::Twist_"),
        ("NN", "", "")]
    node = next(m for m in parsed.values() if m["kind"] == "NN")
    assert node["nid"] == node["id"]
    assert {m["nid"] for m in parsed.values()} == {node["nid"]}
    assert len({m["id"] for m in parsed.values()}) == len(parsed)  # ids unique in the session
    qos = {(m["topic"] or "").replace("%", "/"): m["qos"] for m in parsed.values()}
    assert qos["/r0/scan"] == "2::,5:,:,:,,"  # best effort, keep last 5: sensor data
    assert qos["/r0/odom"] == qos["/r0/cmd_vel"] == "::,10:,:,:,,"  # ROS 2's default
    for m in parsed.values():
        if m["type"]:
            pkg, name = re.match(r"(\w+)::msg::dds_::(\w+)_$", m["type"]).groups()
            assert m["hash"] == STORE.hash_rihs01(f"{pkg}/msg/{name}")
    # each publisher's samples: 33 bytes, a sequence number 1, 2, ... (subscribed before the bridge
    # started), its wall-clock time, and the GID rmw_zenoh derives from the token key
    gids = {m["topic"].replace("%", "/"): xxhash.xxh3_128_intdigest(key.encode()).to_bytes(
        16, "little") for key, m in parsed.items() if m["kind"] == "MP"}
    want = [ros2_key(0, t, typename) for t, typename in KEYS.items()]
    bus.wait(lambda: all(len(bus.samples.get(k, [])) >= 3 for k in want),
             why=f"samples on {want}: got {sorted(bus.samples)}")  # the tokens come first
    with bus.cond:
        samples = {t: list(bus.samples[ros2_key(0, t, typename)]) for t, typename in KEYS.items()}
    now = time.time_ns()
    for topic, got in samples.items():
        atts = [att for _, att in got]
        assert all(att is not None and len(att) == 33 and att[16] == 16 for att in atts)
        seqs = [struct.unpack_from("<q", att)[0] for att in atts]
        # numbered 1, 2, ... in publishing order; a sample a busy subscriber missed leaves a
        # gap (rmw_zenoh drops rather than blocks for a KEEP_LAST topic), never a reordering
        assert seqs == sorted(set(seqs)) and seqs[0] >= 1, topic
        assert len(seqs) >= seqs[-1] // 2, (topic, seqs)
        stamps = [struct.unpack_from("<q", att, 8)[0] for att in atts]
        assert stamps == sorted(stamps) and now - 600e9 < stamps[0] <= now
        assert {att[17:] for att in atts} == {gids[topic]}, topic


def _driver_and_speed(bus: Bus, since: int):
    with bus.cond:
        return [(s.ts, s.driver, s.vel[0]) for s in bus.states[since:]]


def test_a_twist_from_rosbags_moves_the_robot_and_the_watchdog_stops_it(bridged):
    bus, _ = bridged
    key = ros2_key(0, "/r0/cmd_vel", TWIST)
    pub = bus.session.declare_publisher(key)
    with bus.cond:
        mark, x0 = len(bus.states), bus.states[-1].pos[0]
    sent = []
    try:
        # one Twist per state for 1 s of sim time, asking more than the robot's limit
        for seq in range(1, 11):
            n = len(bus.states)
            bus.wait(lambda n=n: len(bus.states) > n)
            pub.put(_twist_cdr(2.0, 0.0), attachment=_attachment(seq))
            sent.append(bus.states[-1].ts)
        def stopped_a_while():  # three states after the first without a driver, once the
            seen = _driver_and_speed(bus, mark)  # last Twist sent has driven (a busy bridge
            driven = [ts for ts, d, _ in seen if d == "ros2"]  # may deliver it late)
            idle = [k for k, (ts, d, _) in enumerate(seen)
                    if d == "" and driven and ts > max(driven[-1], sent[-1])]
            return bool(idle) and len(seen) - idle[0] > 3

        bus.wait(stopped_a_while, why="the watchdog did not stop the robot")
    finally:
        pub.undeclare()
    seen = _driver_and_speed(bus, mark)
    driving = [(ts, v) for ts, d, v in seen if d == "ros2"]
    assert len(driving) >= 8
    assert max(v for _, v in driving) == pytest.approx(MAX_VX, abs=0.02)  # clamped to 0.5 m/s
    with bus.cond:
        assert bus.states[-1].pos[0] > x0 + 0.3  # it moved forward
    last = max(driving[-1][0], sent[-1])
    stopped = next(ts for ts, d, _ in seen if d == "" and ts > last)
    # the server's watchdog (0.5 s sim after the last Twist it got) and a tick
    assert stopped - driving[-1][0] <= 0.5 + 0.25
    after = [v for ts, d, v in seen if ts > stopped]
    # it stands still: no command drives it; a robot that touched a wall while driving is
    # still pushed out of it by the contact solver at a few 1e-7 m/s
    assert after and all(abs(v) < 1e-5 for v in after)


def test_malformed_cdr_on_cmd_vel_is_rejected_counted_and_moves_nothing(server, bridged, tmp_path):
    nan = _twist_cdr(float("nan"), 0.0)
    good = _twist_cdr(0.2, 0.0)
    bad = [b"", b"\x00\x01\x00\x00", b"garbage" * 3, good[:20], good + b"\x00" * 8,
           b"\x00\x07\x00\x00" + good[4:], nan,
           bytes(STORE.serialize_cdr(T[CLOCK](clock=T["builtin_interfaces/msg/Time"](
               sec=1, nanosec=2)), CLOCK))]
    with zenoh.open(make_config(mode="client", connect=[server.endpoint])) as session:
        bus = Bus(session)
        # the module's bridge runs beside this one
        bridge = _bridging(session, bus, server.endpoint, tmp_path, "ros2-bad",
                           others=(bridged[1],))
        key = ros2_key(0, "/r0/cmd_vel", TWIST)
        pub = session.declare_publisher(key)
        bus.wait(lambda: bus.states and bus.states[-1].driver == "")  # nobody drives now
        scan_key = ros2_key(0, "/r0/scan", LASER_SCAN)

        def scans() -> int:  # the bridge's scans seen so far (maybe none yet)
            return len(bus.samples.get(scan_key, []))

        with bus.cond:
            mark = len(bus.states)
            pose = bus.states[-1].pos
        for k, data in enumerate(bad, 1):
            pub.put(data, attachment=_attachment(k))
        stamped = bytes(STORE.serialize_cdr(T[TWIST_STAMPED](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
                sec=0, nanosec=0), frame_id=""), twist=STORE.deserialize_cdr(good, TWIST)),
            TWIST_STAMPED))
        # behind the bad ones on the same path, in order: a valid TwistStamped drives
        session.put(ros2_key(0, "/r0/cmd_vel", TWIST_STAMPED), stamped,
                    attachment=_attachment(1))
        bus.wait(lambda: any(s.driver == "ros2" for s in bus.states[mark:]),
                 why="a valid TwistStamped after the bad ones did not drive")
        pub.undeclare()
        with bus.cond:
            first = next(k for k, s in enumerate(bus.states[mark:]) if s.driver == "ros2")
            untouched = bus.states[mark:mark + first]
            after = scans()
        assert all(s.pos == pose and s.driver == "" for s in untouched)  # nothing moved it
        # the bridge goes on publishing after the bad ones (all of them, and the valid one
        # behind them, may be handled within one scan period: no scan need fall between)
        bus.wait(lambda: scans() > after + 3,
                 why="the bridge stopped publishing scans after the malformed commands")
        assert bridge.poll() is None
        stats = _stop(bridge)
        bus.close()
    r0 = stats["robots"]["r0"]
    assert (stats["cmd_vel_rejected"], r0["cmd_vel_rejected"], r0["cmd_vel"]) == (
        len(bad), len(bad), 1)
    assert "dropped a malformed cmd_vel" in bridge.output()


@pytest.mark.parametrize(("argv", "says"), [
    (["ros2", "--robot", "r-1"], "has no ROS 2 name"),
    (["ros2", "--domain", "-1"], "(a ROS 2 domain id)"),
    (["ros2", "--domain", "233"], "(a ROS 2 domain id)"),
    (["ros2", "--ros-namespace", "fleet"], "--ros-namespace: a ROS 2 namespace"),
    (["ros2", "--scan-topic", "a b"], "--scan-topic: a ROS 2 topic name"),
    (["ros2", "--clock-topic", "~/clock"], "--clock-topic: a ROS 2 topic name"),
    (["ros2", "--robot", "r0", "--robot", "r0"], "each robot once"),
    (["controller", "--tree", "t.rhbl", "--ros2", "--robot", "a.b"], "has no ROS 2 name"),
    (["controller", "--tree", "t.rhbl", "--scan-topic", "/scan"], "only with --ros2"),
    (["controller", "--tree", "t.rhbl", "--ros2", "--odom-topic", "odom/"], "--odom-topic"),
    (["record", "--out", "x.mcap", "--ros2", "--robot", "r-0"], "has no ROS 2 name"),
    (["record", "--out", "x.mcap", "--tf-topic", "/tf2"], "only with --ros2"),
])
def test_bad_ros2_options_exit_2_before_connecting(argv, says, tmp_path):
    """One line naming the option, exit 2, before any connection (nothing listens there)."""
    (tmp_path / "t.rhbl").write_bytes(b"")  # an input file must exist for the parse to go on
    argv = [str(tmp_path / a) if a in ("x.mcap", "t.rhbl") else a for a in argv]
    c = Child("bad", rhbl_argv(*argv, "--connect", f"tcp/127.0.0.1:{free_port()}"), cwd=ROOT)
    assert c.start().wait(60) == 2, c.output()
    assert says in c.output(), c.output()
    assert "cannot open a zenoh session" not in c.output()


def test_record_ros2_is_read_by_mcap_ros2_and_rosbags(server, tmp_path):
    out = tmp_path / "bag.mcap"
    rec = Child("rec", rhbl_argv("record", "--ros2", "--out", str(out), "--robot", "r0",
                                 "--connect", server.endpoint, "--duration", "1.5",
                                 "--stats", str(tmp_path / "rec.json")), cwd=ROOT)
    assert rec.start().wait(60) == 0, rec.output()
    stats = json.loads((tmp_path / "rec.json").read_text())
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        channels = {c.topic: c for c in reader.get_summary().channels.values()}
        got: dict[str, list] = {}
        for _, channel, message, decoded in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append((message, decoded))
    assert set(got) == set(KEYS) == set(channels)
    counts = {t: len(v) for t, v in got.items()}
    assert len(set(counts.values())) == 1 and counts["/r0/scan"] >= 10, counts  # one per tick
    assert sum(counts.values()) == stats["messages"]
    for topic, typename in KEYS.items():
        assert channels[topic].metadata["topic_type_hash"] == STORE.hash_rihs01(typename)
        assert channels[topic].message_encoding == "cdr"
    scans = [d for _, d in got["/r0/scan"]]
    assert {(len(s.ranges), round(s.scan_time, 6), s.header.frame_id) for s in scans} == {
        (360, 0.1, "r0/base_link")}
    stamps = [s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 for s in scans]
    assert np.allclose(np.diff(stamps), 0.1, atol=1e-6)  # the sim time, tick by tick
    with BagReader(out) as bag:  # rosbags' rosbag2 reader: rosbag2's own checks of the file
        assert {c.topic: c.msgtype for c in bag.connections} == KEYS
        assert sum(1 for _ in bag.messages()) == stats["messages"]


# ---- a learned tree drives a ROS 2 robot whose laser differs ----------------------------------


@pytest.fixture(scope="module")
def wall_tree(tmp_path_factory) -> Path:
    """The wall-following recipe's tree (``rhbl train --world room``), trained in-process."""
    spec = resolve_world("room")
    learner = make_learner("wall-following")
    train(spec, learner, RECIPES["wall-following"], seed=0)
    path = tmp_path_factory.mktemp("tree") / "wall.rhbl"
    learner.save(path)
    return path


def _controller(endpoint: str, tree: Path, tmp: Path, name: str = "controller") -> Child:
    c = Child(name, rhbl_argv("controller", "--ros2", "--tree", str(tree), "--connect",
                              endpoint, "--wait-server", "120",
                              "--stats", str(tmp / f"{name}.json")),
              cwd=ROOT, stop_signal=signal.SIGINT, escalate=False)
    c.stats = tmp / f"{name}.json"
    return c.start()


def test_a_tree_drives_a_640_beam_240_degree_ros2_robot_as_well_as_natively(wall_tree, tmp_path):
    """Same tree, same world, same starts, same sim seconds, the same success rule as
    ``rhbl evaluate``: natively (the simulator's 360-beam 180-degree laser, in-process) and
    through ``rhbl controller --ros2`` driving the ROS 2-style robot (640 beams over 240
    degrees, 10 m, resampled by the controller)."""
    spec = resolve_world("room")
    policy = TreePolicy.load(wall_tree)
    native = evaluate(spec, policy)
    steps = int(round(native["seconds"] / 0.1))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    ros2_success = []
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        ctl = _controller(endpoint, wall_tree, tmp_path)
        try:
            for k, start in enumerate(spec.start_poses):
                robot = Ros2StyleRobot(session, spec, start, policy.actions, seed=k)
                try:
                    ep = robot.run(steps)
                finally:
                    robot.close()
                m = ep.metrics(spec.goal)
                assert m["seconds"] == native["learner"][k]["seconds"]
                ros2_success.append(success("wall-following", m, native["teacher"][k]))
                assert "other" not in ep.actions  # every Twist was one of the tree's actions
        finally:
            stats = _stop(ctl)
    assert sum(ros2_success) >= sum(native["success"]), (ros2_success, native["success"])
    assert sum(native["success"]) >= len(spec.start_poses) - 1  # the recipe's tree is good
    assert stats["commands"] >= steps * len(spec.start_poses) and stats["dropped"] == {}
    assert "640-beam laser over 240.0 deg" in ctl.output()


def test_a_laser_that_cannot_give_the_trees_features_is_refused_with_exit_2(wall_tree, tmp_path):
    """A 170-degree laser does not see the wall features' rightmost beam: exit 2, one line."""
    spec = resolve_world("room")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        ctl = _controller(endpoint, wall_tree, tmp_path)
        robot = Ros2StyleRobot(session, spec, spec.pose, TreePolicy.load(wall_tree).actions,
                               laser=OtherLaser(spec, count=341, fov_deg=170.0))
        try:
            # published until the controller has read one and given up
            eventually(lambda: robot.publish() or ctl.wait(0.2) is not None, 120,
                       "the controller's exit on a laser it cannot use")
        finally:
            robot.close()
    assert ctl.wait(30) == 2, ctl.output()
    assert "the tree's features cannot be had from this laser" in ctl.output()
    assert "they need beam 0 +/- 11.25 deg from the right" in ctl.output()
    assert "its 341 beams cover only -85.2..85.3 deg" in ctl.output()  # float32 angles
    assert "Traceback" not in ctl.output()

