"""The fiducial input of a behaviour's perception (client.behaviour.features ``beacon``): the
range and bearing of one beacon, "none in view" a value of its own, in every path that makes
features (extract, extract_many, the payload reader), in behaviour files and snapshots."""

from __future__ import annotations

import math

import numpy as np
import pytest

from client.behaviour.features import NO_BEACON, FeatureError, FeatureSpec
from client.behaviour.spec import BehaviourError, behaviour
from protocol.messages import Fiducial, FiducialItem, Scan

BEAMS = (0.0, 45.0, 90.0, 135.0, 180.0)
SEEN = (FiducialItem(1, 2.0, 0.5), FiducialItem(2, 9.0, -math.pi / 2), FiducialItem(0, 7.0, 0.0))
RANGES = np.linspace(0.5, 3.0, 360).astype(np.float32)


def test_a_fixed_beacon_gives_in_view_range_and_bearing():
    spec = FeatureSpec(beams=BEAMS, beacon=1, beacon_range=4.0)
    assert spec.dim == 8
    x = spec.extract(RANGES, 0.0, seen=SEEN)
    assert x[-3:].tolist() == [1.0, 0.5, pytest.approx((0.5 / math.pi + 1) / 2)]
    assert (x >= 0).all() and (x <= 1).all()
    assert spec.extract(RANGES, 0.0, seen=())[-3:].tolist() == list(NO_BEACON)
    assert spec.extract(RANGES)[-3:].tolist() == list(NO_BEACON)  # nothing said: none


def test_the_goal_beacon_is_the_one_named_with_each_scan():
    spec = FeatureSpec(beams=BEAMS, beacon="goal")
    assert spec.extract(RANGES, seen=SEEN, target=2)[-3:].tolist() == [1.0, 1.0, 0.25]  # clamped
    assert spec.extract(RANGES, seen=SEEN, target=1)[-2] == pytest.approx(2.0 / 8.0)
    assert spec.extract(RANGES, seen=SEEN, target=None)[-3:].tolist() == list(NO_BEACON)
    assert spec.extract(RANGES, seen=SEEN, target=5)[-3:].tolist() == list(NO_BEACON)
    # a beacon seen but too far to identify (id 0) is not the goal's
    assert spec.extract(RANGES, seen=SEEN, target=0)[-3:].tolist() == list(NO_BEACON)


def test_none_in_view_is_apart_from_every_sighting():
    spec = FeatureSpec(beams=BEAMS, beacon=1)
    none = spec.beacon_values(())
    for r in (0.0, 4.0, 8.0, 20.0):
        for b in (-math.pi, -1.0, 0.0, 1.0, math.pi):
            seen = spec.beacon_values((FiducialItem(1, r, b),))
            assert seen[0] == 1.0 and none[0] == 0.0  # the first value tells them apart
            assert 0.0 <= seen[1] <= 1.0 and 0.0 <= seen[2] <= 1.0


def test_bearing_left_is_above_the_middle():
    spec = FeatureSpec(beams=BEAMS, beacon=1)
    left = spec.beacon_values((FiducialItem(1, 2.0, 0.3),))[2]
    right = spec.beacon_values((FiducialItem(1, 2.0, -0.3),))[2]
    assert right < 0.5 < left


def test_many_at_once_equal_one_at_a_time():
    spec = FeatureSpec(beams=BEAMS, beacon="goal", heading="lr", window=5.0)
    rows = np.stack([RANGES, RANGES[::-1].copy(), RANGES])
    yaws, seen, targets = [0.0, 3.0, -1.0], [SEEN, SEEN, None], [1, 2, 1]
    many = spec.extract_many(rows, yaws, seen, targets)
    for i in range(3):
        np.testing.assert_array_equal(many[i], spec.extract(rows[i], yaws[i], seen[i],
                                                            targets[i]))
    with pytest.raises(FeatureError, match="sightings"):
        spec.extract_many(rows, yaws, seen[:2], targets)


def test_the_payload_reader_reads_none_in_view_until_told_what_was_seen():
    spec = FeatureSpec(beams=BEAMS, beacon=1, heading="lr")
    reader = spec.reader()
    scan = Scan(ts=1.0, id=4, ranges=RANGES, pose=(0.0, 0.0, 2.5))
    assert reader.read(scan.encode())
    np.testing.assert_array_equal(reader.x, spec.extract(RANGES, 2.5))
    fid = Fiducial(ts=1.0, seq=4, items=SEEN)
    reader.see(fid.items)
    np.testing.assert_array_equal(reader.x, spec.extract(RANGES, 2.5, seen=SEEN))


def test_specs_with_a_beacon_round_trip_and_those_without_are_unchanged():
    spec = FeatureSpec(beams=BEAMS, beacon="goal", beacon_range=5.0)
    assert FeatureSpec.from_dict(spec.to_dict()) == spec
    plain = FeatureSpec(beams=BEAMS)
    assert "beacon" not in plain.to_dict()  # a snapshot's metadata as before
    assert FeatureSpec.from_dict(plain.to_dict()) == plain


@pytest.mark.parametrize("beacon", [0, -1, True, 1.5, "home"])
def test_a_bad_beacon_is_refused(beacon):
    with pytest.raises(FeatureError, match="beacon"):
        FeatureSpec(beams=BEAMS, beacon=beacon)


BEHAVIOUR = """
name = "seek"
summary = "go to the red beacon"
instructions = "drive to it"
[perception]
sectors = 9
window = 0
{extra}
[expert]
name = "wall-follower"
[worlds]
teach = ["beacons-room"]
held_out = ["beacons-room"]
[success]
no-collision = {{}}
"""


def test_a_behaviour_file_names_its_beacon(tmp_path):
    p = tmp_path / "seek.toml"
    p.write_text(BEHAVIOUR.replace("window = 0\n", "").format(extra='beacon = "goal"\n'
                                                               'beacon_range = 6'))
    b = behaviour(p)
    assert b.features.beacon == "goal" and b.features.beacon_range == 6.0
    assert b.features.dim == 12
    for extra, field in [("beacon = 0", "perception.beacon"),
                         ('beacon = "red"', "perception.beacon"),
                         ("beacon_range = 3", "perception.beacon_range"),
                         ("beacon = 1\nbeacon_range = -3", "perception.beacon_range")]:
        p.write_text(BEHAVIOUR.replace("window = 0\n", "").format(extra=extra))
        with pytest.raises(BehaviourError, match=f"field '{field}'"):
            behaviour(p)
