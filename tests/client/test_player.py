"""client.player against a real ``rhbl server`` process (lock-step, corridor world)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from client.player import LaserProxy, PlayerClient, Position2dProxy, RequestError

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def server(start_module_server):
    return start_module_server("corridor", "--lockstep-timeout", "0.2", lockstep=True)


def test_read_refreshes_proxies_and_set_speed_drives(server, client_config):
    with PlayerClient(client_config(server.endpoint), robot="r0", source="controller") as c:
        pos, laser = c.position2d, c.laser
        assert isinstance(pos, Position2dProxy) and isinstance(laser, LaserProxy)
        assert c.read(timeout=5.0)
        assert laser.count == len(laser) == 360
        assert laser.min_angle == pytest.approx(-math.pi / 2)
        assert laser.max_angle == pytest.approx(math.pi / 2)
        assert laser.resolution == pytest.approx(math.pi / 359)
        assert laser.max_range == 8.0
        assert laser.bearings[0] == pytest.approx(-math.pi / 2)
        assert laser.bearing(359) == pytest.approx(math.pi / 2)
        assert laser[0] == pytest.approx(pos.truth[1], abs=0.01)  # right wall, y = 0
        assert isinstance(laser.ranges, np.ndarray)
        x0, first = pos.x, laser.id
        for _ in range(10):  # lock-step: each command answers the scan just read
            pos.set_speed(0.5, 0.0)
            assert c.read(timeout=5.0)
        assert laser.id >= first + 10
        assert pos.x - x0 == pytest.approx(0.45, abs=0.06)
        assert pos.vx == pytest.approx(0.5, abs=1e-6) and not pos.stall
        assert pos.driver == "controller" and c.driver() in (None, "controller")
        pos.stop()


def test_requests_and_nack(server, client_config):
    with PlayerClient(client_config(server.endpoint), source="client") as c:
        pos = c.position2d
        g = pos.get_geom()
        assert g.size == pytest.approx((0.511, 0.4))
        assert pos.size == pytest.approx((0.511, 0.4))
        cfg = c.laser.get_config()
        assert cfg.count == 360
        pos.set_odom(1.0, 2.0, 0.5)
        c.read(timeout=5.0)
        c.read(timeout=5.0)
        assert (pos.x, pos.y, pos.yaw) == pytest.approx((1.0, 2.0, 0.5), abs=1e-6)
        pos.reset_odom()
        c.read(timeout=5.0)
        c.read(timeout=5.0)
        assert pos.pose == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
        with pytest.raises(RequestError, match="NACK.*'v'"):
            c.request("position2d", "set_odom", b"\x80")
        with pytest.raises(RequestError, match="NACK.*'pose'"):
            c.request("position2d", "set_odom", b"\x81\xa1v\x01")
        with pytest.raises(RequestError, match="no reply"):
            c.request("position2d", "no_such_request", timeout=0.3)
        with pytest.raises(ValueError, match="finite"):
            pos.set_speed(float("nan"), 0.0)


def test_simulation_proxy_sets_and_gets_the_pose(server, client_config):
    with PlayerClient(client_config(server.endpoint), source="controller") as c:
        pos, laser, sim = c.position2d, c.laser, c.simulation
        assert c.read(timeout=5.0)
        ack = sim.set_pose2d(6.0, 1.4, math.pi)
        assert ack.extra["scan_id"] > laser.id
        while laser.id < ack.extra["scan_id"]:
            assert c.read(timeout=5.0)
        for _ in range(10):  # the state may land just after its scan: at most a tick later
            if pos.truth == pytest.approx((6.0, 1.4, math.pi)):
                break
            c.read(timeout=1.0)
        assert pos.truth == pytest.approx((6.0, 1.4, math.pi)) and pos.pose == pytest.approx(pos.truth)
        assert pos.vx == 0.0 and not pos.stall
        assert sim.get_pose2d() == pytest.approx((6.0, 1.4, math.pi))
        c.set_pose(2.0, 1.0, 0.0, reset_odom=False)
        assert sim.get_pose2d() == pytest.approx((2.0, 1.0, 0.0))
        assert sim.get_pose().odom[0] == pytest.approx(6.0)
        with pytest.raises(RequestError, match="NACK.*from a wall"):
            sim.set_pose2d(5.0, 1.9, 0.0)
        assert sim.get_pose2d() == pytest.approx((2.0, 1.0, 0.0))


def test_read_times_out_without_server():
    from process.session import make_config

    with PlayerClient(make_config(mode="peer")) as c, c.laser:
        assert c.read(timeout=0.2) is False
        assert c.laser.count == 0


def test_simulation_proxy_gets_the_world(server, client_config):
    from server import world_path
    from server.world import load_world

    spec = load_world(world_path("corridor"))
    with PlayerClient(client_config(server.endpoint), source="controller") as c:
        info = c.simulation.get_world()
    assert (info.name, info.task) == (spec.name, "")  # worlds name no task (a hint of old files)
    assert np.allclose(np.asarray(info.walls), spec.segments())
    assert info.starts[0] == pytest.approx(spec.pose)
    assert len(info.starts) == len(spec.start_poses)
