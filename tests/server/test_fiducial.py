"""The fiducial finder (server.fiducial, World.fiducials) and the world files' beacons."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import server
from server.world import FIDUCIAL, World, WorldError, load_world, parse_world

ROOM = {"name": "box", "robot": {"pose": [1.0, 1.0, 0.0]},
        "walls": [{"closed": True, "points": [[0, 0], [10, 0], [10, 6], [0, 6]]}]}


def world(beacons, walls=(), pose=(1.0, 3.0, 0.0)) -> World:
    data = {**ROOM, "walls": ROOM["walls"] + [{"points": w} for w in walls],
            "beacons": beacons}
    w = World(parse_world(data))
    w.reset(poses=[pose])
    return w


def seen(w: World) -> dict[int, tuple[float, float]]:
    (s,) = w.fiducials()
    return {int(i): (float(r), float(b)) for i, r, b in zip(s.ids, s.ranges, s.bearings,
                                                             strict=True)}


def test_a_beacon_ahead_is_seen_at_its_range_and_bearing():
    w = world([{"id": 3, "pos": [5.0, 3.0]}])
    assert seen(w) == {3: (pytest.approx(4.0), pytest.approx(0.0))}


def test_bearing_is_counter_clockwise_positive_as_players():
    # facing +x: a beacon on the robot's left (+y) has a positive bearing, on its right negative
    w = world([{"id": 1, "pos": [4.0, 5.0]}, {"id": 2, "pos": [4.0, 1.0]}])
    got = seen(w)
    assert got[1][1] == pytest.approx(math.atan2(2.0, 3.0))
    assert got[2][1] == pytest.approx(-math.atan2(2.0, 3.0))
    # turned to face +y, the beacon at +y ahead-left is now ahead-right
    w.reset(poses=[(1.0, 3.0, math.pi / 2)])
    assert seen(w)[1][1] == pytest.approx(math.atan2(2.0, 3.0) - math.pi / 2)


def test_a_beacon_behind_a_wall_is_not_seen():
    w = world([{"id": 1, "pos": [8.0, 3.0]}, {"id": 2, "pos": [8.0, 5.0]}],
              walls=[[[5.0, 2.0], [5.0, 4.0]]])
    got = seen(w)
    assert 1 not in got  # the partition crosses the line to it
    assert 2 in got  # the line to (8, 5) passes above the partition's end
    # from the far side of the partition it is seen again
    w.reset(poses=[(6.0, 3.0, 0.0)])
    assert set(seen(w)) == {1, 2}


def test_a_beacon_on_a_wall_is_seen_from_the_side_its_centre_is_on():
    w = world([{"id": 1, "pos": [10.0, 3.0], "size": 0.2}], pose=(4.0, 3.0, 0.0))  # on x = 10
    assert set(seen(w)) == {1}  # a wall through the centre hides nothing
    w = world([{"id": 1, "pos": [4.95, 3.0], "size": 0.2}], walls=[[[5.0, 1.0], [5.0, 5.0]]])
    assert set(seen(w)) == {1}  # mounted on the partition's left face
    w.reset(poses=[(9.0, 3.0, math.pi)])
    assert seen(w) == {}  # from behind the partition: hidden


def test_out_of_field_of_view_or_range_is_not_seen():
    w = world([{"id": 1, "pos": [0.5, 3.0]}, {"id": 2, "pos": [1.0, 5.0]}])
    got = seen(w)
    assert 1 not in got  # behind (bearing pi)
    assert got[2][1] == pytest.approx(math.pi / 2)  # at the edge of the 180 degrees: seen
    w.reset(poses=[(1.0, 3.0, -0.01)])
    assert 2 not in seen(w)  # just outside
    data = {**ROOM, "walls": [{"closed": True, "points": [[0, 0], [20, 0], [20, 6], [0, 6]]}],
            "beacons": [{"id": 1, "pos": [1.0 + FIDUCIAL.max_range + 0.01, 3.0]},
                        {"id": 2, "pos": [1.0 + FIDUCIAL.max_range - 0.01, 3.0]}]}
    far = World(parse_world(data))
    far.reset(poses=[(1.0, 3.0, 0.0)])
    assert set(seen(far)) == {2}


def test_every_robot_sees_its_own_and_the_rows_agree():
    data = {**ROOM, "beacons": [{"id": 1, "pos": [5.0, 3.0]}, {"id": 2, "pos": [9.0, 1.0]}]}
    fleet = World(parse_world(data), robots=3)
    poses = [(1.0, 3.0, 0.0), (8.0, 3.0, 0.0), (4.0, 1.0, math.pi)]
    fleet.reset(poses=poses)
    together = fleet.fiducials()
    for k, p in enumerate(poses):
        one = World(parse_world(data))
        one.reset(poses=[p])
        (alone,) = one.fiducials()
        np.testing.assert_array_equal(together[k].ids, alone.ids)
        np.testing.assert_allclose(together[k].ranges, alone.ranges)
        np.testing.assert_allclose(together[k].bearings, alone.bearings)
    assert list(fleet.fiducials([1])[0].ids) == [2]  # ahead; beacon 1 behind it
    assert list(together[2].ids) == []  # facing -x: both behind


def test_naive_reference_agrees_in_the_shipped_beacon_world():
    spec = load_world(server.world_path("beacons-room"))
    w = World(spec)
    rng = np.random.default_rng(5)
    segs = spec.segments()
    checked = 0
    while checked < 200:
        x0, y0, x1, y1 = spec.bounds()
        pose = (rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-math.pi, math.pi))
        if w.pose_problem(0, pose):
            continue
        w.reset(poses=[pose])
        x, y, yaw = w.pose(0)
        want = {}
        for b in spec.beacons:
            dx, dy = b.pos[0] - x, b.pos[1] - y
            r = math.hypot(dx, dy)
            a = math.atan2(math.sin(math.atan2(dy, dx) - yaw), math.cos(math.atan2(dy, dx) - yaw))
            if r > FIDUCIAL.max_range or abs(a) > FIDUCIAL.fov / 2:
                continue
            if any(_crosses((x, y), b.pos, s, 1 - 1e-6 / r) for s in segs):
                continue
            want[b.id] = (pytest.approx(r), pytest.approx(a, abs=1e-9))
        assert seen(w) == want, pose
        checked += 1


def _crosses(o, p, seg, limit) -> bool:
    (ox, oy), (px, py) = o, p
    x0, y0, x1, y1 = seg
    vx, vy, ex, ey = px - ox, py - oy, x1 - x0, y1 - y0
    den = vx * ey - vy * ex
    if den == 0:
        return False
    wx, wy = x0 - ox, y0 - oy
    t = (wx * ey - wy * ex) / den
    u = (wx * vy - wy * vx) / den
    return 0 < t < limit and 0 <= u <= 1


def test_the_shipped_beacon_world_hides_each_beacon_from_somewhere():
    spec = load_world(server.world_path("beacons-room"))
    assert [(b.id, b.colour) for b in spec.beacons] == [(1, (220, 40, 40)), (2, (40, 170, 60))]
    w = World(spec)
    w.reset(poses=[(1.0, 3.0, 0.0)])  # facing beacon 2 across the room: the partition between
    assert 2 not in seen(w)
    w.reset(poses=[(6.5, 3.0, 0.0)])
    assert 2 in seen(w)


def test_a_world_without_beacons_sees_nothing():
    w = World(load_world(server.world_path("room")))
    (s,) = w.fiducials()
    assert len(s.ids) == 0 and w.spec.beacons == ()


def test_beacons_scale_with_the_world():
    spec = parse_world({**ROOM, "beacons": [{"id": 4, "pos": [2.0, 3.0], "colour": "blue"}]})
    assert spec.scaled(2.0).beacons[0].pos == (4.0, 6.0)


@pytest.mark.parametrize("beacons, names", [
    ({"id": 1}, "beacons"),
    ([7], "beacons[0]"),
    ([{"pos": [1, 1]}], "beacons[0].id"),
    ([{"id": 0, "pos": [1, 1]}], "beacons[0].id"),
    ([{"id": True, "pos": [1, 1]}], "beacons[0].id"),
    ([{"id": 1.5, "pos": [1, 1]}], "beacons[0].id"),
    ([{"id": 1, "pos": [1, 1]}, {"id": 1, "pos": [2, 2]}], "beacons[1].id"),
    ([{"id": 1}], "beacons[0].pos"),
    ([{"id": 1, "pos": [1]}], "beacons[0].pos"),
    ([{"id": 1, "pos": [1, float("nan")]}], "beacons[0].pos[1]"),
    ([{"id": 1, "pos": [30, 1]}], "beacons[0].pos"),
    ([{"id": 1, "pos": [1, 1], "size": 0}], "beacons[0].size"),
    ([{"id": 1, "pos": [1, 1], "size": "big"}], "beacons[0].size"),
    ([{"id": 1, "pos": [1, 1], "colour": "mauve"}], "beacons[0].colour"),
    ([{"id": 1, "pos": [1, 1], "colour": [255, 0]}], "beacons[0].colour"),
    ([{"id": 1, "pos": [1, 1], "colour": [255, 0, 256]}], "beacons[0].colour"),
    ([{"id": 1, "pos": [1, 1], "color": "red"}], "beacons[0].color"),
    ([{"id": k, "pos": [1, 1]} for k in range(1, 300)], "beacons"),
])
def test_bad_beacons_are_refused_naming_the_field(beacons, names):
    with pytest.raises(WorldError, match=re.escape(f"key '{names}'")):
        parse_world({**ROOM, "beacons": beacons})


def test_colour_by_name_or_rgb():
    spec = parse_world({**ROOM, "beacons": [{"id": 1, "pos": [1, 1], "colour": "Red"},
                                            {"id": 2, "pos": [2, 2], "colour": [1, 2, 3]},
                                            {"id": 3, "pos": [3, 3]}]})
    assert [b.colour for b in spec.beacons][:2] == [(220, 40, 40), (1, 2, 3)]
    assert spec.beacon(3).size == 0.2 and spec.beacon(9) is None


def test_the_python_loop_and_numpy_give_the_same_sightings():
    from server.fiducial import FiducialFinder

    spec = load_world(server.world_path("beacons-room"))
    loop = FiducialFinder(spec.segments(), spec.beacons, FIDUCIAL, small=10**9)
    vec = FiducialFinder(spec.segments(), spec.beacons, FIDUCIAL, small=0)
    rng = np.random.default_rng(11)
    x0, y0, x1, y1 = spec.bounds()
    poses = np.column_stack([rng.uniform(x0, x1, 500), rng.uniform(y0, y1, 500),
                             rng.uniform(-math.pi, math.pi, 500)])
    a, b = loop.detect(poses), vec.detect(poses)
    assert sum(len(s.ids) for s in a) > 100  # many sightings, some hidden
    for sa, sb in zip(a, b, strict=True):
        assert sa.ids == sb.ids and sa.index == sb.index
        np.testing.assert_allclose(sa.ranges, sb.ranges, rtol=1e-12)
        np.testing.assert_allclose(sa.bearings, sb.bearings, atol=1e-12)
