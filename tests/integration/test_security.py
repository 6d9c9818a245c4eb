"""The shipped router security (docker/zenoh/router.json5) on loopback, with real zenoh sessions.

A Python session in router mode (docker/router_standin.py) runs the very config file the compose
router uses, with secrets freshly made by scripts/gen-dev-secrets.sh in a temporary directory.
Clients use the generated per-role configs, as the processes do with ``--zenoh-config``.
Every wait is bounded, and none is a fixed time: that a message did NOT arrive is known once a
message sent after it, on a path it would have taken, has (``_passed``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

zenoh = pytest.importorskip("zenoh")
from waiting import eventually, patience  # noqa: E402

from lab.children import free_port  # noqa: E402
from protocol import keys  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
ROUTER_CONFIG = ROOT / "docker" / "zenoh" / "router.json5"
GEN_SECRETS = ROOT / "scripts" / "gen-dev-secrets.sh"
ROLES = ("server", "teacher", "learner", "controller", "ros2")
ROBOT = "r0"
# a read-only request every role may make of the server: its answer tells a sender that the
# router has handled everything the sender sent before (``_passed``)
BARRIER = keys.request_key(ROBOT, "position2d", "get_barrier")


def _load_standin():
    spec = importlib.util.spec_from_file_location(
        "router_standin", ROOT / "docker" / "router_standin.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def secrets(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("secrets")
    env = {"PATH": "/usr/bin:/bin:/usr/local/bin", "SECRETS_PREFIX": str(out), "FORCE": "1"}
    subprocess.run(
        ["bash", str(GEN_SECRETS), str(out)], check=True, env=env, capture_output=True, timeout=60
    )
    return out


def _users(secrets: Path) -> dict[str, str]:
    lines = (secrets / "users.txt").read_text().splitlines()
    return dict(line.split(":", 1) for line in lines if line)


def _client_config(
    secrets: Path, port: int, role: str | None = "teacher", **change
) -> zenoh.Config:
    """The generated ``<role>.json5`` (or a bare config), pointed at the router, then changed."""
    if role is None:
        config = zenoh.Config()
        config.insert_json5(
            "transport/link/tls/root_ca_certificate", json.dumps(str(secrets / "ca.pem"))
        )
    else:
        config = zenoh.Config.from_file(str(secrets / f"{role}.json5"))
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([f"tls/localhost:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    for key, value in change.items():
        config.insert_json5(key.replace("__", "/"), json.dumps(value))
    return config


def _refused(config: zenoh.Config) -> bool:
    try:
        session = zenoh.open(config)
    except zenoh.ZError:
        return True
    session.close()
    return False


@pytest.fixture(scope="module")
def router(secrets):
    standin = _load_standin()
    port = free_port()
    session = standin.open_router(ROUTER_CONFIG, secrets, [f"tls/127.0.0.1:{port}"])
    yield port
    session.close()


@pytest.fixture(scope="module")
def sessions(secrets, router):
    opened = {role: zenoh.open(_client_config(secrets, router, role)) for role in ROLES}
    yield opened
    for session in opened.values():
        session.close()


class Inbox:
    """Collects (subscriber, key, payload) from callback subscribers; bounded waits."""

    def __init__(self):
        self.items: list[tuple[str, str, bytes]] = []
        self.cond = threading.Condition()

    def handler(self, who: str):
        def on_sample(sample):
            with self.cond:
                self.items.append((who, str(sample.key_expr), sample.payload.to_bytes()))
                self.cond.notify_all()

        return on_sample

    def wait_for(self, item, timeout: float = 3.0) -> bool:
        """Whether ``item`` arrived within ``timeout`` s (times ``$RHBL_TEST_PATIENCE``)."""
        with self.cond:
            return self.cond.wait_for(lambda: item in self.items, patience(timeout))


def _subscribe(sessions, inbox, who, key):
    return sessions[who].declare_subscriber(key, inbox.handler(who))


def _flush_key(who: str) -> str:
    """A key only ``who``'s flush subscriber listens to, on which its flusher may publish: the
    server's sensor data for every other role, the teacher's commands for the server."""
    if who == "server":
        return keys.cmd_vel_key("flush", source="teacher")
    return keys.driver_key(f"flush-{who}")


def _flusher(who: str) -> str:
    return "teacher" if who == "server" else "server"


@pytest.fixture(scope="module")
def flush(sessions):
    """Per role, the payloads its flush subscriber got; the server answers the barrier."""
    inbox = Inbox()
    subs = [_subscribe(sessions, inbox, who, _flush_key(who)) for who in ROLES]
    barrier = sessions["server"].declare_queryable(BARRIER, lambda q: q.reply(q.key_expr,
                                                                               b"barrier"))
    for who in ROLES:  # every flush path is up, and the barrier known to the router
        _flush(sessions, inbox, who)
    yield inbox
    barrier.undeclare()
    for sub in subs:
        sub.undeclare()


_FLUSHES = iter(range(1, 1 << 30))


def _flush(sessions, flush, who: str, timeout: float = 10.0) -> None:
    """A flush message from ``who``'s flusher reaches ``who``: behind it on that path, whatever
    the router had queued for ``who`` before. Sent again every 0.1 s until it arrives (the
    first ones may go out before the router knows the flush subscription)."""
    payload = f"flush-{next(_FLUSHES)}".encode()

    def arrived() -> bool:
        if flush.wait_for((who, _flush_key(who), payload), timeout=0.1):
            return True
        sessions[_flusher(who)].put(_flush_key(who), payload)
        return False

    eventually(arrived, timeout, f"a flush reaching {who}", every=0.001)


def _passed(sessions, flush, senders=(), receivers=(), timeout: float = 10.0) -> None:
    """Everything the ``senders`` sent or declared so far has been handled by the router, and
    what it let through has reached the ``receivers``. The router handles what a session sends
    in order, so a sender's query of the server, once answered, comes after everything that
    sender sent before (the server itself: its flush to the teacher); then a flush from each
    receiver's flusher, sent after that, reaches the receiver behind whatever the router had
    queued for it. (A session that just subscribed is a sender of its declaration.)"""
    for who in senders:
        if who == "server":
            _flush(sessions, flush, "teacher")
        else:
            assert [r.ok for r in sessions[who].get(BARRIER, timeout=timeout) if r.ok], who
    for who in receivers:
        _flush(sessions, flush, who)


# ---- authentication ------------------------------------------------------------------------


def test_authorised_client_is_accepted(secrets, router):
    with zenoh.open(_client_config(secrets, router, "teacher")) as session:
        assert str(session.zid())


def test_client_without_the_ca_is_refused(secrets, router):
    config = _client_config(secrets, router, "teacher")
    config.insert_json5("transport/link/tls/root_ca_certificate", "null")
    assert _refused(config)


def test_client_trusting_another_ca_is_refused(secrets, router, tmp_path):
    other = tmp_path / "other"
    env = {"PATH": "/usr/bin:/bin:/usr/local/bin", "SECRETS_PREFIX": str(other)}
    subprocess.run(
        ["bash", str(GEN_SECRETS), str(other)], check=True, env=env, capture_output=True, timeout=60
    )
    # a router certificate made by a different CA (e.g. an impostor) is not trusted either
    assert _refused(_client_config(other, router, "teacher"))


def test_wrong_password_is_refused(secrets, router):
    config = _client_config(secrets, router, "teacher", transport__auth__usrpwd__password="not-it")
    assert _refused(config)


def test_unknown_user_is_refused(secrets, router):
    password = _users(secrets)["teacher"]
    config = _client_config(
        secrets,
        router,
        None,
        transport__auth__usrpwd__user="admin",
        transport__auth__usrpwd__password=password,
    )
    assert _refused(config)


def test_anonymous_client_is_refused(secrets, router):
    assert _refused(_client_config(secrets, router, None))


def test_plain_tcp_is_refused(secrets, router):
    config = _client_config(secrets, router, "teacher")
    config.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{router}"]))
    assert _refused(config)


def test_mutual_tls_requires_a_client_certificate(secrets):
    standin = _load_standin()
    port = free_port()
    mtls = ["transport/link/tls/enable_mtls:true"]
    with standin.open_router(ROUTER_CONFIG, secrets, [f"tls/127.0.0.1:{port}"], mtls):
        with zenoh.open(_client_config(secrets, port, "learner")) as session:
            assert str(session.zid())
        no_cert = _client_config(secrets, port, "learner")
        no_cert.insert_json5("transport/link/tls/enable_mtls", "false")
        assert _refused(no_cert)


# ---- access control --------------------------------------------------------------------------


def test_learner_cannot_publish_commands_teacher_and_controller_can(sessions, flush):
    inbox = Inbox()
    sub = _subscribe(sessions, inbox, "server", keys.cmd_vel_subscription(ROBOT))
    _passed(sessions, flush, ["server"])  # the subscription is in place
    teacher_key = keys.cmd_vel_key(ROBOT, source="teacher")
    controller_key = keys.cmd_vel_key(ROBOT, source="controller")
    plain_key = keys.cmd_vel_key(ROBOT)
    denied = [
        ("learner", teacher_key),
        ("learner", controller_key),
        ("learner", plain_key),
        ("teacher", controller_key),  # a teacher cannot pose as the controller
        ("controller", teacher_key),  # nor the controller as the teacher
        ("teacher", plain_key),  # the key without a source is closed on the secured router
        ("controller", plain_key),
    ]
    for who, key in denied:
        sessions[who].put(key, f"denied:{who}".encode())
    sessions["teacher"].put(teacher_key, b"teacher")
    sessions["controller"].put(controller_key, b"controller")
    try:
        assert inbox.wait_for(("server", teacher_key, b"teacher"))
        assert inbox.wait_for(("server", controller_key, b"controller"))
        _passed(sessions, flush, {who for who, _ in denied}, ["server"])
        leaked = [item for item in inbox.items if item[2].startswith(b"denied:")]
        assert leaked == []
    finally:
        sub.undeclare()


def test_sensor_data_flows_to_authorised_readers_only_from_the_server(sessions, flush):
    inbox = Inbox()
    readers = ("teacher", "learner", "controller", "ros2")
    subs = [_subscribe(sessions, inbox, who, f"rhbl/{ROBOT}/*/*/data/**") for who in readers]
    _passed(sessions, flush, readers)
    for who in readers:  # forged sensor data
        sessions[who].put(keys.scan_key(ROBOT), f"forged:{who}".encode())
    sessions["server"].put(keys.scan_key(ROBOT), b"scan")
    sessions["server"].put(keys.state_key(ROBOT), b"state")
    sessions["server"].put(keys.driver_key(ROBOT), b"driver")
    try:
        for who in readers:
            for key, payload in [
                (keys.scan_key(ROBOT), b"scan"),
                (keys.state_key(ROBOT), b"state"),
                (keys.driver_key(ROBOT), b"driver"),
            ]:
                assert inbox.wait_for((who, key, payload)), (who, key)
        _passed(sessions, flush, readers, readers)
        # a forger's own subscriber sees its own put locally; nobody else may
        leaked = [
            (who, p)
            for who, _, p in inbox.items
            if p.startswith(b"forged:") and p != f"forged:{who}".encode()
        ]
        assert leaked == []
    finally:
        for sub in subs:
            sub.undeclare()


@pytest.mark.parametrize("key_of", [keys.teacher_action_key, keys.teacher_withdraw_key],
                         ids=["label", "withdrawal"])
def test_only_the_teacher_labels_demonstrations(sessions, flush, key_of):
    """A label, and a withdrawal of labels (the console's undo): the teacher's alone."""
    key = key_of(ROBOT)
    inbox = Inbox()
    sub = _subscribe(sessions, inbox, "learner", key)
    _passed(sessions, flush, ["learner"])
    for who in ("controller", "server"):
        sessions[who].put(key, f"forged:{who}".encode())
    sessions["teacher"].put(key, b"label")
    try:
        assert inbox.wait_for(("learner", key, b"label"))
        _passed(sessions, flush, ["controller", "server"], ["learner"])
        assert [p for _, _, p in inbox.items if p.startswith(b"forged:")] == []
    finally:
        sub.undeclare()


def _ask(session, key) -> list[bytes]:
    return [reply.ok.payload.to_bytes() for reply in session.get(key, timeout=1.5) if reply.ok]


def test_requests_are_answered_by_the_server_mutating_ones_not_for_the_learner(sessions, flush):
    geom, odom = (
        keys.request_key(ROBOT, "laser", "get_geom"),
        keys.request_key(ROBOT, "position2d", "set_odom"),
    )
    queryables = [
        sessions["server"].declare_queryable(key, lambda q: q.reply(q.key_expr, b"ack"))
        for key in (geom, odom)
    ]
    forged = sessions["teacher"].declare_queryable(
        keys.request_key(ROBOT, "laser", "get_config"), lambda q: q.reply(q.key_expr, b"forged")
    )
    _passed(sessions, flush, ["server", "teacher"])  # both declarations handled
    try:
        for who in ("teacher", "learner", "controller", "ros2"):  # read-only: get_*
            assert _ask(sessions[who], geom) == [b"ack"], who
        assert _ask(sessions["teacher"], odom) == [b"ack"]
        assert _ask(sessions["learner"], odom) == []
        assert _ask(sessions["ros2"], odom) == []
        # only the server answers device requests
        assert _ask(sessions["controller"], keys.request_key(ROBOT, "laser", "get_config")) == []
    finally:
        forged.undeclare()
        for q in queryables:
            q.undeclare()


def test_only_teacher_may_teleport_every_role_may_read_the_true_pose(sessions, flush):
    set_pose, get_pose = keys.sim_request_key(ROBOT, "set_pose"), keys.sim_request_key(ROBOT, "get_pose")
    queryables = [
        sessions["server"].declare_queryable(key, lambda q: q.reply(q.key_expr, b"ack"))
        for key in (set_pose, get_pose)
    ]
    _passed(sessions, flush, ["server"])
    try:
        assert _ask(sessions["teacher"], set_pose) == [b"ack"]
        assert _ask(sessions["learner"], set_pose) == []
        assert _ask(sessions["controller"], set_pose) == []
        for who in ("teacher", "learner", "controller"):
            assert _ask(sessions[who], get_pose) == [b"ack"], who
    finally:
        for q in queryables:
            q.undeclare()


def test_learner_snapshot_and_notices_reach_the_controller(sessions, flush):
    inbox = Inbox()
    sub = _subscribe(sessions, inbox, "controller", keys.learner_notice_key(ROBOT))
    snap = sessions["learner"].declare_queryable(
        keys.learner_snapshot_key(ROBOT), lambda q: q.reply(q.key_expr, b"tree")
    )
    _passed(sessions, flush, ["controller", "learner"])
    sessions["teacher"].put(keys.learner_notice_key(ROBOT), b"forged:teacher")
    sessions["learner"].put(keys.learner_notice_key(ROBOT), b"notice")
    try:
        assert inbox.wait_for(("controller", keys.learner_notice_key(ROBOT), b"notice"))
        assert _ask(sessions["controller"], keys.learner_snapshot_key(ROBOT)) == [b"tree"]
        _passed(sessions, flush, ["teacher"], ["controller"])
        assert [p for _, _, p in inbox.items if p.startswith(b"forged:")] == []
    finally:
        snap.undeclare()
        sub.undeclare()


def test_console_reads_notices_and_decisions_with_the_teachers_credentials(sessions, flush):
    """``rhbl console`` runs with the teacher's credentials: it receives the learner's notices
    and the controller's decisions, and only the controller may publish decisions."""
    inbox = Inbox()
    decision, notice = keys.controller_decision_key(ROBOT), keys.learner_notice_key(ROBOT)
    subs = [_subscribe(sessions, inbox, "teacher", decision),
            _subscribe(sessions, inbox, "teacher", notice)]
    _passed(sessions, flush, ["teacher"])
    for who in ("learner", "server"):  # (a session's own puts reach its own subscribers)
        sessions[who].put(decision, f"forged:{who}".encode())
    sessions["controller"].put(decision, b"decision")
    sessions["learner"].put(notice, b"notice")
    try:
        assert inbox.wait_for(("teacher", decision, b"decision"))
        assert inbox.wait_for(("teacher", notice, b"notice"))
        _passed(sessions, flush, ["learner", "server"], ["teacher"])
        assert [p for _, _, p in inbox.items if p.startswith(b"forged:")] == []
    finally:
        for sub in subs:
            sub.undeclare()


def test_liveliness_is_shared_between_authorised_roles(sessions):
    token = sessions["teacher"].liveliness().declare_token(keys.alive_key("teacher", "t1"))
    try:
        eventually(lambda: _alive_tokens(sessions["server"]), 10,
                   "the teacher's token seen by the server",
                   until=lambda seen: keys.alive_key("teacher", "t1") in seen)
    finally:
        token.undeclare()


def _alive_tokens(session, timeout: float = 1.0) -> set[str]:
    return {
        str(r.ok.key_expr)
        for r in session.liveliness().get("rhbl/alive/**", timeout=timeout)
        if r.ok is not None
    }


def test_each_role_declares_liveliness_tokens_only_under_its_own_key(secrets, router, sessions):
    """A token under another role's key is dropped at the router: a controller cannot fake a
    learner (the teacher would demonstrate to nobody) nor declare-and-drop a teacher token (the
    server would release the teacher's hold on the robot). Each role's own token is seen."""
    roles = (*ROLES, "operator")
    declarers = dict(sessions, operator=zenoh.open(_client_config(secrets, router, "operator")))
    # an observer of its own (a session's local tokens are visible to itself without the router)
    observer = zenoh.open(_client_config(secrets, router, "server"))
    events: list[tuple[str, str]] = []
    lock = threading.Lock()

    def on_change(sample):
        with lock:
            events.append((str(sample.kind), str(sample.key_expr)))

    watch = observer.liveliness().declare_subscriber("rhbl/alive/**", on_change, history=True)
    own = {role: keys.alive_key(role, f"acl-{role}") for role in roles}
    forged = {
        (who, keys.alive_key(role, f"forged-by-{who}"))
        for who in roles
        for role in roles
        if role != who
    }
    forged.add(("controller", keys.alive_key("learner", f"{ROBOT}-1")))  # a learner of r0
    tokens = []

    def declared_after(tag: str) -> set[str]:
        """Each declarer declares a token of its own now, and the observer sees them all: the
        router handles a session's declarations in order, so it has handled every token each
        declarer declared or dropped before (the forged ones included)."""
        mine = {role: keys.alive_key(role, f"acl-{role}-{tag}") for role in roles}
        for role in roles:
            tokens.append(declarers[role].liveliness().declare_token(mine[role]))
        return eventually(lambda: _alive_tokens(observer), 10,
                          f"every role's own token {sorted(mine.values())} seen",
                          until=lambda seen: set(mine.values()) <= seen)

    try:
        for who, key in sorted(forged):
            tokens.append(declarers[who].liveliness().declare_token(key))
        for role in roles:
            tokens.append(declarers[role].liveliness().declare_token(own[role]))
        seen = declared_after("first")
        assert set(own.values()) <= seen, sorted(seen)
        assert [key for _, key in forged if key in seen] == []
        # ... and dropping them releases nothing: no appearance, no disappearance
        for token in tokens[: len(forged)]:
            token.undeclare()
        declared_after("then")
        with lock:
            leaked = [(kind, key) for kind, key in events if "forged" in key or key.endswith("-1")]
            subscribed = {key for _, key in events}
        assert leaked == []
        assert set(own.values()) <= subscribed
    finally:
        for token in tokens[len(forged) :]:
            token.undeclare()
        watch.undeclare()
        observer.close()
        declarers["operator"].close()


# ---- ROS 2 over rmw_zenoh: the bridge's credentials (rhbl ros2) -----------------------------


def test_the_bridge_commands_on_its_own_key_only(sessions, flush):
    """The ``ros2`` credentials publish commands on ``.../cmd/vel/ros2`` (priority 0 in the
    server's arbitration) and nowhere else; nobody else may pose as the bridge."""
    inbox = Inbox()
    sub = _subscribe(sessions, inbox, "server", keys.cmd_vel_subscription(ROBOT))
    _passed(sessions, flush, ["server"])
    ros2_key = keys.cmd_vel_key(ROBOT, source="ros2")
    denied = [
        ("ros2", keys.cmd_vel_key(ROBOT, source="teacher")),
        ("ros2", keys.cmd_vel_key(ROBOT, source="controller")),
        ("ros2", keys.cmd_vel_key(ROBOT)),
        ("teacher", ros2_key),
        ("controller", ros2_key),
        ("learner", ros2_key),
    ]
    for who, key in denied:
        sessions[who].put(key, f"denied:{who}".encode())
    sessions["ros2"].put(ros2_key, b"ros2")
    try:
        assert inbox.wait_for(("server", ros2_key, b"ros2"))
        _passed(sessions, flush, {who for who, _ in denied}, ["server"])
        assert [item for item in inbox.items if item[2].startswith(b"denied:")] == []
    finally:
        sub.undeclare()


def _ros2_topics():
    from protocol.ros2.graph import RobotTopics

    return RobotTopics.of(ROBOT)


def test_ros2_samples_flow_between_the_bridge_and_the_controller_only(sessions, flush):
    """Domain 0's keys (``0/<topic>/<type>/<hash>``): the bridge's LaserScan reaches the
    controller (``rhbl controller --ros2``), the controller's Twist reaches the bridge; the
    learner and the teacher can neither publish there nor read."""
    topics = _ros2_topics()
    scan, cmd_vel = topics.scan.key(0), topics.cmd_vel.key(0)
    inbox = Inbox()
    readers = {"controller": scan, "ros2": cmd_vel, "learner": "0/**", "teacher": "0/**"}
    subs = [_subscribe(sessions, inbox, who, key) for who, key in readers.items()]
    _passed(sessions, flush, list(readers))
    for who in ("learner", "teacher"):
        sessions[who].put(scan, f"forged:{who}".encode())
        sessions[who].put(cmd_vel, f"forged:{who}".encode())
    sessions["ros2"].put(scan, b"laserscan")
    sessions["controller"].put(cmd_vel, b"twist")
    try:
        assert inbox.wait_for(("controller", scan, b"laserscan"))
        assert inbox.wait_for(("ros2", cmd_vel, b"twist"))
        _passed(sessions, flush, ["learner", "teacher", "ros2", "controller"], list(readers))
        leaked = [
            (who, p)
            for who, _, p in inbox.items
            if (who in ("learner", "teacher") and p in (b"laserscan", b"twist"))
            or (p.startswith(b"forged:") and p != f"forged:{who}".encode())
        ]
        assert leaked == []
    finally:
        for sub in subs:
            sub.undeclare()


def test_ros2_graph_tokens_are_declared_by_the_bridge_and_the_controller_only(sessions):
    """rmw_zenoh's liveliness tokens (``@ros2_lv/0/...``): the bridge's node and publisher are
    seen by the controller and the controller's by the bridge; a learner's are dropped."""
    from client.ros2.nodes import Ros2Graph

    topics = _ros2_topics()
    graphs = {who: Ros2Graph(sessions[who], 0) for who in ("ros2", "controller", "learner")}
    marker = None

    def announce(who, name, topic):
        node = graphs[who].node(name, f"/{ROBOT}")
        return {node.token.key(), node.publisher(topic).token.key()}

    try:
        learner_keys = announce("learner", "forged", topics.scan)
        # the learner's own token after its forged ones: once seen, those were handled
        learner_alive = keys.alive_key("learner", "ros2-graph")
        marker = sessions["learner"].liveliness().declare_token(learner_alive)
        bridge_keys = announce("ros2", "rhbl_bridge", topics.scan)
        driver_keys = announce("controller", "rhbl_controller", topics.cmd_vel)
        def graph_seen() -> dict[str, set[str]]:
            return {
                who: {
                    str(r.ok.key_expr)
                    for r in sessions[who].liveliness().get("@ros2_lv/0/**", timeout=1.0)
                    if r.ok is not None
                }
                for who in ("ros2", "controller")
            }

        seen = eventually(graph_seen, 10, "the driver's and the bridge's graph tokens and the "
                          "learner's own token seen across",
                          until=lambda seen: driver_keys <= seen["ros2"]
                          and bridge_keys <= seen["controller"]
                          and learner_alive in _alive_tokens(sessions["controller"]))
        assert driver_keys <= seen["ros2"], sorted(seen["ros2"])
        assert bridge_keys <= seen["controller"], sorted(seen["controller"])
        assert learner_alive in _alive_tokens(sessions["controller"])
        assert not learner_keys & (seen["ros2"] | seen["controller"])
    finally:
        for graph in graphs.values():
            graph.close()
        if marker is not None:
            marker.undeclare()


# ---- the remote teacher's messages -----------------------------------------------------------


def _teacher(secrets: Path, port: int, config: Path | None = None, timeout: float = 60):
    argv = [
        sys.executable, "-m", "lab.cli", "teacher",
        "--connect", f"tls/localhost:{port}",
        "--zenoh-config", str(config or secrets / "teacher.json5"),
        "--wait-server", "1", "--seconds", "1",
    ]  # fmt: skip
    env = dict(os.environ, RUST_LOG="off")
    return subprocess.run(argv, capture_output=True, text=True, timeout=timeout, env=env)


def test_remote_teacher_says_when_the_router_is_unreachable(secrets):
    run = _teacher(secrets, free_port())
    assert run.returncode == 3, run.stderr
    assert "connection refused" in run.stderr and "router" in run.stderr


def test_remote_teacher_says_when_credentials_are_refused(secrets, router, tmp_path):
    text = (secrets / "teacher.json5").read_text()
    password = _users(secrets)["teacher"]
    bad = tmp_path / "teacher.json5"
    bad.write_text(text.replace(password, "not-the-password"))
    run = _teacher(secrets, router, bad)
    assert run.returncode == 3, run.stderr
    assert "refused the zenoh session" in run.stderr and "credentials" in run.stderr


def test_remote_teacher_says_when_the_server_is_not_up(secrets, router):
    run = _teacher(secrets, router)
    assert run.returncode == 4, run.stderr
    assert "server is not up" in run.stderr


def test_console_runs_with_the_teachers_credentials(secrets, router, sessions):
    """``rhbl console`` behind the secured router with the teacher's credentials: the session is
    accepted and its liveliness token (rhbl/alive/console/...) is let through."""
    from browser import ConsoleProcess

    console = ConsoleProcess(f"tls/localhost:{router}", "--zenoh-config",
                             str(secrets / "teacher.json5"))
    try:
        console.wait_url()
        key = keys.alive_key("console", f"{ROBOT}-{console.pid}")
        eventually(lambda: _alive_tokens(sessions["server"]), 10,
                   f"the console's token {key} seen by the server",
                   until=lambda seen: key in seen, alive=[console])
    finally:
        assert console.stop() == 0, console.output()
