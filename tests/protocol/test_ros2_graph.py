"""protocol.ros2 names, QoS, topic keys and liveliness tokens, against rmw_zenoh's own examples."""

from __future__ import annotations

import queue

import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from process.session import make_config
from protocol import DecodeError
from protocol.ros2 import cdr
from protocol.ros2.attachment import Attachment
from protocol.ros2.graph import (
    EntityKind,
    LivelinessToken,
    Node,
    RobotTopics,
    Topic,
    liveliness_space,
)
from protocol.ros2.names import dds_type_name, fully_qualified, ros_type_name
from protocol.ros2.qos import (
    DEFAULT_QOS,
    RMW_ZENOH_DEFAULT,
    SENSOR_DATA_QOS,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
    adapt,
    qos_from_keyexpr,
    qos_to_keyexpr,
)

# Data: the examples of rmw_zenoh's docs/design.md (the demo_nodes_cpp talker, listener and
# add_two_ints nodes, rmw_zenoh 0.2.x+), copied verbatim.
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
DESIGN_KEYS = [
    ("0/chatter/std_msgs::msg::dds_::String_/" + STRING_HASH, 0, "/chatter", "std_msgs/msg/String",
     STRING_HASH),
    ("0/robot1/chatter/std_msgs::msg::dds_::String_/" + STRING_HASH, 0, "/robot1/chatter",
     "std_msgs/msg/String", STRING_HASH),
    ("2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/" + ADD_TWO_INTS_HASH, 2,
     "/add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_TWO_INTS_HASH),
]
DESIGN_TOKENS = [
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener",
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
    "std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,10:,:,:,,",
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    "std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,7:,:,:,,",
    "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
    "example_interfaces::srv::dds_::AddTwoInts_/" + ADD_TWO_INTS_HASH + "/::,10:,:,:,,",
    "@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
    "example_interfaces::srv::dds_::AddTwoInts_/" + ADD_TWO_INTS_HASH + "/::,10:,:,:,,",
]
ZID = "8b20917502ee955ac4476e0266340d5c"


@pytest.mark.parametrize(("key", "domain", "name", "typename", "type_hash"), DESIGN_KEYS)
def test_topic_keys_are_rmw_zenohs(key, domain, name, typename, type_hash):
    assert Topic(name, typename, DEFAULT_QOS, type_hash).key(domain) == key


def test_the_type_hash_rmw_zenoh_shows_is_the_one_rosbags_computes():
    assert cdr.type_hash("std_msgs/msg/String") == STRING_HASH
    assert Topic("/chatter", "std_msgs/msg/String", DEFAULT_QOS).key() == DESIGN_KEYS[0][0]


def test_our_topics_keys():
    scan = Topic("/r0/scan", cdr.LASER_SCAN, SENSOR_DATA_QOS)
    assert scan.key(0) == ("0/r0/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c191398013af"
                           "96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828")
    assert Topic("/tf", cdr.TF_MESSAGE, DEFAULT_QOS).key(7).startswith(
        "7/tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369d0f0")
    zenoh.KeyExpr(scan.key(0))  # a valid zenoh key (raises otherwise)


def test_a_robots_topics():
    t = RobotTopics.of("r0")
    assert [x.name for x in (t.scan, t.odom, t.cmd_vel, t.tf, t.clock)] == [
        "/r0/scan", "/r0/odom", "/r0/cmd_vel", "/tf", "/clock"]
    assert [qos_to_keyexpr(x.qos) for x in (t.scan, t.odom, t.cmd_vel, t.tf, t.clock)] == [
        "2::,5:,:,:,,", "::,10:,:,:,,", "::,10:,:,:,,", "::,100:,:,:,,", "2::,1:,:,:,,"]
    assert t.cmd_vel.key(0).startswith("0/r0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_")
    assert RobotTopics.of("r1", "/fleet").scan.name == "/fleet/r1/scan"
    with pytest.raises(ValueError, match="ROS 2 topic name"):
        RobotTopics.of("robot-1")  # a valid rhbl robot name, not a ROS 2 one
    assert t.published == (t.scan, t.odom, t.tf, t.clock)
    assert (t.cmd_vel_stamped.name, t.cmd_vel_stamped.typename) == ("/r0/cmd_vel",
                                                                    cdr.TWIST_STAMPED)


def test_a_robots_topic_names_are_options():
    t = RobotTopics.of("r0", "/fleet", scan="base_scan", odom="/odom", cmd_vel="nav/cmd_vel",
                       tf="tf", clock="/sim/clock")
    assert [x.name for x in (t.scan, t.odom, t.cmd_vel, t.tf, t.clock)] == [
        "/fleet/r0/base_scan", "/odom", "/fleet/r0/nav/cmd_vel", "/fleet/r0/tf", "/sim/clock"]
    for bad in ("scan-1", "", "/a//b", "~/scan", "{robot}/scan"):
        with pytest.raises(ValueError, match="ROS 2 topic name"):
            RobotTopics.of("r0", scan=bad)


@pytest.mark.parametrize("key", DESIGN_TOKENS)
def test_rmw_zenohs_tokens_parse_and_print_back(key):
    token = LivelinessToken.parse(key)
    assert token.key() == key
    assert token.node.domain == 2 and token.node.namespace == "/" and token.node.enclave == "/"


def test_parsed_token_fields():
    sub = LivelinessToken.parse(DESIGN_TOKENS[1])
    assert sub.kind is EntityKind.SUBSCRIPTION
    assert (sub.zid, sub.node_id, sub.entity_id, sub.node.name) == (
        "aac3178e146ba6f1fc6e6a4085e77f21", 0, 10, "listener")
    assert sub.topic.name == "/chatter" and sub.topic.typename == "std_msgs/msg/String"
    assert sub.topic.qos == adapt(DEFAULT_QOS)
    pub = LivelinessToken.parse(DESIGN_TOKENS[2])
    assert pub.kind is EntityKind.PUBLISHER and pub.topic.qos.depth == 7
    assert pub.topic.qos.reliability is QosReliability.RELIABLE
    node = LivelinessToken.parse(DESIGN_TOKENS[0])
    assert node.kind is EntityKind.NODE and node.topic is None


def test_our_tokens():
    node = Node("rhbl_bridge", namespace="/r0")
    scan = Topic("/r0/scan", cdr.LASER_SCAN, SENSOR_DATA_QOS)
    cmd = Topic("/r0/cmd_vel", cdr.TWIST, DEFAULT_QOS)
    nn = LivelinessToken.for_node(ZID, 0, node)
    assert nn.key() == f"@ros2_lv/0/{ZID}/0/0/NN/%/%r0/rhbl_bridge"
    mp = LivelinessToken.for_topic(ZID, 0, 1, EntityKind.PUBLISHER, node, scan)
    assert mp.key() == (f"@ros2_lv/0/{ZID}/0/1/MP/%/%r0/rhbl_bridge/%r0%scan/"
                        f"sensor_msgs::msg::dds_::LaserScan_/{scan.type_hash}/2::,5:,:,:,,")
    ms = LivelinessToken.for_topic(ZID, 0, 2, EntityKind.SUBSCRIPTION, node, cmd)
    assert ms.key().endswith("/MS/%/%r0/rhbl_bridge/%r0%cmd_vel/geometry_msgs::msg::dds_::Twist_/"
                             f"{cmd.type_hash}/::,10:,:,:,,")
    for t in (nn, mp, ms):
        zenoh.KeyExpr(t.key())
        assert LivelinessToken.parse(t.key()) == LivelinessToken(
            t.zid, t.node_id, t.entity_id, t.kind, t.node,
            None if t.topic is None else Topic(t.topic.name, t.topic.typename,
                                               adapt(t.topic.qos)))
    assert liveliness_space(0) == "@ros2_lv/0/**"


def test_gid_is_xxh3_128_of_the_token_key_low_half_first():
    """rmw_zenoh copies the hash's low 64 bits, then its high 64 bits, each as the host (little
    endian) stores them: the canonical big-endian digest reversed."""
    import xxhash

    gid = LivelinessToken.parse(DESIGN_TOKENS[2]).gid()
    assert gid == xxhash.xxh3_128(DESIGN_TOKENS[2].encode()).digest()[::-1]
    assert gid.hex() == "ac170f31eadcd9ff0cd86d7a17907d1c"  # pinned: the talker's publisher
    assert LivelinessToken.parse(DESIGN_TOKENS[1]).gid() != gid


@pytest.mark.parametrize(("bad", "match"), [
    ("ros2_lv/0/abc/0/0/NN/%/%/n", "does not start with '@ros2_lv'"),
    ("@ros2_lv/0/abc/0/0/NN/%/%", "expected 9"),
    ("@ros2_lv/0/abc/0/0/NN/%/%/n/x", "expected 9"),
    ("@ros2_lv/0/abc/0/0/NN//%/n", "non-empty"),
    ("@ros2_lv/x/abc/0/0/NN/%/%/n", "domain id 'x' is not a number"),
    ("@ros2_lv/0/abc/0/-1/NN/%/%/n", "entity id"),
    ("@ros2_lv/0/abc/0/0/XX/%/%/n", "unknown entity kind 'XX'"),
    ("@ros2_lv/0/ABC/0/0/NN/%/%/n", "zenoh session id"),
    ("@ros2_lv/0/abc/0/0/NN/%/%/9lives", "node name"),
    ("@ros2_lv/0/abc/0/0/NN/%/%bad-ns/n", "namespace"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n", "MP token has 13"),
    ("@ros2_lv/0/abc/0/0/NN/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,10:,:,:,,",
     "NN token has 9"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs.msg.String/" + STRING_HASH + "/::,10:,:,:,,",
     "DDS type name"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/TypeHashNotSupported/::,10:,:,:,,",
     "type hash"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,10:,:,,",
     "expected 6"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/9::,10:,:,:,,",
     "9 is not a QosReliability"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/::,x:,:,:,,",
     "depth"),
    ("@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/" + STRING_HASH + "/::10:,:,:,,",
     "history,depth"),
])
def test_malformed_tokens_are_a_decode_error_naming_what(bad, match):
    with pytest.raises(DecodeError, match=match):
        LivelinessToken.parse(bad)


def test_names():
    assert fully_qualified("scan", "/r0") == "/r0/scan"
    assert fully_qualified("scan") == "/scan"
    assert fully_qualified("/tf", "/r0") == "/tf"
    assert fully_qualified("a/b", "/x/y") == "/x/y/a/b"
    assert dds_type_name("nav_msgs/msg/Odometry") == "nav_msgs::msg::dds_::Odometry_"
    assert ros_type_name("nav_msgs::msg::dds_::Odometry_") == "nav_msgs/msg/Odometry"
    for bad in ["r-1/scan", "~/scan", "{node}/scan", "", "scan/", "1scan", "a//b"]:
        with pytest.raises(ValueError, match="ROS 2 topic name"):
            fully_qualified(bad, "/")
    with pytest.raises(ValueError, match="namespace"):
        fully_qualified("scan", "r0")
    with pytest.raises(ValueError, match="node name"):
        Node("r-0")
    with pytest.raises(ValueError, match="domain id"):
        Node("n", domain=-1)
    with pytest.raises(ValueError, match="package/msg/Name"):
        dds_type_name("LaserScan")


def test_qos_chunks_as_rmw_zenoh_writes_them():
    assert qos_to_keyexpr(DEFAULT_QOS) == "::,10:,:,:,,"
    assert qos_to_keyexpr(SENSOR_DATA_QOS) == "2::,5:,:,:,,"
    assert qos_to_keyexpr(DEFAULT_QOS._replace(depth=100)) == "::,100:,:,:,,"  # tf2's /tf
    latched = DEFAULT_QOS._replace(depth=1, durability=QosDurability.TRANSIENT_LOCAL)
    assert qos_to_keyexpr(latched) == ":1:,1:,:,:,,"
    assert qos_to_keyexpr(RMW_ZENOH_DEFAULT) == "::,:,:,:,,"
    assert qos_to_keyexpr(DEFAULT_QOS._replace(depth=0)) == "::,:,:,:,,"  # depth 0 -> 42
    odd = DEFAULT_QOS._replace(history=QosHistory.KEEP_ALL, deadline=QosTime(1, 500),
                               liveliness=QosLiveliness.MANUAL_BY_TOPIC,
                               liveliness_lease_duration=QosTime(2, 0))
    assert qos_to_keyexpr(odd) == "::2,10:1,500:,:3,2,0"
    assert qos_from_keyexpr("::2,10:1,500:,:3,2,0") == adapt(odd)
    with pytest.raises(ValueError, match="not supported"):
        qos_to_keyexpr(DEFAULT_QOS._replace(reliability=QosReliability.UNKNOWN))


_policies = st.fixed_dictionaries({
    "history": st.sampled_from([QosHistory.SYSTEM_DEFAULT, QosHistory.KEEP_LAST,
                                QosHistory.KEEP_ALL]),
    "depth": st.integers(0, 10_000),
    "reliability": st.sampled_from([QosReliability.SYSTEM_DEFAULT, QosReliability.RELIABLE,
                                    QosReliability.BEST_EFFORT]),
    "durability": st.sampled_from([QosDurability.SYSTEM_DEFAULT, QosDurability.TRANSIENT_LOCAL,
                                   QosDurability.VOLATILE]),
    "deadline": st.builds(QosTime, st.integers(0, 10**9), st.integers(0, 999_999_999)),
    "lifespan": st.builds(QosTime, st.integers(0, 10**9), st.integers(0, 999_999_999)),
    "liveliness": st.sampled_from([QosLiveliness.SYSTEM_DEFAULT, QosLiveliness.AUTOMATIC,
                                   QosLiveliness.MANUAL_BY_TOPIC]),
    "liveliness_lease_duration": st.builds(QosTime, st.integers(0, 10**9),
                                           st.integers(0, 999_999_999)),
})


@given(_policies)
def test_qos_chunk_roundtrips_to_the_adapted_profile(fields):
    qos = Qos(**fields, avoid_ros_namespace_conventions=False)
    assert qos_from_keyexpr(qos_to_keyexpr(qos)) == adapt(qos)


@pytest.mark.integration
def test_tokens_and_a_sample_cross_a_real_zenoh_session(free_port):
    """What part of the bridge will do, by hand: our tokens seen by a raw liveliness
    subscriber on rmw_zenoh's space, a CDR sample with its attachment on the topic key."""

    ep = f"tcp/127.0.0.1:{free_port()}"
    node = Node("rhbl_bridge", namespace="/r0")
    cmd = Topic("/r0/cmd_vel", cdr.TWIST, DEFAULT_QOS)
    tokens = [LivelinessToken.for_node(ZID, 0, node),
              LivelinessToken.for_topic(ZID, 0, 1, EntityKind.SUBSCRIPTION, node, cmd)]
    seen: queue.Queue = queue.Queue()
    samples: queue.Queue = queue.Queue()
    with (
        zenoh.open(make_config(mode="router", listen=[ep])) as a,
        zenoh.open(make_config(connect=[ep])) as b,
    ):
        b.liveliness().declare_subscriber(liveliness_space(0), lambda s: seen.put(str(s.key_expr)),
                                          history=True)
        b.declare_subscriber(cmd.key(0), lambda s: samples.put(
            (s.payload.to_bytes(), s.attachment.to_bytes())))
        held = [a.liveliness().declare_token(t.key()) for t in tokens]
        got = {LivelinessToken.parse(seen.get(timeout=10)) for _ in tokens}
        assert got == {LivelinessToken.parse(t.key()) for t in tokens}
        att = Attachment(1, 1_700_000_000_000_000_000, tokens[1].gid())
        v = cdr.types()["geometry_msgs/msg/Vector3"]
        data = cdr.serialize(cdr.types()[cdr.TWIST](linear=v(x=0.2, y=0.0, z=0.0),
                                                    angular=v(x=0.0, y=0.0, z=-0.4)))
        for _ in range(100):  # until the subscription has reached the router (at most 10 s)
            a.put(cmd.key(0), data, attachment=att.encode())
            try:
                payload, attachment = samples.get(timeout=0.1)
                break
            except queue.Empty:
                pass
        else:
            pytest.fail("no sample on the topic key within 10 s")
        assert Attachment.decode(attachment) == att
        twist = cdr.deserialize(payload, cdr.TWIST)
        assert (twist.linear.x, twist.angular.z) == (0.2, -0.4)
        del held
