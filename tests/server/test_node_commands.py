"""A free-running node takes the commands zenoh queued for each robot at its tick: every one is
handled (counted, checked, arbitrated) in order, the latest drives, and the watchdog counts from
the sim time the command arrived at. Real zenoh sessions on loopback, the node ticked by hand."""

from __future__ import annotations

import pytest
import zenoh
from waiting import eventually

import server
from process.session import make_config
from protocol import keys
from protocol.messages import VelCmd
from server.node import ServerNode, keep_freed_memory
from server.world import World, load_world

pytestmark = pytest.mark.integration


@pytest.fixture
def node_and_client(free_port):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as srv:
        world = World(load_world(server.world_path("corridor")))
        node = ServerNode(srv, world, rate=10.0, watchdog=0.5)
        try:
            with zenoh.open(make_config(mode="client", connect=[endpoint])) as cli:
                yield node, cli
        finally:
            node.close()


def tick_until(node: ServerNode, done, timeout: float = 10.0) -> int:
    """Tick until ``done()`` (commands arrive in zenoh's queue in their own time)."""
    ticks = 0

    def ticked():
        nonlocal ticks
        if done():
            return True
        node.tick()
        ticks += 1
        return {"ticks": ticks, **node.counters}

    eventually(ticked, timeout, "the commands handled", until=lambda r: r is True,
               every=1e-4)
    return ticks


def test_queued_commands_are_all_handled_at_the_tick_and_the_latest_drives(node_and_client):
    node, cli = node_and_client
    pub = cli.declare_publisher(keys.cmd_vel_key("r0", source="controller"),
                                congestion_control=zenoh.CongestionControl.BLOCK)
    for k in range(1, 41):  # more than a tick's worth, all in one burst
        pub.put(VelCmd(vx=0.01 * k, va=0.0, source="controller", scan_id=k).encode())
    pub.put(b"not msgpack")  # a bad one among them: counted and dropped, never applied
    tick_until(node, lambda: node.counters["cmd_accepted"] + node.counters["rejected"] == 41)
    assert node.counters["cmd_accepted"] == 40 and node.counters["cmd"] == 1
    assert node.world.command(0) == pytest.approx((0.40, 0.0))  # the last one drives
    assert node._robots[0].answers["controller"] == 40
    # nothing more: the watchdog (0.5 s of sim time since the last arrival) stops the robot
    for _ in range(6):
        node.tick()
    assert node.world.command(0) == (0.0, 0.0)


def test_keep_freed_memory_is_set_where_the_c_library_allows_it():
    assert keep_freed_memory() in (True, False)
    try:
        import ctypes

        ctypes.CDLL(None).mallopt  # noqa: B018 - glibc: the setting must take
    except (OSError, AttributeError):
        pytest.skip("no mallopt in this C library")
    assert keep_freed_memory() is True

