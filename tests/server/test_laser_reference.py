"""The vectorised laser against a plain per-beam ray cast, on random free poses of every shipped
world (the corridor property test in test_world.py checks a box analytically). Every test runs
twice: with the cast compiled ahead of time (setup.py; skipped where it is not built) and with
numba's."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

import server
from server import laser
from server.world import LASER, World, load_world

# the kernels numba compiles when first used: the same checks, after tens of seconds of
# compiling; only in the whole suite (`make test`), not the fast tier (`make check`)
NUMBA = pytest.param("numba", marks=pytest.mark.slow)


@pytest.fixture(autouse=True, scope="module", params=["ahead-of-time", NUMBA])
def kernels(request):
    """The cast every laser of the module uses."""
    cast, origin = laser._kernels()
    if request.param == "numba":
        cast, origin = importlib.import_module("server._laser_kernels").cast, "numba"
    elif origin != "ahead-of-time":
        pytest.skip("no laser kernel compiled ahead of time (setup.py: no C compiler, or the "
                    "source changed since make install)")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(laser, "_kernels", lambda: (cast, origin))
        yield request.param


def dense_walls(segments, x, y, dc, ds) -> np.ndarray:
    """Every segment against every beam (float32 directions ``dc``, ``ds``), nothing culled,
    in numpy: float32 intersections with the arithmetic the compiled cast documents
    (server/laser.py)."""
    f4 = np.float32
    ax, ay = (segments[:, 0] - x).astype(f4)[:, None], (segments[:, 1] - y).astype(f4)[:, None]
    ex = (segments[:, 2] - segments[:, 0]).astype(f4)[:, None]
    ey = (segments[:, 3] - segments[:, 1]).astype(f4)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = f4(1.0) / (ey * dc - ex * ds)
        tr = (ax * ey - ay * ex) * inv
        u = (ax * ds - ay * dc) * inv
    hit = (u >= 0.0) & (u <= 1.0) & (tr > 0.0)
    return np.min(np.where(hit, tr, f4(LASER.max_range)), axis=0)


def placed(world, rng, n, axis_every=0):
    """Put ``world``'s robot at ``n`` random free poses in turn (every ``axis_every``-th facing
    along the axes or a diagonal: beams along the walls' lines); yield its pose each time."""
    xmin, ymin, xmax, ymax = world.spec.bounds()
    checked = 0
    while checked < n:
        yaw = float(rng.uniform(-math.pi, math.pi))
        if axis_every and checked % axis_every == 0:
            yaw = float(rng.choice([0.0, math.pi / 2, -math.pi / 2, math.pi, math.pi / 4]))
        pose = (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), yaw)
        if world.pose_problem(0, pose):
            continue
        world.reset(poses=[pose])
        yield world.pose(0)
        checked += 1


@pytest.mark.parametrize("name", server.world_names())
def test_the_culled_cast_equals_the_dense_cast_bit_for_bit(name):
    # the compiled cast skips segments behind the laser or out of range and the beams outside
    # a segment's angular interval; what it skips must never have been a hit
    spec = load_world(server.world_path(name))
    world = World(spec)
    for x, y, yaw in placed(world, np.random.default_rng(3), 300, axis_every=4):
        ranges = world.scan(0)
        dc, ds = world._laser.directions(0)
        ang = LASER.bearings() + yaw  # the directions are those of the heading, to float32
        np.testing.assert_allclose(dc, np.cos(ang), atol=1e-7)
        np.testing.assert_allclose(ds, np.sin(ang), atol=1e-7)
        np.testing.assert_array_equal(ranges, dense_walls(spec.segments(), x, y, dc, ds))


def naive_scan(segments, x, y, yaw) -> np.ndarray:
    out = np.full(LASER.count, LASER.max_range)
    for i, b in enumerate(LASER.bearings()):
        dx, dy = math.cos(yaw + b), math.sin(yaw + b)
        for x0, y0, x1, y1 in segments:
            ex, ey = x1 - x0, y1 - y0
            den = ey * dx - ex * dy
            if den == 0.0:
                continue
            ax, ay = x0 - x, y0 - y
            t = (ax * ey - ay * ex) / den
            u = (ax * dy - ay * dx) / den
            if 0.0 <= u <= 1.0 and t > 0.0:
                out[i] = min(out[i], t)
    return out


@pytest.mark.parametrize("name", server.world_names())
def test_scan_matches_a_naive_ray_cast(name):
    spec = load_world(server.world_path(name))
    world = World(spec)
    for pose in placed(world, np.random.default_rng(7), 6):
        ranges = world.scan(0)
        assert ranges.dtype == np.float32 and ranges.shape == (LASER.count,)
        np.testing.assert_allclose(ranges, naive_scan(spec.segments(), *pose), atol=1e-4)


def test_a_beam_along_a_wall_line_gets_a_finite_range():
    # beam 0 of a laser facing exactly +y points exactly along +x: along the line of the
    # protrusion's top wall (y = 1.5), which it meets end-on at (4.0, 1.5), 1 m away. The
    # collinear segment's intersection is 0 * inf; it must not turn the range into NaN (a scan
    # with NaN is not a valid message)
    spec = load_world(server.world_path("room"))
    world = World(spec)
    pose = (3.0, 1.5, math.pi / 2)
    assert world.pose_problem(0, pose) is None
    world.reset(poses=[pose])
    ranges = world.scan(0)
    assert np.isfinite(ranges).all()
    assert ranges[0] == pytest.approx(1.0, abs=1e-6)
    fleet = World(spec, robots=8)  # a fleet's cast agrees
    fleet.reset(poses=[pose] + [(2.0 + 0.7 * k, 6.0, 0.0) for k in range(7)])
    together = fleet.scans()
    assert np.isfinite(together).all()
    assert together[0][0] == ranges[0]


def test_reusing_the_heading_gives_the_ranges_of_a_fresh_cast():
    # a laser keeps the beam directions of the last heading; a robot driving straight (or
    # turning back to a heading) must get what a fresh world gets
    spec = load_world(server.world_path("room"))
    world = World(spec)
    xmin, ymin, xmax, ymax = spec.bounds()
    rng = np.random.default_rng(11)
    yaw = 0.3
    for k in range(200):
        if k % 3 == 0:
            yaw = float(rng.choice([rng.uniform(-math.pi, math.pi), 0.0, math.pi / 2, math.pi]))
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        fresh = World(spec)._scan_walls(x, y, yaw)
        for got, want in zip(world._scan_walls(x, y, yaw), fresh, strict=True):
            np.testing.assert_array_equal(got, want)


def test_a_laser_refuses_what_it_cannot_cast():
    spec = load_world(server.world_path("room"))
    beams = LASER.bearings()
    lasers = laser.Laser(spec.segments(), beams, LASER.max_range, 0.25, robots=2)
    origins, yaws, centres = np.zeros((1, 2)), np.zeros(1), np.zeros((2, 2))
    for bad in (-1, 2):  # a robot row outside the laser's robots would read another's state
        with pytest.raises(ValueError, match="robot row"):
            lasers.cast(origins, yaws, np.array([bad], dtype=np.intp), centres)
    with pytest.raises(ValueError, match="one row per laser"):
        lasers.cast(origins, np.zeros(2), np.zeros(1, dtype=np.intp), centres)
    for bearings in (beams[:1], beams[::-1], np.linspace(-math.pi, math.pi, 360),
                     np.concatenate([beams[:10], beams[11:]])):
        with pytest.raises(ValueError, match="evenly spaced"):
            laser.Laser(spec.segments(), bearings, LASER.max_range, 0.25)
    good = lasers.cast(origins + [[3.0, 3.0]], yaws, np.zeros(1, dtype=np.intp), centres)
    assert good.shape == (1, LASER.count) and np.isfinite(good).all()
