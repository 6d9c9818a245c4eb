"""The fleet's laser cast together (``World.scans``, ``server.laser``) against the plain cast of
one robot at a time: the same float32 ranges, bit for bit, in every shipped world, with robots
crowded together, overlapping, behind walls and at the edges of each other's field of view."""

from __future__ import annotations

import math

import numpy as np
import pytest

import server
from server import laser
from server.world import LASER, ROBOT, World, load_world


def random_fleet(spec, n, rng, min_gap=0.3):
    probe = World(spec)
    x0, y0, x1, y1 = spec.bounds()
    poses = []
    for _ in range(50_000):
        if len(poses) == n:
            break
        p = (rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-math.pi, math.pi))
        if probe.pose_problem(0, p):
            continue
        # closer than a robot's diameter on purpose: robots overlap after collisions
        if any(math.hypot(p[0] - q[0], p[1] - q[1]) < min_gap for q in poses):
            continue
        poses.append(p)
    return poses


def one_at_a_time(world: World) -> np.ndarray:
    n = world.n_robots
    centres = np.asarray([world.pose(i)[:2] for i in range(n)])
    out = np.empty((n, LASER.count), dtype=np.float32)
    for i in range(n):
        x, y, yaw = world.pose(i)
        r, dc, ds = world._scan_walls(x, y, yaw)
        out[i] = laser.robots_dense(r, (x, y), dc, ds, np.delete(centres, i, axis=0),
                                    ROBOT.radius, LASER.max_range)
    return out


@pytest.mark.parametrize("name", ["room", "maze", "corridor", "eval-room-ring"])
@pytest.mark.parametrize("n", [2, 7, 40])
def test_scans_equal_the_one_at_a_time_cast(name, n):
    spec = load_world(server.world_path(name))
    rng = np.random.default_rng(n)
    poses = random_fleet(spec, n, rng)
    world = World(spec, robots=len(poses))
    world.reset(poses=poses)
    for _ in range(3):  # and after moving (collisions push robots apart)
        together = world.scans()
        assert together.dtype == np.float32 and together.shape == (len(poses), LASER.count)
        np.testing.assert_array_equal(together, one_at_a_time(world))
        for i in (0, len(poses) - 1):
            np.testing.assert_array_equal(world.scan(i), together[i])
        for i in range(len(poses)):
            world.set_command(i, 0.4, 0.6)
        world.step(0.5)


def test_a_robot_in_front_shortens_the_beams_it_covers():
    spec = load_world(server.world_path("room"))
    world = World(spec, robots=2)
    world.reset(poses=[(3.0, 3.0, 0.0), (5.0, 3.0, 0.0)])
    alone = World(spec)
    alone.reset(poses=[(3.0, 3.0, 0.0)])
    ranges, empty = world.scans()[0], alone.scan(0)
    mid = LASER.count // 2
    assert ranges[mid] == pytest.approx(2.0 - ROBOT.radius, abs=1e-3)  # beam at +0.25 deg
    half = math.asin(ROBOT.radius / 2.0)
    covered = np.abs(LASER.bearings()) < half - LASER.resolution
    assert np.all(ranges[covered] < empty[covered])
    np.testing.assert_array_equal(ranges[~(np.abs(LASER.bearings()) < half + LASER.resolution)],
                                  empty[~(np.abs(LASER.bearings()) < half + LASER.resolution)])


def test_range_noise_is_drawn_in_the_order_of_scan_calls():
    spec = load_world(server.world_path("room"))
    poses = random_fleet(spec, 12, np.random.default_rng(3))
    a = World(spec, robots=12, seed=4, range_noise=0.02)
    b = World(spec, robots=12, seed=4, range_noise=0.02)
    a.reset(poses=poses)
    b.reset(poses=poses)
    np.testing.assert_array_equal(a.scans(), np.stack([b.scan(i) for i in range(12)]))


def test_robots_driving_straight_or_standing_keep_the_ranges_of_a_fresh_cast():
    # the fleet keeps each robot's beam directions while its heading stays the same: robots
    # standing, driving straight, turning, teleported, in changing subsets of lasers
    spec = load_world(server.world_path("room"))
    poses = random_fleet(spec, 16, np.random.default_rng(5))
    world = World(spec, robots=len(poses))
    world.reset(poses=poses)
    for k in range(6):
        np.testing.assert_array_equal(world.scans(), one_at_a_time(world))
        subset = list(range(k % 2, len(poses), 2)) + [0]
        np.testing.assert_array_equal(world.scans(subset), one_at_a_time(world)[subset])
        for i in range(len(poses)):
            world.set_command(i, 0.0 if i % 3 == 0 else 0.3, 0.5 if i % 3 == 1 and k % 2 else 0.0)
        if k == 3:
            world.set_pose(2, (*poses[2][:2], poses[2][2] + 1.0))
        world.step(0.1)
