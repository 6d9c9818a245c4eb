"""process.session: zenoh configs, and the topology the server relies on."""

from __future__ import annotations

import argparse
import json

import pytest
import zenoh
from waiting import eventually

from process.session import (
    DEFAULT_ENDPOINT,
    add_zenoh_arguments,
    config_from_args,
    make_config,
)


def _get(conf, key):
    return json.loads(conf.get_json(key))


def test_make_config_is_hermetic():
    c = make_config(connect=["tcp/127.0.0.1:1234"])
    assert _get(c, "mode") == "client"
    assert _get(c, "connect/endpoints") == ["tcp/127.0.0.1:1234"]
    assert _get(c, "scouting/multicast/enabled") is False
    assert _get(c, "transport/link/tx/lease") == 2000
    r = make_config(mode="router", listen=["tcp/127.0.0.1:7447"], multicast=True, namespace="t1")
    assert _get(r, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert _get(r, "scouting/multicast/enabled") is True
    assert _get(r, "namespace") == "t1"
    with pytest.raises(ValueError, match="mode"):
        make_config(mode="satellite")
    with pytest.raises(ValueError, match="does not exist"):
        make_config(config_file="/nonexistent.json5")


def test_config_file_then_flags(tmp_path):
    f = tmp_path / "z.json5"
    f.write_text('{ mode: "peer", connect: { endpoints: ["tcp/127.0.0.1:9"] } }')
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p)
    c = config_from_args(p.parse_args(["--zenoh-config", str(f), "--mode", "peer"]))
    assert _get(c, "connect/endpoints") == ["tcp/127.0.0.1:9"]
    assert _get(c, "mode") == "peer"


def test_arguments_and_defaults():
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p)
    c = config_from_args(p.parse_args([]))
    assert _get(c, "mode") == "client"
    assert _get(c, "connect/endpoints") == [DEFAULT_ENDPOINT]
    c = config_from_args(p.parse_args(["-e", "tcp/127.0.0.1:1,tcp/127.0.0.1:2"]))
    assert _get(c, "connect/endpoints") == ["tcp/127.0.0.1:1", "tcp/127.0.0.1:2"]
    p = argparse.ArgumentParser()
    add_zenoh_arguments(p, default_listen=[DEFAULT_ENDPOINT], default_mode="router")
    c = config_from_args(p.parse_args([]))
    assert _get(c, "mode") == "router"
    assert _get(c, "listen/endpoints") == [DEFAULT_ENDPOINT]
    c = config_from_args(p.parse_args(["--listen", "tcp/127.0.0.1:5"]))
    assert _get(c, "listen/endpoints") == ["tcp/127.0.0.1:5"]


@pytest.mark.integration
def test_two_clients_talk_through_a_router(free_port):
    ep = f"tcp/127.0.0.1:{free_port()}"
    with (
        zenoh.open(make_config(mode="router", listen=[ep])),
        zenoh.open(make_config(connect=[ep])) as a,
        zenoh.open(make_config(connect=[ep])) as b,
    ):
        got = []
        b.declare_subscriber("t/x", lambda s: got.append(s.payload.to_bytes()))
        # put again until the router knows b's subscription
        eventually(lambda: a.put("t/x", b"hi") or got, 10, "b gets a's put")
        assert got[0] == b"hi"
