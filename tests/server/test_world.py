"""server.world: world files, physics, odometry and the laser (pure, no zenoh)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import server
from server.world import LASER, ROBOT, World, WorldError, load_world, parse_world, wrap_angle


@pytest.fixture(scope="module")
def corridor():
    return load_world(server.world_path("corridor"))


@pytest.mark.parametrize("name", ["room", "maze", "corridor"])
def test_shipped_worlds_load(name):
    spec = load_world(server.world_path(name))
    assert spec.name == name
    assert spec.path == server.world_path(f"{name}.toml")
    assert len(spec.start_poses) >= (5 if name == "room" else 1)
    w = World(spec)
    for p in spec.start_poses:  # every start pose is free: scans see walls, nothing overlaps
        w.reset(poses=[p])
        r = w.scan(0)
        assert r.min() > ROBOT.radius


def test_worlds_are_closed():
    # from every start, no beam of a full turn escapes to max range beyond the bounds
    for name in ["room", "maze", "corridor"]:
        spec = load_world(server.world_path(name))
        xmin, ymin, xmax, ymax = spec.bounds()
        w = World(spec)
        for p in spec.start_poses:
            for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2):
                w.reset(poses=[(p[0], p[1], yaw)])
                r = w.scan(0)
                b = LASER.bearings() + yaw
                ex = p[0] + r * np.cos(b)
                ey = p[1] + r * np.sin(b)
                hit = r < LASER.max_range
                assert (ex[hit] >= xmin - 1e-3).all() and (ex[hit] <= xmax + 1e-3).all()
                assert (ey[hit] >= ymin - 1e-3).all() and (ey[hit] <= ymax + 1e-3).all()


def test_maze_is_tiered_with_goal_in_last_tier():
    spec = load_world(server.world_path("maze"))
    assert spec.task is None and spec.goal is not None  # a behaviour names its worlds
    assert spec.goal.center[1] > 6.6 and spec.pose[1] < 2.2


def test_world_path_resolution(tmp_path):
    assert server.world_path("room") == server.world_path("room.toml")
    assert {"room", "maze", "corridor"} <= set(server.world_names())
    with pytest.raises(FileNotFoundError, match="nowhere"):
        server.world_path("nowhere")


@pytest.mark.parametrize(
    "text, key, expected",
    [
        ('name = "x"\n[robot]\npose = [1, 2]\n', "robot.pose", "x, y, yaw"),
        ('task = "dance"\n', "task", "one of"),
        ("[robot]\npose = [1, 1, 0]\n", "walls", "at least one"),
        (
            "[robot]\npose = [1, 1, 0]\n[[walls]]\npoints = [[0, 0]]\n",
            "walls[0].points",
            "at least 2",
        ),
        (
            '[robot]\npose = [1, 1, 0]\n[[walls]]\npoints = [[0, 0], [1, "a"]]\n',
            "walls[0].points[1][1]",
            "finite number",
        ),
        (
            'task = "maze"\n[robot]\npose = [1, 1, 0]\n[[walls]]\npoints = [[0, 0], [3, 0]]\n',
            "goal",
            "required",
        ),
        (
            "[robot]\npose = [0.1, 0.1, 0]\n[[walls]]\npoints = [[0, 0], [3, 0]]\n",
            "robot.pose",
            "from every wall",
        ),
        ("this is = not toml [", "", "not valid TOML"),
    ],
)
def test_bad_world_files_name_file_key_and_expectation(tmp_path, text, key, expected):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(WorldError) as e:
        load_world(f)
    msg = str(e.value)
    assert str(f) in msg and key in msg and expected in msg


def test_missing_world_file(tmp_path):
    with pytest.raises(WorldError, match="not found"):
        load_world(tmp_path / "none.toml")


def test_scan_geometry_in_corridor(corridor):
    w = World(corridor)
    r = w.scan(0)
    assert r.dtype == np.float32 and r.shape == (LASER.count,)
    assert LASER.resolution == pytest.approx(math.pi / 359)
    assert r[0] == pytest.approx(1.0, abs=1e-5)  # right wall
    assert r[-1] == pytest.approx(1.0, abs=1e-5)  # left wall
    assert r[179] == LASER.max_range  # 9 m to the end wall: nothing within range


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(0.5, 9.5),
    y=st.floats(0.4, 1.6),
    yaw=st.floats(-math.pi, math.pi),
)
def test_scan_matches_analytic_box_distance(corridor, x, y, yaw):
    w = World(corridor)
    w.reset(poses=[(x, y, yaw)])
    r = w.scan(0).astype(np.float64)
    b = LASER.bearings() + yaw
    c, s = np.cos(b), np.sin(b)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (10.0 - x) / c, np.where(c < 0, -x / c, np.inf))
        ty = np.where(s > 0, (2.0 - y) / s, np.where(s < 0, -y / s, np.inf))
    expect = np.minimum(np.minimum(tx, ty), LASER.max_range)
    np.testing.assert_allclose(r, expect, atol=1e-4)


def test_commands_clamped_and_non_finite_rejected(corridor):
    w = World(corridor)
    w.set_command(0, 5.0, -9.0)
    assert w.command(0) == (ROBOT.max_vx, -ROBOT.max_va)
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="finite"):
            w.set_command(0, bad, 0.0)
    assert w.command(0) == (ROBOT.max_vx, -ROBOT.max_va)


def test_driving_forward_and_turning(corridor):
    w = World(corridor)
    w.set_command(0, 0.5, 0.0)
    for _ in range(10):
        w.step(0.1)
    assert w.pose(0) == pytest.approx((1.5, 1.0, 0.0), abs=1e-6)
    assert w.velocity(0) == pytest.approx((0.5, 0.0, 0.0), abs=1e-6)
    assert w.time == pytest.approx(1.0)
    w.set_command(0, 0.0, math.pi / 4)
    for _ in range(10):
        w.step(0.1)
    assert w.pose(0)[2] == pytest.approx(math.pi / 4, abs=1e-6)
    assert w.odom(0) == pytest.approx(w.pose(0), abs=1e-9)


def test_wall_stops_robot_sets_stall_and_backing_away_works(corridor):
    w = World(corridor)
    w.set_command(0, 0.5, 0.0)
    for _ in range(250):
        w.step(0.1)
    x = w.pose(0)[0]
    assert w.stall(0)
    assert 10.0 - 0.28 < x < 10.0 - ROBOT.radius
    assert w.velocity(0)[0] == pytest.approx(0.0, abs=0.02)
    w.set_command(0, 0.0, 1.0)  # turning in place at the wall: no stall
    w.step(0.1)
    assert not w.stall(0)
    w.set_command(0, -0.3, 0.0)
    w.step(0.5)
    assert not w.stall(0) and w.pose(0)[0] < x - 0.1


def test_oblique_contact_slides_along_wall(corridor):
    w = World(corridor)
    w.reset(poses=[(2.0, 1.0, -0.5)])  # heading into the right wall at an angle
    w.set_command(0, 0.4, 0.0)
    for _ in range(50):
        w.step(0.1)
    x, y, _ = w.pose(0)
    assert w.stall(0)
    assert y > ROBOT.radius  # never passes through
    assert x > 3.0  # slid along the wall instead of pinning


def test_deterministic_and_noise_is_seeded(corridor):
    def run(seed, noise):
        w = World(corridor, seed=seed, range_noise=noise, odom_noise=noise)
        out = []
        for k in range(60):
            w.set_command(0, 0.4, 0.3 * math.sin(k / 5))
            w.step(0.1)
            out.append((w.pose(0), w.odom(0), w.scan(0).tobytes()))
        return out

    assert run(1, 0.0) == run(2, 0.0)
    assert run(3, 0.05) == run(3, 0.05)
    assert run(3, 0.05) != run(4, 0.05)
    noisy = run(3, 0.05)[-1]
    assert noisy[0] != noisy[1]  # odometry drifted from the truth


def test_reset_restores_start(corridor):
    w = World(corridor)
    w.set_command(0, 0.5, 0.2)
    w.step(1.0)
    w.reset()
    assert w.pose(0) == corridor.pose and w.time == 0.0 and w.command(0) == (0.0, 0.0)
    w.set_odom(0, (1.0, 2.0, 3.0))
    assert w.odom(0) == (1.0, 2.0, 3.0)
    w.reset_odom(0)
    assert w.odom(0) == (0.0, 0.0, 0.0)


def test_several_robots_collide_and_see_each_other(corridor):
    w = World(corridor, robots=2)
    w.reset(poses=[(2.0, 1.0, 0.0), (4.0, 1.0, math.pi)])
    r = w.scan(0)
    assert r[179] == pytest.approx(2.0 - ROBOT.radius, abs=0.01)
    w.set_command(0, 0.5, 0.0)
    w.set_command(1, 0.5, 0.0)
    for _ in range(40):
        w.step(0.1)
    (x0, y0, _), (x1, y1, _) = w.pose(0), w.pose(1)
    assert math.hypot(x1 - x0, y1 - y0) > 2 * ROBOT.radius - 0.03
    assert w.stall(0) and w.stall(1)


def test_goal(corridor):
    spec = load_world(server.world_path("maze"))
    w = World(spec)
    assert not w.at_goal(0)
    w.reset(poses=[(*spec.goal.center, 0.0)])
    assert w.at_goal(0)
    assert not World(corridor).at_goal(0)


def test_wrap_angle():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


def test_parse_world_mapping():
    spec = parse_world(
        {
            "robot": {"pose": [2, 0.5, 0]},
            "walls": [{"points": [[0, 0], [4, 0], [4, 3]], "closed": True}],
        }
    )
    assert len(spec.segments()) == 3 and spec.task is None  # a world need not name a task


def test_set_pose_teleports_and_refuses_walls(corridor):
    w = World(corridor, robots=2)
    w.set_command(0, 0.5, 0.0)
    w.step(0.5)
    w.set_pose(0, (6.0, 1.2, math.pi), reset_odom=True)
    assert w.pose(0) == pytest.approx((6.0, 1.2, math.pi))
    assert w.odom(0) == pytest.approx(w.pose(0))
    assert w.command(0) == (0.0, 0.0) and w.velocity(0) == (0.0, 0.0, 0.0)
    assert not w.stall(0)
    w.step(0.1)  # the zeroed command holds it in place
    assert w.pose(0) == pytest.approx((6.0, 1.2, math.pi), abs=1e-6)
    w.set_pose(0, (4.0, 1.0, 0.0), reset_odom=False)
    assert w.odom(0)[0] == pytest.approx(6.0, abs=1e-6)
    for pose, why in [((5.0, 0.2, 0.0), "from a wall"), ((20.0, 1.0, 0.0), "outside"),
                      ((float("nan"), 1.0, 0.0), "finite"),
                      (w.pose(1), "overlaps robot 1")]:
        with pytest.raises(ValueError, match=why):
            w.set_pose(0, pose)
    assert w.pose(0) == pytest.approx((4.0, 1.0, 0.0))


# ---- free-space geometry (demonstration and corrective-round starts of any world file) ----


def test_clearance_and_inside():
    room = load_world(server.world_path("room"))
    assert not room.inside(0.5, 0.5)  # the room's cut-off corner (outside the polygon)
    assert room.inside(6.0, 4.5)
    x, y, _ = room.pose
    segs = room.segments()
    # clearance: the distance to the nearest segment (checked against a dense sampling of them)
    t = np.linspace(0.0, 1.0, 2001)[:, None]
    pts = np.concatenate([s[:2] + t * (s[2:] - s[:2]) for s in segs])
    assert room.clearance(x, y) == pytest.approx(np.hypot(pts[:, 0] - x, pts[:, 1] - y).min(),
                                                 abs=5e-3)
    assert room.clearance(x, y) > ROBOT.radius
    # an open wall encloses nothing: everywhere is inside; no wall at all: infinitely clear
    from server.world import Wall, WorldSpec

    line = WorldSpec("line", "wall-following", (0.0, 0.0, 0.0), walls=(Wall(((0, 0), (1, 0))),))
    assert line.clearance(2.0, 0.0) == pytest.approx(1.0) and line.inside(5.0, 5.0)
    empty = WorldSpec("empty", "wall-following", (0.0, 0.0, 0.0))
    assert empty.clearance(1.0, 2.0) == math.inf


def test_free_pose_is_inside_and_clear():
    from server.world import Pose, free_pose

    for name in ("room", "maze"):
        spec = load_world(server.world_path(name))
        rng = np.random.default_rng(3)
        for _ in range(30):
            p = free_pose(spec, rng)
            assert isinstance(p, Pose) and spec.clearance(p.x, p.y) >= 0.45
            assert spec.inside(p.x, p.y) and -math.pi <= p.yaw <= math.pi
    # no free space that far from the walls: None
    corridor = load_world(server.world_path("corridor"))
    assert free_pose(corridor, np.random.default_rng(0), clearance=50.0) is None


def test_sample_pose_is_near_the_path_and_clear():
    from server.world import sample_pose

    spec = load_world(server.world_path("maze"))
    rng = np.random.default_rng(0)
    visited = [(1.0, 1.1, 0.0), (5.0, 3.3, math.pi)]
    for _ in range(20):
        p = sample_pose(spec, visited, rng, turn=0.6)
        assert p is not None and spec.clearance(p.x, p.y) >= 0.45
        assert min(math.hypot(p.x - v[0], p.y - v[1]) for v in visited) < 1.5
    assert sample_pose(spec, [], rng) is None


def test_scaled_copy_of_a_world():
    maze = load_world(server.world_path("maze"))
    big = maze.scaled(1.2)
    assert big.name == "mazex1.2" and big.path is None and big.task == maze.task
    assert big.walls[1].points[1] == (8.7 * 1.2, 2.2 * 1.2)
    assert big.start_poses[0] == (1.0 * 1.2, 1.1 * 1.2, 0.0)
    assert big.goal.center == (1.0 * 1.2, 7.7 * 1.2) and big.goal.radius == maze.goal.radius
    assert len(big.start_poses) == len(maze.start_poses)
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="scale factor"):
            maze.scaled(bad)


def test_shipped_worlds_name_no_task_and_an_older_files_task_is_still_read():
    """Worlds no longer name a task (a behaviour names its worlds); a user's older world file
    with ``task = ...`` is still read, its task kept as a hint."""
    for name in server.world_names():
        assert load_world(server.world_path(name)).task is None, name
    old = parse_world({"name": "mine", "task": "wall-following", "robot": {"pose": [2, 0.5, 0]},
                       "walls": [{"points": [[0, 0], [4, 0], [4, 3]], "closed": True}]})
    assert old.task == "wall-following" and old.scaled(1.2).task == "wall-following"


def test_free_space_is_outside_the_boxes_within_the_outer_wall():
    """A world with boxes, pillars or an island drawn as closed polylines inside its outer
    wall: its free space is inside the outer wall and outside each of them (so free-space
    poses, ``round_free`` and free demonstrations, exist there)."""
    from server.world import free_pose

    clutter = load_world(server.world_path("clutter-room"))
    assert clutter.inside(5.0, 1.0) and not clutter.inside(2.5, 2.4)  # in box 1.2 x 1.0 m
    assert not clutter.inside(-1.0, 1.0)  # outside the outer wall
    ring = load_world(server.world_path("eval-room-ring"))
    assert ring.inside(3.0, 0.7) and not ring.inside(7.0, 3.5)  # round the island, not on it
    rng = np.random.default_rng(0)
    poses = [free_pose(clutter, rng) for _ in range(20)]
    assert all(p is not None and clutter.inside(p.x, p.y) and clutter.clearance(p.x, p.y) >= 0.45
               for p in poses)
