"""In-process harness: ``rhbl train``. No zenoh: steps ``server.world.World`` directly at 10 Hz.

One step: scan -> (teacher label | tree prediction) -> world.set_command -> world.step(dt), with
the same feature, action, policy and learning code the zenoh processes run.

    spec = load_world(path)
    learner = make_learner(spec.task, spawn="winner")             # or DemonstrationLearner(...)
    traj = train(spec, learner, seconds=300, seed=0)               # the scripted teacher demonstrates
    traj = run(spec, TreePolicy.from_learner(learner), pose, seconds=120, teacher=make_policy(...))
    traj.poses, traj.stalls, traj.actions, traj.side, traj.teacher_actions, traj.dt

``rhbl train --world PATH --seconds S --out SNAPSHOT [--resume SNAPSHOT] [--start x,y,yaw]
[--seed N] [--perturb P] [--spawn all|winner] ...`` writes the snapshot with its metadata.
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from client.behaviour.actions import DEFAULT_ACTIONS, ActionSet
from client.behaviour.features import FEATURES, FeatureSpec
from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.policies import Demonstrator, make_policy, takes_over
from lab import metrics
from server.world import World, WorldSpec, load_world

__all__ = [
    "DT",
    "TRAINING",
    "Trajectory",
    "add_arguments",
    "add_compact_arguments",
    "compact_overrides",
    "followed_side",
    "main",
    "make_learner",
    "parse_pose",
    "parse_scales",
    "scale_world",
    "resolve_world",
    "run",
    "train",
]

log = logging.getLogger(__name__)

DT = 0.1  # 10 Hz, as the processes run

# Default training recipe per task (docs/experiments.md says how it was chosen).
TRAINING: dict[str, dict] = {
    # reactive teacher; one demonstration from each start pose of the world, then (room) 30 s
    # demonstrations from random poses anywhere in the free space (random heading), then
    # corrective (DAgger) rounds: the tree drives from each start pose, the teacher labels.
    # The maze's rounds run in copies of the world scaled by 0.85 and 1.2 first, then in the
    # world itself (narrower and wider corridors than the one drawn), each round also from 4
    # random free-space poses (corners and tips met at other angles): unseen mazes 75% -> 87%,
    # collisions 41 -> 4 over 12 of them, trees 3x; the room's do neither (with range noise
    # its success fell from 100% to 97%; docs/experiments.md)
    # No "compact" step by default: every compaction measured lost closed-loop success on some
    # world for some seed (docs/experiments.md, "Compact trees (issue)"); e.g. {"method":
    # "prune", "class_weight": "balanced", "max_nodes": 200} (rhbl train --compact ...) makes the
    # tree compact itself on every vector it learned, last
    "wall-following": {"features": "wall", "perturb": 0.05, "seconds": 600.0,
                       "tree": {"spawn": "winner"}, "stride": 1, "min_delta": 0.0,
                       "starts": "free", "segment": 60.0, "random_segment": 0.5,
                       "rounds": 3, "round_seconds": 60.0, "takeover": 0.3},
    "maze": {"features": "wall", "perturb": 0.05, "seconds": 600.0,
             "tree": {"spawn": "winner"}, "stride": 1, "min_delta": 0.0,
             "starts": "world", "segment": 240.0, "random_segment": 0.0,
             "rounds": 6, "round_seconds": 240.0, "takeover": 0.3,
             "round_scales": (0.85, 1.2), "round_free": 4},
}


def followed_side(task: str) -> str | None:
    return "right" if task == "wall-following" else None


def resolve_world(path_or_name: str) -> WorldSpec:
    p = Path(path_or_name)
    if not p.exists():
        import server

        if hasattr(server, "world_path"):
            p = Path(server.world_path(path_or_name))
        else:  # pragma: no cover
            p = Path(__file__).resolve().parent.parent / "server" / "worlds" / f"{path_or_name}.toml"
    return load_world(p)


def _floats(text: str, what: str) -> tuple[float, ...]:
    """Comma-separated numbers of a CLI value; ArgumentTypeError saying ``what`` they must be."""
    try:
        return tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{what}, got {text!r}") from exc


def parse_pose(text: str) -> tuple[float, float, float]:
    vals = _floats(text, "pose must be x,y,yaw numbers")
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"pose must be x,y,yaw (3 numbers), got {text!r}")
    return vals  # type: ignore[return-value]


def parse_scales(text: str) -> tuple[float, ...]:
    """``--round-scales``: comma-separated positive factors, or 'none'."""
    if text.strip().lower() in ("", "none"):
        return ()
    vals = _floats(text, "scales must be numbers like 0.85,1.2 or 'none'")
    if not all(v > 0 and math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"scales must be positive, got {text!r}")
    return vals


@dataclass
class Trajectory:
    dt: float
    start: tuple[float, float, float]
    poses: list = field(default_factory=list)
    stalls: list = field(default_factory=list)
    actions: list = field(default_factory=list)       # what was executed
    labels: list = field(default_factory=list)        # teacher labels (training) or []
    teacher_actions: list = field(default_factory=list)  # teacher's choice on these states
    side: list = field(default_factory=list)          # followed-side wall distance
    segments: list = field(default_factory=list)      # start pose of each demonstration
    learned: int = 0
    wall_time: float = 0.0

    def metrics(self, goal=None) -> dict:
        return metrics.episode_metrics(
            self.poses, self.stalls, self.actions, self.dt,
            side=self.side if self.side else None, goal=goal,
            teacher_actions=self.teacher_actions or None, start=self.start)


def make_learner(task: str, features: FeatureSpec | str | None = None,
                 actions: ActionSet = DEFAULT_ACTIONS, stride: int | None = None,
                 min_delta: float | None = None, **tree_params) -> DemonstrationLearner:
    """A learner with the task's default recipe; keyword arguments override it."""
    recipe = TRAINING.get(task, TRAINING["wall-following"])
    if features is None:
        features = recipe["features"]
    if isinstance(features, str):
        features = FEATURES[features]
    params = dict(recipe["tree"])
    params.update(tree_params)
    params.setdefault("record", bool(recipe.get("compact")))  # compaction needs the vectors
    return DemonstrationLearner(
        features, actions, task=task,
        stride=recipe["stride"] if stride is None else stride,
        min_delta=recipe["min_delta"] if min_delta is None else min_delta,
        **params)


def _step_world(world: World, traj: Trajectory, actions: ActionSet, name: str, side: str | None,
                ranges) -> None:
    vx, va = actions[name]
    world.set_command(0, vx, va)
    world.step(traj.dt)
    traj.actions.append(name)
    traj.poses.append(world.pose(0))
    traj.stalls.append(world.stall(0))
    if side is not None:
        traj.side.append(metrics.side_distance(ranges, side))


def _clearance(segs: np.ndarray, x: float, y: float) -> float:
    """Distance from (x, y) to the nearest wall segment."""
    if len(segs) == 0:
        return float("inf")
    a = segs[:, 0:2]
    e = segs[:, 2:4] - a
    ee = np.einsum("ij,ij->i", e, e)
    p = np.array([x, y])
    t = np.clip(np.einsum("ij,ij->i", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    d = a + t[:, None] * e - p
    return float(np.sqrt(np.einsum("ij,ij->i", d, d)).min())


def sample_pose(spec: WorldSpec, visited, rng, jitter: float = 0.3, turn: float = math.pi,
                clearance: float = 0.45, tries: int = 50) -> tuple[float, float, float] | None:
    """A fresh demonstration start near a pose the teacher already visited (so it lies in the
    reachable free space of any world, no map-specific code): position jittered by ``jitter``
    metres (normal), heading turned by up to +/- ``turn`` rad (uniform; pi = any heading), at
    least ``clearance`` metres from every wall. None when no such pose was found."""
    if not len(visited):
        return None
    segs = spec.segments()
    for _ in range(tries):
        x, y, yaw = visited[int(rng.integers(len(visited)))]
        x += float(rng.normal(0.0, jitter))
        y += float(rng.normal(0.0, jitter))
        yaw += float(rng.uniform(-turn, turn))
        yaw = math.atan2(math.sin(yaw), math.cos(yaw))
        if _clearance(segs, x, y) >= clearance:
            return (round(x, 3), round(y, 3), round(yaw, 4))
    return None


def _inside(spec: WorldSpec, x: float, y: float) -> bool:
    """True when (x, y) lies inside every closed wall polyline of the world (even-odd rule;
    a world with no closed wall: inside its bounding box)."""
    for w in spec.walls:
        if not w.closed:
            continue
        inside = False
        for x0, y0, x1, y1 in w.segments():
            if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                inside = not inside
        if not inside:
            return False
    return True


def free_pose(spec: WorldSpec, rng, clearance: float = 0.45,
              tries: int = 200) -> tuple[float, float, float] | None:
    """A demonstration start anywhere in the world's free space: position uniform over the
    walls' bounding box, inside the closed walls and at least ``clearance`` metres from every
    wall, heading uniform. Needs no map-specific code (any world file). None if none found."""
    segs = spec.segments()
    x0, y0, x1, y1 = spec.bounds()
    for _ in range(tries):
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        if _clearance(segs, x, y) >= clearance and _inside(spec, x, y):
            return (round(x, 3), round(y, 3), round(float(rng.uniform(-math.pi, math.pi)), 4))
    return None


def demonstration_starts(spec: WorldSpec, starts: str = "world") -> list[tuple[float, float, float]]:
    """The fixed part of a training run's schedule: ``"default"`` = the world's pose only,
    ``"world"`` = every start pose of the world (default pose first)."""
    if starts == "default":
        return [tuple(spec.pose)]
    if starts in ("world", "free"):
        return [tuple(p) for p in spec.start_poses]
    raise ValueError(f"starts must be 'default', 'world' or 'free', got {starts!r}")


def train(spec: WorldSpec, learner: DemonstrationLearner, seconds: float, seed: int = 0,
          perturb: float | None = None, start: tuple[float, float, float] | None = None,
          range_noise: float = 0.0, odom_noise: float = 0.0, dt: float = DT,
          policy=None, starts: str | None = None, segment: float | None = None,
          random_starts: float | None = None, turn: float | None = None,
          consistent: bool | None = None, rounds: int | None = None,
          round_seconds: float | None = None, takeover: float | None = None,
          round_free: int | None = None, augment: int | None = None,
          augment_scale: float | None = None,
          round_scales: tuple[float, ...] | None = None,
          compact: dict | None = None) -> Trajectory:
    """One training run: the world's scripted teacher demonstrates for ``seconds`` (sim time, in
    total) while ``learner`` observes every step.

    The run is a sequence of demonstrations (the teacher restarts; the tree keeps growing):
    first one from each pose of ``starts`` ("world": every start pose of the world, "default":
    its default pose), each until the goal (maze) or ``segment`` seconds; the rest of the time
    from poses sampled near the teacher's earlier path (``sample_pose``: jittered position,
    heading turned by up to ``turn`` rad), each for ``segment * random_starts`` seconds or until
    the goal. ``start`` given: a single demonstration from there (a corrective one).

    ``rounds`` > 0 then adds corrective rounds (DAgger, the paper's "corrective demonstration"
    automated): in each round the LEARNED tree drives from every start pose for
    ``round_seconds`` (or until the goal) while the teacher labels every visited state, and the
    tree learns those labels (it only grows where it disagrees). The teacher takes over the
    wheels while any beam is closer than ``takeover`` metres (as the server's arbitration lets a
    teacher override a controller), so a round never drives into a wall."""
    task = spec.task
    recipe = TRAINING.get(task, TRAINING["wall-following"])
    perturb = recipe["perturb"] if perturb is None else perturb
    starts = recipe.get("starts", "default") if starts is None else starts
    segment = recipe.get("segment", seconds) if segment is None else segment
    random_starts = recipe.get("random_segment", 1.0) if random_starts is None else random_starts
    turn = recipe.get("turn", math.pi) if turn is None else turn
    consistent = recipe.get("consistent", False) if consistent is None else consistent
    rounds = int(recipe.get("rounds", 0) if rounds is None else rounds)
    round_seconds = recipe.get("round_seconds", segment) if round_seconds is None else round_seconds
    takeover = recipe.get("takeover", 0.0) if takeover is None else takeover
    round_free = int(recipe.get("round_free", 0) if round_free is None else round_free)
    augment = int(recipe.get("augment", 0) if augment is None else augment)
    augment_scale = float(recipe.get("augment_scale", 1.3) if augment_scale is None else augment_scale)
    round_scales = tuple(float(v) for v in (recipe.get("round_scales", ()) if round_scales is None
                                            else round_scales))
    policy = policy or make_policy(task, actions=learner.actions)
    rng = np.random.default_rng(seed)
    aug = _Augmenter(policy, augment, augment_scale, seed) if augment > 0 else None
    demo = Demonstrator(policy, perturb=perturb, rng=rng, dt=dt)
    fixed = [tuple(start)] if start is not None else demonstration_starts(spec, starts)
    if start is not None:
        segment = seconds
    world = World(spec, robots=1, seed=seed, range_noise=range_noise, odom_noise=odom_noise)
    first = fixed[0]
    traj = Trajectory(dt=dt, start=first)
    side = followed_side(task)
    total = int(round(seconds / dt))
    done = 0
    t0 = time.perf_counter()
    k = 0
    while done < total:
        if k < len(fixed) or random_starts <= 0:
            pose, limit = fixed[k % len(fixed)], segment
        else:
            if starts == "free":
                pose = free_pose(spec, rng) or fixed[k % len(fixed)]
            else:
                pose = sample_pose(spec, traj.poses, rng, turn=turn) or fixed[k % len(fixed)]
            limit = segment * random_starts
        world.reset(poses=[pose], seed=seed * 1000 + k)
        demo.reset()
        if k > 0 and hasattr(policy, "resume_following"):
            policy.resume_following()
        traj.segments.append(list(pose))
        steps = min(total - done, max(1, int(round(limit / dt))))
        for _ in range(steps):
            ranges = world.scan(0)
            odom = world.odom(0)
            label, executed = demo.step(ranges, odom)
            traj.labels.append(label)
            if (not consistent or demo.consistent) and learner.observe(ranges, odom[2], label):
                traj.learned += 1
            if aug is not None:
                traj.learned += aug.offer(learner, ranges, odom)
            _step_world(world, traj, learner.actions, executed, side, ranges)
            done += 1
            if spec.goal is not None and world.at_goal(0):
                break
        k += 1
    demo_vectors = traj.learned
    round_stats = []
    if start is not None:
        rounds = 0  # a corrective demonstration from a given pose: no rounds
    if rounds > 0:
        # scaled copies first, the training world last (its corrections are the latest)
        for f in round_scales:
            scaled = scale_world(spec, f)
            for st in _corrective_rounds(scaled, learner, policy, scaled.start_poses, rounds,
                                         round_seconds, takeover, seed, range_noise, odom_noise,
                                         dt, traj, free=round_free, rng=rng, aug=aug):
                round_stats.append(dict(st, scale=f))
        round_stats += _corrective_rounds(spec, learner, policy, fixed, rounds, round_seconds,
                                          takeover, seed, range_noise, odom_noise, dt, traj,
                                          free=round_free, rng=rng, aug=aug)
    compact = dict(recipe.get("compact") or {}) if compact is None else dict(compact)
    compaction = None
    if compact.get("method"):
        if not getattr(learner, "recording", False):
            log.warning("not compacting: the learner kept no vectors (make it with record=True)")
        else:
            compaction = learner.compact(**compact)
    traj.wall_time = time.perf_counter() - t0
    learner.session = {"world": spec.name, "world_path": str(spec.path) if spec.path else None,
                       "seconds": seconds, "seed": seed, "perturb": perturb,
                       "start": list(first), "starts": starts if start is None else "given",
                       "demonstrations": len(traj.segments), "segment": segment,
                       "consistent": consistent, "demonstration_vectors": demo_vectors,
                       "rounds": rounds, "round_seconds": round_seconds if rounds else None,
                       "takeover": takeover if rounds else None, "round_stats": round_stats,
                       "round_free": round_free if rounds else None,
                       "round_scales": list(round_scales) if rounds else None,
                       "augment": augment, "augment_scale": augment_scale if augment else None,
                       "range_noise": range_noise, "odom_noise": odom_noise,
                       "vectors": traj.learned, "compaction": compaction}
    return traj


def scale_world(spec: WorldSpec, factor: float) -> WorldSpec:
    """A copy of ``spec`` uniformly scaled about the origin by ``factor``: wall points, start
    poses (headings kept) and the goal centre (radius kept). Works for any world file."""
    import dataclasses

    from server.world import Goal, Wall

    if factor <= 0:
        raise ValueError(f"scale factor must be > 0, got {factor}")

    def pose(p):
        return (p[0] * factor, p[1] * factor, p[2])

    walls = tuple(Wall(tuple((x * factor, y * factor) for x, y in w.points), w.closed)
                  for w in spec.walls)
    goal = None if spec.goal is None else Goal(
        (spec.goal.center[0] * factor, spec.goal.center[1] * factor), spec.goal.radius)
    return dataclasses.replace(spec, name=f"{spec.name}x{factor:g}", pose=pose(spec.pose),
                               starts=tuple(pose(p) for p in spec.starts), walls=walls, goal=goal,
                               path=None)


class _Augmenter:
    """Scale augmentation (see ``train``): offers each state again with the scan scaled."""

    def __init__(self, policy, copies: int, scale: float, seed: int):
        label = getattr(policy, "reactive", None)
        if label is None:
            raise ValueError("augment needs a teacher with a scan-only label (reactive)")
        if scale < 1.0:
            raise ValueError(f"augment_scale must be >= 1, got {scale}")
        self.label, self.copies = label, int(copies)
        self.log_scale = math.log(scale)
        self.rng = np.random.default_rng(seed + 7919)

    def offer(self, learner: DemonstrationLearner, ranges, odom) -> int:
        r = np.asarray(ranges, dtype=np.float64)
        n = 0
        for _ in range(self.copies):
            scaled = r * math.exp(float(self.rng.uniform(-self.log_scale, self.log_scale)))
            n += bool(learner.observe(scaled, odom[2], self.label(scaled)))
        return n


def _corrective_rounds(spec: WorldSpec, learner: DemonstrationLearner, policy, poses, rounds: int,
                       seconds: float, takeover: float, seed: int, range_noise: float,
                       odom_noise: float, dt: float, traj: Trajectory, free: int = 0,
                       rng=None, aug=None) -> list[dict]:
    """DAgger rounds (see ``train``): the tree drives, the teacher labels; per round the number
    of steps, disagreements (learned labels that differed from the tree's choice) and takeovers.
    ``free`` > 0: each round also drives from that many fresh poses anywhere in the free space
    (``free_pose``), so the corrections cover states the start poses never lead to."""
    world = World(spec, robots=1, seed=seed, range_noise=range_noise, odom_noise=odom_noise)
    tree = TreePolicy.from_learner(learner)
    side = followed_side(spec.task)
    stats = []
    for r in range(rounds):
        steps = disagree = took = 0
        extra = [p for p in (free_pose(spec, rng) for _ in range(free)) if p is not None] \
            if free > 0 and rng is not None else []
        for k, pose in enumerate([*poses, *extra]):
            world.reset(poses=[pose], seed=seed * 1000 + 500 + r * 50 + k)
            policy.reset()
            for _ in range(max(1, int(round(seconds / dt)))):
                ranges = world.scan(0)
                odom = world.odom(0)
                label = policy.act(ranges, odom)
                drive = tree.act(ranges, odom)
                if drive != label:
                    disagree += 1
                if learner.observe(ranges, odom[2], label):
                    traj.learned += 1
                if aug is not None:
                    traj.learned += aug.offer(learner, ranges, odom)
                if takes_over(ranges, takeover):
                    drive = label
                    took += 1
                _step_world(world, traj, learner.actions, drive, side, ranges)
                traj.labels.append(label)
                steps += 1
                if spec.goal is not None and world.at_goal(0):
                    break
        stats.append({"round": r + 1, "steps": steps, "disagreements": disagree, "takeovers": took,
                      "nodes": learner.nodes})
        log.debug("round %d: %s", r + 1, stats[-1])
    return stats


def run(spec: WorldSpec, driver, start, seconds: float, seed: int = 0, teacher=None,
        range_noise: float = 0.0, odom_noise: float = 0.0, dt: float = DT,
        stop_at_goal: bool = True) -> Trajectory:
    """Drive ``driver`` (anything with ``act(ranges, pose)``: a TreePolicy or a scripted policy)
    from ``start`` for ``seconds``; ``teacher`` (optional) is asked what it would do on each
    state (teacher agreement). Stops at the goal, when the world has one."""
    actions = getattr(driver, "actions", DEFAULT_ACTIONS)
    world = World(spec, robots=1, seed=seed, range_noise=range_noise, odom_noise=odom_noise)
    start = tuple(float(v) for v in start)
    world.reset(poses=[start])
    driver.reset()
    if teacher is not None:
        teacher.reset()
    traj = Trajectory(dt=dt, start=start)
    side = followed_side(spec.task)
    t0 = time.perf_counter()
    for _ in range(int(round(seconds / dt))):
        ranges = world.scan(0)
        odom = world.odom(0)
        name = driver.act(ranges, odom)
        if teacher is not None:
            traj.teacher_actions.append(teacher.act(ranges, odom))
        _step_world(world, traj, actions, name, side, ranges)
        if stop_at_goal and spec.goal is not None and world.at_goal(0):
            break
    traj.wall_time = time.perf_counter() - t0
    return traj


# ------------------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", required=True, help="world file (or a shipped world's name)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="sim seconds of demonstration (default: the task's recipe, 300)")
    parser.add_argument("--out", required=True, help="snapshot to write")
    parser.add_argument("--resume", default=None,
                        help="continue training this snapshot (a corrective demonstration)")
    parser.add_argument("--start", type=parse_pose, default=None,
                        help="start pose x,y,yaw (default: the world's pose); use the pose of an "
                             "oscillation loop reported by 'rhbl evaluate --json'")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--perturb", type=float, default=None,
                        help="fraction of time a random action is executed (default 0.2)")
    parser.add_argument("--features", choices=sorted(FEATURES), default=None,
                        help="feature spec (default: the task's)")
    parser.add_argument("--spawn", choices=["all", "winner"], default=None,
                        help="spawn rule (default: winner; 'all' is the paper's literal rule)")
    parser.add_argument("--distance", choices=["squared", "euclidean"], default=None)
    parser.add_argument("--min-radius", type=float, default=None)
    parser.add_argument("--max-nodes", type=int, default=None)
    parser.add_argument("--stride", type=int, default=None, help="learn every n-th step")
    parser.add_argument("--starts", choices=["default", "world", "free"], default=None,
                        help="demonstrate from the world's default pose only, or from each of its "
                             "start poses in turn ('free': then from poses anywhere in the free "
                             "space, random heading) (default: the task's recipe)")
    parser.add_argument("--segment", type=float, default=None,
                        help="sim seconds per demonstration before the teacher restarts")
    parser.add_argument("--random-segment", type=float, default=None,
                        help="after the start poses: demonstrations from poses near the teacher's "
                             "path, each this fraction of --segment (0: cycle the start poses)")
    parser.add_argument("--consistent", action="store_true", default=None,
                        help="learn only labels that do not depend on the teacher's memory")
    parser.add_argument("--rounds", type=int, default=None,
                        help="corrective (DAgger) rounds after the demonstration: the tree drives "
                             "from every start pose, the teacher labels (default: the recipe's)")
    parser.add_argument("--round-seconds", type=float, default=None,
                        help="sim seconds per start pose in each corrective round")
    parser.add_argument("--round-free", type=int, default=None,
                        help="corrective rounds also drive from this many random free-space poses "
                             "(default: the recipe's: maze 4, wall following 0)")
    parser.add_argument("--takeover", type=float, default=None,
                        help="in corrective rounds the teacher drives while a beam is closer "
                             "than this (m; 0 = never)")
    parser.add_argument("--augment", type=int, default=None,
                        help="scale augmentation: offer every labelled state N more times with the "
                             "scan scaled (a wider/narrower copy of the world; default: recipe's)")
    parser.add_argument("--augment-scale", type=float, default=None,
                        help="largest scale factor of --augment (and 1/it the smallest)")
    parser.add_argument("--round-scales", type=parse_scales, default=None, metavar="F,F",
                        help="repeat the corrective rounds in the training world scaled by these "
                             "factors first ('none': only the world itself; default: the "
                             "recipe's: maze 0.85,1.2, wall following none)")
    parser.add_argument("--range-noise", type=float, default=0.0)
    parser.add_argument("--odom-noise", type=float, default=0.0)
    add_compact_arguments(parser)


def add_compact_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--compact", choices=list(COMPACT_CHOICES), default=None,
                        help="last step: compact the tree on the vectors it learned (rhbl.compact;"
                             " prune-balanced: errors weighted per label; default: the recipe's, "
                             "none)")
    parser.add_argument("--compact-max-nodes", type=int, default=None,
                        help="prune: delete the weakest spheres until at most N are left")
    parser.add_argument("--compact-max-error", type=float, default=None,
                        help="prune: fraction of the learned vectors whose errors it may add")


COMPACT_CHOICES = {"none": {}, "exact": {"method": "exact"}, "prune": {"method": "prune"},
                   "prune-balanced": {"method": "prune", "class_weight": "balanced"}}


def compact_overrides(task: str, args) -> dict | None:
    """The ``compact`` argument of ``train`` from the CLI options (None: the recipe's)."""
    method = getattr(args, "compact", None)
    n, e = getattr(args, "compact_max_nodes", None), getattr(args, "compact_max_error", None)
    if method is None and n is None and e is None:
        return None
    if method == "none":
        return {}
    out = dict(TRAINING.get(task, TRAINING["wall-following"]).get("compact") or {})
    if method is not None:
        out = dict(COMPACT_CHOICES[method])
    if n is not None:
        out["max_nodes"] = n
    if e is not None:
        out["max_error"] = e
    if out.get("method") == "exact" and len(out) > 1:
        raise ValueError("--compact-max-nodes/--compact-max-error apply to --compact prune only")
    return out


def _tree_overrides(args) -> dict:
    out = {}
    for key in ("spawn", "distance", "min_radius", "max_nodes"):
        v = getattr(args, key, None)
        if v is not None:
            out[key] = v
    return out


def main(args) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    spec = resolve_world(args.world)
    if args.resume:
        learner = DemonstrationLearner.resume(
            args.resume, features=FEATURES[args.features] if args.features else None)
    else:
        compact = compact_overrides(spec.task, args)
        learner = make_learner(spec.task, features=args.features, stride=args.stride,
                               record=bool(compact if compact is not None else TRAINING.get(
                                   spec.task, TRAINING["wall-following"]).get("compact")),
                               **_tree_overrides(args))
    seconds = args.seconds if args.seconds is not None else TRAINING.get(
        spec.task, TRAINING["wall-following"])["seconds"]
    traj = train(spec, learner, seconds, seed=args.seed, perturb=args.perturb, start=args.start,
                 range_noise=args.range_noise, odom_noise=args.odom_noise,
                 starts=getattr(args, "starts", None), segment=getattr(args, "segment", None),
                 random_starts=getattr(args, "random_segment", None),
                 consistent=getattr(args, "consistent", None),
                 rounds=getattr(args, "rounds", None), round_seconds=getattr(args, "round_seconds", None),
                 takeover=getattr(args, "takeover", None),
                 round_free=getattr(args, "round_free", None),
                 augment=getattr(args, "augment", None),
                 augment_scale=getattr(args, "augment_scale", None),
                 round_scales=getattr(args, "round_scales", None),
                 compact={} if args.resume else compact_overrides(spec.task, args))
    out = learner.save(args.out)
    m = traj.metrics()
    print(f"trained on {spec.name} ({spec.task}) for {seconds:g} s from {list(traj.start)}: "
          f"{len(traj.segments)} demonstrations + {learner.session.get('rounds', 0)} corrective "
          f"rounds{_scales_note(learner.session.get('round_scales'))}, {traj.learned} vectors "
          f"learned, tree {_size_note(learner.session.get('compaction'))}{learner.nodes} nodes, "
          f"height {learner.height}; "
          f"teacher collisions {m['collisions']}; {traj.wall_time:.1f} s wall time")
    print(f"wrote {out}")
    return 0


def _size_note(rec) -> str:
    if not rec:
        return ""
    return (f"compacted ({rec['method']}) from {rec['nodes_before']} nodes, height "
            f"{rec['height_before']}, to ")


def _scales_note(scales) -> str:
    return f" (each also in copies scaled {', '.join(f'{f:g}' for f in scales)})" if scales else ""


__all__ += ["TreePolicy"]
