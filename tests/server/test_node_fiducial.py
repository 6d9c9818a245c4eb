"""The real ``rhbl server`` process serving the fiducial interface (a world with beacons) over a
real zenoh session on loopback."""

from __future__ import annotations

import math
import threading

import pytest
import zenoh
from waiting import patience

from protocol import keys
from protocol.messages import (
    Ack,
    Fiducial,
    FiducialGeometry,
    Geometry,
    Scan,
    SetPose,
    WorldInfo,
)

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def beacons(start_module_server):
    return start_module_server("beacons-room")


@pytest.fixture
def session(beacons, client_config):
    with zenoh.open(client_config(beacons.endpoint)) as s:
        yield s


class Seen:
    """Every fiducial message and scan of robot r0, in arrival order."""

    def __init__(self, session: zenoh.Session) -> None:
        self.cond = threading.Condition()
        self.fiducials: list[Fiducial] = []
        self.scans: list[Scan] = []
        self._subs = [
            session.declare_subscriber(keys.fiducial_key("r0"), self._on(Fiducial, self.fiducials)),
            session.declare_subscriber(keys.scan_key("r0"), self._on(Scan, self.scans)),
        ]

    def _on(self, cls, into):
        def on_sample(sample):
            msg = cls.decode(sample.payload.to_bytes())
            with self.cond:
                into.append(msg)
                self.cond.notify_all()
        return on_sample

    def fiducial_after(self, scan_id: int, timeout=5.0) -> Fiducial:
        with self.cond:
            assert self.cond.wait_for(
                lambda: any(f.seq > scan_id for f in self.fiducials), patience(timeout)), \
                f"no fiducial message after scan {scan_id}"
            return next(f for f in self.fiducials if f.seq > scan_id)


def place(session, pose) -> int:
    """Teleport r0 to ``pose``; the id of the first scan taken there."""
    (reply,) = list(session.get(keys.sim_request_key("r0", "set_pose"),
                                payload=SetPose(pose).encode(), timeout=3.0))
    return int(Ack.decode(reply.ok.payload.to_bytes()).extra["scan_id"])


def test_the_beacons_in_view_arrive_every_tick_with_the_scans_ids(session):
    seen = Seen(session)
    first = place(session, (6.5, 3.0, 0.0))  # facing the green beacon (id 2) at (9.7, 3.5)
    f = seen.fiducial_after(first - 1)
    assert [i.id for i in f.items] == [2]
    item = f.find(2)
    assert item.range == pytest.approx(math.hypot(3.2, 0.5), abs=1e-6)
    assert item.bearing == pytest.approx(math.atan2(0.5, 3.2), abs=1e-6)  # left: positive
    assert f.truth == pytest.approx((6.5, 3.0, 0.0)) and f.find(1) is None
    # the messages are numbered as the scans: every tick's scan has its tick's message (sent
    # before the scan, but on another subscriber: its callback may run after the scan's)
    with seen.cond:
        assert seen.cond.wait_for(lambda: len(seen.scans) >= 3, patience(5.0))
        ids = [scan.id for scan in seen.scans[1:3]]  # the first may precede the subscription
        assert seen.cond.wait_for(lambda: set(ids) <= {x.seq for x in seen.fiducials},
                                  patience(5.0)), (ids, [x.seq for x in seen.fiducials])


def test_a_beacon_behind_the_partition_is_not_seen_and_none_is_an_empty_list(session):
    seen = Seen(session)
    f = seen.fiducial_after(place(session, (1.0, 3.0, 0.0)) - 1)  # the partition hides id 2
    assert f.items == ()
    f = seen.fiducial_after(place(session, (1.0, 3.0, math.pi)) - 1)  # facing the red one
    assert [i.id for i in f.items] == [1]
    assert f.items[0].bearing == pytest.approx(-math.atan2(0.5, 0.7), abs=1e-6)


def test_get_geom_answers_the_sensors_geometry_in_one_place(session):
    (reply,) = list(session.get(keys.request_key("r0", "fiducial", "get_geom"), timeout=3.0))
    g = FiducialGeometry.decode(reply.ok.payload.to_bytes())
    assert (g.max_range, g.max_range_id, g.fov, g.rate) == (8.0, 8.0, pytest.approx(math.pi),
                                                            10.0)
    assert g.pose == (0.0, 0.0, 0.0)
    Geometry.decode(reply.ok.payload.to_bytes())  # read as any device's geometry, too


def test_the_world_names_its_beacons(session):
    (reply,) = list(session.get(keys.sim_request_key("r0", "get_world"), timeout=3.0))
    info = WorldInfo.decode(reply.ok.payload.to_bytes())
    assert [(b.id, b.pos, b.colour) for b in info.beacons] == [
        (1, (0.3, 3.5), "#dc2828"), (2, (9.7, 3.5), "#28aa3c")]


def test_the_player_clients_fiducial_proxy(session):
    from client.player import FiducialProxy, PlayerClient

    with PlayerClient(session=session, robot="r0", source="probe") as client:
        fid, laser = client.fiducial, client.laser
        assert isinstance(fid, FiducialProxy) and fid.count == 0 and fid.find(2) is None
        first = place(session, (6.5, 3.0, 0.0))
        while True:  # a read pairs the scan with its tick's beacons once any came
            assert client.read(timeout=patience(5.0))
            if laser.id >= first and fid.seq >= first:
                break
        assert fid.seq == laser.id  # the beacons of the scan's own tick
        assert [i.id for i in fid.items] == [2] and len(fid) == 1
        item = fid.find(2)
        assert item is fid[0]
        assert (item.x, item.y) == (pytest.approx(3.2, abs=1e-6), pytest.approx(0.5, abs=1e-6))
        assert fid.get_geom().fov == pytest.approx(math.pi)


def test_a_fiducial_log_pairs_each_scan_with_its_ticks_beacons(session):
    from client.behaviour.features import NO_BEACON, FeatureSpec
    from client.player import PlayerClient

    spec = FeatureSpec(beams=(0.0, 90.0, 180.0), beacon=2)
    reader = spec.reader()
    with PlayerClient(session=session, robot="r0", source="probe") as client:
        log = client.fiducials(depth=8)
        scans = client.scans(depth=4)
        first = place(session, (6.5, 3.0, 0.0))
        while True:  # scans of the new pose
            data = scans.recv_payload()
            assert reader.read(data)
            if reader.id >= first:
                break
        assert tuple(reader.x[-3:]) == NO_BEACON  # until told what was seen
        items = log.seen(reader.id, timeout=patience(5.0))
        assert [i.id for i in items] == [2] and log.at(reader.id).seq == reader.id
        reader.see(items)
        assert reader.x[-3] == 1.0 and 0.5 < reader.x[-1] < 0.6  # ahead, a little left
        assert log.at(10**9) is None and log.seen(10**9) == ()


def test_a_world_without_beacons_answers_get_geom_and_publishes_no_fiducials(
        start_module_server, client_config):
    srv = start_module_server("corridor")
    with zenoh.open(client_config(srv.endpoint)) as s:
        seen = Seen(s)
        (reply,) = list(s.get(keys.request_key("r0", "fiducial", "get_geom"), timeout=3.0))
        assert FiducialGeometry.decode(reply.ok.payload.to_bytes()).max_range == 8.0
        with seen.cond:
            assert seen.cond.wait_for(lambda: len(seen.scans) >= 5, patience(5.0))
            assert seen.fiducials == []  # five ticks, not one fiducial message
