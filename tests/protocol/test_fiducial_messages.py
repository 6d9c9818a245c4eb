"""The fiducial messages (Fiducial, FiducialGeometry, WorldInfo's beacons): round trips, and
hostile maps refused with the field named, never anything but a DecodeError."""

from __future__ import annotations

import contextlib
import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.codec import DecodeError
from protocol.messages import (
    BeaconInfo,
    Fiducial,
    FiducialGeometry,
    FiducialItem,
    Geometry,
    WorldInfo,
)

GOOD = Fiducial(ts=2.5, seq=7, items=(FiducialItem(1, 2.0, -0.25), FiducialItem(0, 7.5, 1.0)),
                pose=(1.0, 2.0, 0.5), truth=(1.1, 2.1, 0.4))


def _map(msg) -> dict:
    return msgpack.unpackb(msg.encode(), raw=False)


def _pack(m: dict) -> bytes:
    return msgpack.packb(m, use_bin_type=True)


def test_round_trips():
    assert Fiducial.decode(GOOD.encode()) == GOOD
    assert Fiducial.decode(Fiducial(ts=0.0, seq=0).encode()).items == ()
    assert _map(GOOD)["items"][0] == {"id": 1, "range": 2.0, "bearing": -0.25}
    g = FiducialGeometry(pose=(0.1, 0, 0), size=(0.1, 0.1), min_range=0.0, max_range=8.0,
                         max_range_id=5.0, fov=math.pi)
    assert FiducialGeometry.decode(g.encode()) == g
    assert Geometry.decode(g.encode()).size == (0.1, 0.1)  # the device geometry part
    w = WorldInfo(name="w", task="", beacons=(BeaconInfo(3, (1.0, 2.0), "#ff0000", 0.3),))
    assert WorldInfo.decode(w.encode()) == w
    assert "beacons" not in _map(WorldInfo(name="w", task=""))  # none: left out, as before


def test_an_item_gives_players_pose_in_the_sensor_frame():
    item = FiducialItem(4, 2.0, math.pi / 2)
    assert (item.x, item.y) == (pytest.approx(0.0), pytest.approx(2.0))
    assert GOOD.find(1) == GOOD.items[0] and GOOD.find(3) is None


@pytest.mark.parametrize("items, field", [
    ({"id": 1}, "items"),
    ([[1, 2.0, 0.5]], "items[0]"),
    ([{"id": 1, "range": 2.0}], "items[0].bearing"),
    ([{"id": -1, "range": 2.0, "bearing": 0.0}], "items[0].id"),
    ([{"id": True, "range": 2.0, "bearing": 0.0}], "items[0].id"),
    ([{"id": 1.0, "range": 2.0, "bearing": 0.0}], "items[0].id"),
    ([{"id": 1, "range": float("nan"), "bearing": 0.0}], "items[0].range"),
    ([{"id": 1, "range": 2.0, "bearing": float("inf")}], "items[0].bearing"),
    ([{"id": 1, "range": "far", "bearing": 0.0}], "items[0].range"),
    ([{"id": 1, "range": 2.0, "bearing": 0.0}] * 257, "items"),
    (None, "items"),
])
def test_hostile_items_are_refused_naming_the_field(items, field):
    m = dict(_map(GOOD), items=items)
    with pytest.raises(DecodeError, match=f"field '{field.replace('[', '.').replace(']', '.')}'"):
        Fiducial.decode(_pack(m))


def test_a_hostile_beacon_of_a_world_is_refused_naming_it():
    w = _map(WorldInfo(name="w", task="", beacons=(BeaconInfo(3, (1.0, 2.0), "#ff0000", 0.3),)))
    for bad, field in [({"id": 3, "pos": [1.0], "colour": "#ff0000", "size": 0.3}, "pos"),
                       ({"id": 3, "pos": [1.0, 2.0], "colour": "x" * 17, "size": 0.3}, "colour"),
                       ({"id": 3, "pos": [1.0, 2.0], "colour": "#ff0000"}, "size")]:
        with pytest.raises(DecodeError, match=f"beacons.0..{field}"):
            WorldInfo.decode(_pack(dict(w, beacons=[bad])))


values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats()
    | st.text(max_size=5) | st.binary(max_size=8),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(
        st.sampled_from(["id", "range", "bearing", "x"]), c, max_size=4),
    max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from(["v", "ts", "seq", "items", "pose", "truth"]), values))
def test_random_maps_only_ever_raise_decode_error(m):
    m.setdefault("v", 1)
    with contextlib.suppress(DecodeError):
        f = Fiducial.decode(_pack(m))
        assert all(math.isfinite(i.range) and math.isfinite(i.bearing) and i.id >= 0
                   for i in f.items)
