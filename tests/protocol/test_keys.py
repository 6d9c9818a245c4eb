"""Keys are built, parsed and made into wildcards in one place (protocol.keys)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol import keys


def test_every_robots_key_is_a_wildcard_given_on_purpose():
    assert keys.scan_key(keys.EVERY) == "rhbl/*/laser/0/data/scan"
    assert keys.cmd_vel_subscription(keys.EVERY) == "rhbl/*/position2d/0/cmd/vel/**"
    assert keys.controller_decision_key(keys.EVERY) == "rhbl/*/controller/decision"
    assert keys.learner_notice_key(keys.EVERY) == "rhbl/*/learner/notice"
    assert keys.robot_keys() == "rhbl/**" and keys.robot_keys("r2") == "rhbl/r2/**"
    assert keys.every_token() == "rhbl/alive/**"
    for bad in ("*", "**", "r/0", ""):  # a plain wildcard (a --robot '*') is refused
        with pytest.raises(ValueError, match="robot must be a non-empty key chunk"):
            keys.scan_key(bad)


@pytest.mark.parametrize("key,kind,extra", [
    (keys.state_key("r0"), "state", {"iface": "position2d", "index": 0}),
    (keys.scan_key("r0"), "scan", {"iface": "laser", "index": 0}),
    (keys.fiducial_key("r0"), "fiducial", {"iface": "fiducial", "index": 0}),
    (keys.request_key("r0", "fiducial", "get_geom"), "request", {"name": "get_geom"}),
    (keys.driver_key("r0"), "driver", {}),
    (keys.cmd_vel_key("r0"), "cmd", {"source": None}),
    (keys.cmd_vel_key("r0", source="teacher"), "cmd", {"source": "teacher"}),
    ("rhbl/r0/position2d/0/cmd/vel/a/b", "cmd", {"source": "a/b"}),
    (keys.request_key("r0", "laser", "get_config"), "request", {"name": "get_config"}),
    (keys.sim_request_key("r0", "set_pose"), "sim", {"name": "set_pose"}),
    (keys.teacher_action_key("r0"), "label", {}),
    (keys.teacher_labeled_key("r0"), "labeled", {}),
    (keys.learner_ack_key("r0"), "ack", {}),
    (keys.learner_notice_key("r0"), "notice", {}),
    (keys.learner_snapshot_key("r0"), "snapshot", {}),
    (keys.controller_decision_key("r0"), "decision", {}),
    (keys.alive_key("learner", "r0-77"), "alive", {"role": "learner", "ident": "r0-77"}),
    ("rhbl/alive/server/host-1/r0", "alive", {"role": "server", "ident": "host-1", "name": "r0"}),
])
def test_parse_says_what_each_key_of_ours_names(key, kind, extra):
    k = keys.parse(key)
    assert k.kind == kind and k.robot == "r0"
    assert {f: getattr(k, f) for f in extra} == extra


@pytest.mark.parametrize("key", ["other/r0/x", "rhbl", "rhbl/r0", "rhbl/r0/x/y",
                                 "rhbl/r0/laser/x/data/scan", "rhbl/r0/laser/0/data/state",
                                 "rhbl/r0/position2d/0/cmd", "rhbl/r0/teacher/action/x"])
def test_parse_calls_anything_else_other(key):
    assert keys.parse(key).kind == "other"


def test_a_token_names_its_robot_by_the_prefix_of_its_ident():
    hold = keys.parse(keys.alive_key("teacher", "my-bot-12-hold"))
    assert hold.names_robot("my-bot") and hold.names_robot("my") and not hold.names_robot("my-b")
    assert keys.parse("rhbl/alive/server/host-1/r3").names_robot("r3")
    assert not keys.parse("rhbl/alive/server/host-1/r3").names_robot("host")
    assert keys.parse(keys.scan_key("r1")).names_robot("r1")
    assert keys.source_of_cmd_key(keys.cmd_vel_key("r1", source="controller")) == "controller"
    assert keys.source_of_cmd_key(keys.cmd_vel_key("r1")) is None


@given(st.text(max_size=80))
def test_parse_never_raises(text):
    assert keys.parse(text).kind in keys.KINDS
