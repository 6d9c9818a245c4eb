"""The vectorised laser against a plain per-beam ray cast, on random free poses of every shipped
world (the corridor property test in test_world.py checks a box analytically)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import server
from server.world import LASER, World, load_world


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
    segments = spec.segments()
    xmin, ymin, xmax, ymax = spec.bounds()
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 6:
        pose = (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), rng.uniform(-math.pi, math.pi))
        if world.pose_problem(0, pose):
            continue
        world.reset(poses=[pose])
        ranges = world.scan(0)
        assert ranges.dtype == np.float32 and ranges.shape == (LASER.count,)
        np.testing.assert_allclose(ranges, naive_scan(segments, *world.pose(0)), atol=1e-4)
        checked += 1
