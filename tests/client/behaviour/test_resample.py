"""client.behaviour.resample: another laser's scans in the layout the tree's features read."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client.behaviour.features import FEATURES, FeatureError, FeatureSpec
from client.behaviour.resample import TAUGHT_BEAMS, CoverageError, LaserResampler
from client.behaviour.tasks import make_policy
from protocol.messages import Scan
from server import world_path
from server.world import LASER, free_pose, load_world

NATIVE = dict(min_angle=LASER.min_angle, resolution=LASER.resolution, count=LASER.count,
              max_range=LASER.max_range)


def _layout(count, fov_deg, max_range=10.0):
    span = math.radians(fov_deg)
    return dict(min_angle=-span / 2, resolution=span / (count - 1), count=count,
                max_range=max_range)


def _cast(segments, pose, bearings, max_range):
    """A plain ray cast of ``bearings`` (robot frame) from ``pose`` against wall segments."""
    x, y, yaw = pose
    d = np.stack([np.cos(bearings + yaw), np.sin(bearings + yaw)])[:, None, :]
    a = (segments[:, :2] - (x, y)).T[:, :, None]
    e = (segments[:, 2:] - segments[:, :2]).T[:, :, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        den = e[1] * d[0] - e[0] * d[1]
        t = (a[0] * e[1] - a[1] * e[0]) / den
        u = (a[0] * d[1] - a[1] * d[0]) / den
    hit = (u >= 0) & (u <= 1) & (t > 0)
    return np.minimum(np.where(hit, t, np.inf).min(axis=0), max_range).astype(np.float32)


def test_the_native_layout_is_left_as_it_is():
    fit = LaserResampler(FEATURES["wall"], **NATIVE)
    r = np.random.default_rng(0).uniform(0.3, 8.0, LASER.count).astype(np.float32)
    assert np.array_equal(fit.resample(r), r)
    assert np.array_equal(fit.features(r, 0.3), FEATURES["wall"].extract(r, 0.3))
    assert LASER.count == TAUGHT_BEAMS


def test_each_taught_beam_reads_the_nearest_echo_in_its_footprint():
    # a 720-beam 180-degree laser: two of its beams per taught beam
    fit = LaserResampler(FEATURES["wall"], **_layout(720, 180.0))
    r = np.full(720, 5.0, dtype=np.float32)
    r[101] = 1.0
    out = fit.resample(r)
    assert out.shape == (360,) and out.dtype == np.float32
    assert out[50] == 1.0 and (np.delete(out, 50) == 5.0).all()
    r[4:6] = np.nan, np.inf  # the two beams in taught beam 2's footprint: no reading, no echo
    assert fit.resample(r)[2] == 10.0 and fit.resample(r)[1] == 5.0


@pytest.mark.parametrize(("name", "count", "fov"), [
    ("wall", 640, 240.0), ("wall", 1081, 270.0), ("maze-right", 640, 240.0),
    ("wall", 181, 180.0), ("maze", 360, 360.0 * 359 / 360)])
def test_another_laser_gives_the_features_and_the_teacher_the_native_laser_gives(name, count, fov):
    """Same room, same poses: features from the other laser, resampled, against features from
    the simulator's laser (both cast here the same way, so only the resampling differs), and
    the wall-following teacher's choice on each. Rare poses differ more (a fin's end seen
    edge-on by one laser's rays and not the other's), so the bound is on the 99th percentile."""
    spec, other = FEATURES[name], _layout(count, fov, max_range=LASER.max_range)
    fit = LaserResampler(spec, **other)
    world = load_world(world_path("room"))
    segments = world.segments()
    bearings = other["min_angle"] + np.arange(count) * other["resolution"]
    teacher = make_policy("wall-following")
    rng = np.random.default_rng(7)
    diffs, agree, poses = [], 0, 200
    for _ in range(poses):
        pose = free_pose(world, rng)
        native = _cast(segments, pose, LASER.bearings(), LASER.max_range)
        theirs = fit.resample(_cast(segments, pose, bearings, LASER.max_range))
        diffs.append(np.abs(spec.extract(native, pose[2]) - spec.extract(theirs, pose[2])).max())
        agree += teacher.act(native, pose) == teacher.act(theirs, pose)
    assert np.percentile(diffs, 99) <= 0.025  # features are metres / 2: 5 cm
    assert np.median(diffs) <= 0.002
    assert agree >= 0.97 * poses


@pytest.mark.parametrize(("name", "layout", "match"), [
    ("wall", _layout(360, 170.0), r"beam 0 \+/- 11.25 deg from the right \(-90.0..-78.5 deg\).*"
                                  r"cover only -85.2..85.2 deg"),
    ("maze", _layout(640, 120.0), r"beam 0 deg from the right .*beam 180 deg from the right"),
    ("wall-ping", dict(min_angle=0.1, resolution=0.01, count=100, max_range=8.0), "beam 0 deg"),
])
def test_a_laser_that_cannot_see_a_needed_beam_is_refused(name, layout, match):
    with pytest.raises(CoverageError, match=match):
        LaserResampler(FEATURES[name], **layout)


def test_a_laser_missing_only_unneeded_beams_is_fine():
    # "wall" looks at 0..101.25 deg from the right: the left quarter is never read
    spec = FEATURES["wall"]
    right = dict(min_angle=-math.pi / 2, resolution=math.radians(0.5), count=241, max_range=8.0)
    fit = LaserResampler(spec, **right)  # -90..+30 deg
    out = fit.resample(np.full(241, 1.5, dtype=np.float32))
    assert (out[:240] == 1.5).all() and out[-1] == 8.0  # nothing seen where it cannot look


def test_for_scan_and_fits():
    scan = Scan(ts=0.0, id=1, ranges=np.ones(640, np.float32), **{
        k: v for k, v in _layout(640, 240.0).items() if k != "count"},
        max_angle=math.radians(120))
    fit = LaserResampler.for_scan(FEATURES["wall"], scan)
    assert fit.fits(scan)
    assert not fit.fits(Scan(ts=0.0, id=2, ranges=np.ones(360, np.float32)))
    with pytest.raises(FeatureError, match="expected a scan of 640 beams"):
        fit.resample(np.ones(360))


def test_bad_layouts():
    with pytest.raises(FeatureError, match="finite min_angle"):
        LaserResampler(FEATURES["wall"], min_angle=float("nan"), resolution=0.01, count=10,
                       max_range=8.0)
    with pytest.raises(FeatureError, match="count >= 1"):
        LaserResampler(FEATURES["wall"], min_angle=0.0, resolution=0.0, count=10, max_range=8.0)


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 2000), st.floats(100.0, 359.0), st.floats(-5.0, 5.0),
       st.integers(0, 2**32 - 1))
def test_resampled_ranges_are_footprint_minima(count, fov, shift_deg, seed):
    spec = FeatureSpec(beams=(90.0,))  # straight ahead only
    layout = _layout(count, fov)
    layout["min_angle"] += math.radians(shift_deg)
    try:
        fit = LaserResampler(spec, **layout)
    except CoverageError:
        assert count < 4  # a sparse laser may miss straight ahead; any decent one does not
        return
    r = np.random.default_rng(seed).uniform(0.1, 10.0, count).astype(np.float32)
    out = fit.resample(r)
    src = layout["min_angle"] + np.arange(count) * layout["resolution"]
    targets = -math.pi / 2 + np.arange(360) * (math.pi / 359)
    half = math.pi / 359 / 2
    for j in (0, 90, 179, 180, 270, 359):
        inside = (src >= targets[j] - half - 1e-9) & (src < targets[j] + half - 1e-9)
        if inside.any():
            assert out[j] == r[inside].min()
        else:
            assert out[j] in (np.float32(10.0), r[np.argmin(np.abs(src - targets[j]))])
