"""``rhbl train``: a scripted teacher demonstrates on a world in-process (``lab.harness``, no zenoh)
and a tree learns; the snapshot is written with its metadata.

    b = get("wall-following")                                        # lab.behaviours: a behaviour
    spec = teaching_world(b)                                         # its first teaching world
    recipe = recipe_of(b).replace(seconds=300)                       # lab.recipe: the defaults
    learner = make_learner(recipe)                                   # or DemonstrationLearner(...)
    ep = train(spec, learner, recipe, seed=0, behaviour=b)           # its scripted expert demonstrates

``rhbl train --behaviour NAME|FILE | --world PATH --out SNAPSHOT [--resume SNAPSHOT] [--start
x,y,yaw] [--seed N] [recipe flags: --seconds S --perturb P --spawn all|winner ...]`` writes the
snapshot with its metadata; every flag left out takes the behaviour's recipe value
(``lab.behaviours.recipe_of``: ``lab.recipe.RECIPES``). ``--behaviour`` alone teaches in its
first teaching world; ``--world`` alone teaches the world's behaviour.
``rhbl train --from-recording FILE ...`` learns recorded labels instead (``lab.retrain``).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import time

import numpy as np

from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.policies import Demonstrator, takes_over
from client.behaviour.spec import Behaviour
from client.behaviour.teaching import add_person_arguments
from lab.behaviours import (
    add_paper_argument,
    behaviour_arg,
    behaviour_for_world,
    get,
    recipe_of,
    teaching_world,
    world_of,
)
from lab.episode import DT, Episode
from lab.generated import generated
from lab.harness import (
    OnStep,
    demonstration_starts,
    make_learner,
    parse_pose,
    recorded,
    resolve_world,
    step_world,
)
from lab.recipe import Recipe, add_recipe_arguments, recipe_from_args
from process import arguments
from server import world_arg
from server.world import World, WorldSpec, free_pose, sample_pose

__all__ = ["add_arguments", "main", "train", "visited_states"]

log = logging.getLogger(__name__)


def train(spec: WorldSpec, learner: DemonstrationLearner, recipe: Recipe | None = None, *,
          seed: int = 0, start: tuple[float, float, float] | None = None,
          range_noise: float = 0.0, odom_noise: float = 0.0, dt: float = DT,
          policy=None, on_step: OnStep | None = None,
          behaviour: Behaviour | None = None) -> Episode:
    """One training run of ``recipe`` (default: the behaviour's, ``lab.behaviours.recipe_of``)
    of ``behaviour`` (default: the world's, ``lab.behaviours.behaviour_for_world``; in a world
    no shipped behaviour names, the recipe's task, else the learner's): its
    scripted expert (or ``policy``) demonstrates for ``recipe.seconds`` (sim time, in total)
    while ``learner`` observes every step.

    The run is a sequence of demonstrations (the teacher restarts; the tree keeps growing):
    first one from each pose of ``recipe.starts`` ("world": every start pose of the world,
    "default": its default pose), each until the goal (maze) or ``segment`` seconds; the rest of
    the time from poses sampled near the teacher's earlier path (``server.world.sample_pose``:
    jittered position, heading turned by up to ``turn`` rad; "free": anywhere in the free space,
    ``server.world.free_pose``), each for ``segment * random_segment`` seconds or until the goal.
    ``start`` given: a single demonstration from there (a corrective one), no rounds.

    ``recipe.rounds`` > 0 then adds corrective rounds (DAgger, the paper's "corrective
    demonstration" automated): in each round the LEARNED tree drives from every start pose for
    ``round_seconds`` (or until the goal) while the teacher labels every visited state, and the
    tree learns those labels (it only grows where it disagrees). The teacher takes over the
    wheels while any beam is closer than ``takeover`` metres (as the server's arbitration lets a
    teacher override a controller), so a round never drives into a wall.

    ``recipe.radius`` "margin": then the tree is learned again from every vector it learned
    (``learner.relearn``: each sphere bounded by the nearest vector of another label among
    them; ``learner.session["relearned"]``), unless the learner extends a tree of its own.
    ``recipe.compact`` (not "none") is the last step: the tree is compacted on every vector it
    learned (``learner.compact``; ``learner.session["compaction"]`` is the record). With
    ``recipe.compact_rounds`` it is compacted also after the demonstrations and after every
    corrective round but the last (``learner.session["compact_rounds"]``), so each round drives,
    and corrects, the compacted tree. With ``recipe.compact_visits`` the last compaction is
    redone against the learned vectors plus held-out states the compacted tree reaches
    (``visited_states``)."""
    b = behaviour if behaviour is not None else behaviour_for_world(
        spec, recipe.task if recipe is not None else learner.task)
    recipe, compact = _checked(spec, b, learner, recipe)
    policy = policy or b.expert(actions=learner.actions)
    rng = np.random.default_rng(seed)
    aug = (_Augmenter(policy, recipe.augment, recipe.augment_scale, seed)
           if recipe.augment > 0 else None)
    fixed = [tuple(start)] if start is not None else demonstration_starts(spec, recipe.starts)
    segment = recipe.seconds if start is not None else recipe.segment
    ep = Episode(start=fixed[0], dt=dt, kind="training")
    t0 = time.perf_counter()
    noise = (range_noise, odom_noise)
    _demonstrations(spec, learner, recipe, policy, fixed, segment, ep, rng=rng, aug=aug,
                    seed=seed, noise=noise, on_step=on_step, record=recorded(b))
    demo_vectors = ep.learned
    rounds = 0 if start is not None else recipe.rounds  # a corrective demonstration: no rounds
    others = [world_of(b, w) for w in recipe.round_worlds] if rounds else []
    drawn = generated(recipe.generator, recipe.round_generated if rounds else 0, seed,
                      b.band_side or "right")
    round_stats, between = _rounds(spec, learner, policy, fixed, recipe, rounds, compact, ep,
                                   rng=rng, aug=aug, seed=seed, noise=noise, on_step=on_step,
                                   record=recorded(b), others=others, drawn=drawn)
    relearned = recipe.radius == "margin" and learner.relearn()
    compaction = _last_compaction(spec, learner, recipe, compact, seed, policy, on_step, b)
    ep.wall_time = time.perf_counter() - t0
    learner.session = _session_record(
        spec, recipe, ep, seed=seed, given=start is not None, segment=segment,
        demo_vectors=demo_vectors, rounds=rounds, round_stats=round_stats, noise=noise,
        compaction=compaction, between=between, compacted=compact is not None)
    learner.session["relearned"] = relearned
    return ep


def _checked(spec: WorldSpec, b: Behaviour, learner: DemonstrationLearner,
             recipe: Recipe | None) -> tuple[Recipe, dict | None]:
    """The recipe (default: the behaviour's) and its compaction step's settings; ValueError
    when the recipe is another behaviour's, or compacts with a learner that keeps no
    vectors."""
    recipe = recipe_of(b) if recipe is None else recipe
    if recipe.task != b.name:
        raise ValueError(f"the recipe is for task {recipe.task!r} but world {spec.name!r} is "
                         f"taught the behaviour {b.name!r}")
    compact = recipe.compact_params()
    if compact is not None and not learner.recording:
        raise ValueError(f"recipe compact {recipe.compact!r} needs a learner that kept its "
                         "vectors (make_learner(recipe), or record=True)")
    return recipe, compact


def _demonstrations(spec: WorldSpec, learner: DemonstrationLearner, recipe: Recipe, policy,
                    fixed: list, segment: float, ep: Episode, *, rng, aug, seed: int,
                    noise: tuple[float, float], on_step: OnStep | None = None,
                    record: dict | None = None) -> None:
    """The demonstrations of ``train`` until ``recipe.seconds`` of sim time are used: the teacher
    restarts from each pose of ``fixed``, then (``recipe.random_segment`` > 0) from sampled
    poses; ``learner`` observes every step; ``ep`` records them."""
    demo = Demonstrator(policy, perturb=recipe.perturb, rng=rng, dt=ep.dt)
    world = World(spec, robots=1, seed=seed, range_noise=noise[0], odom_noise=noise[1])
    record = record or {}
    total = int(round(recipe.seconds / ep.dt))
    done = 0
    k = 0
    while done < total:
        pose, limit = _demonstration_start(spec, recipe, fixed, segment, ep, k, rng)
        world.reset(poses=[pose], seed=seed * 1000 + k)
        demo.reset()
        if k > 0 and hasattr(policy, "resume_following"):
            policy.resume_following()
        ep.segments.append(list(pose))
        steps = min(total - done, max(1, int(round(limit / ep.dt))))
        for _ in range(steps):
            ranges = world.scan(0)
            odom = world.odom(0)
            label, executed = demo.step(ranges, odom)
            ep.labels.append(label)
            if (not recipe.consistent or demo.consistent) and learner.observe(ranges, odom[2], label):
                ep.learned += 1
            if aug is not None:
                ep.learned += aug.offer(learner, ranges, odom)
            step_world(world, ep, learner.actions, executed, record.get("side"), ranges,
                       label=label, on_step=on_step, gaps=record.get("gaps", False))
            done += 1
            if spec.goal is not None and world.at_goal(0):
                break
        k += 1


def _demonstration_start(spec: WorldSpec, recipe: Recipe, fixed: list, segment: float,
                         ep: Episode, k: int, rng) -> tuple[tuple, float]:
    """The k-th demonstration's start pose and time limit: the fixed poses first, then (with
    ``recipe.random_segment`` > 0) poses sampled near the teacher's path or, ``starts`` "free",
    anywhere in the free space (a fixed pose when none is found)."""
    if k < len(fixed) or recipe.random_segment <= 0:
        return fixed[k % len(fixed)], segment
    if recipe.starts == "free":
        pose = free_pose(spec, rng) or fixed[k % len(fixed)]
    else:
        pose = sample_pose(spec, ep.poses, rng, turn=recipe.turn) or fixed[k % len(fixed)]
    return pose, segment * recipe.random_segment


def _rounds(spec: WorldSpec, learner: DemonstrationLearner, policy, fixed: list, recipe: Recipe,
            rounds: int, compact: dict | None, ep: Episode, *, rng, aug, seed: int,
            noise: tuple[float, float], on_step: OnStep | None = None,
            record: dict | None = None, others: list[WorldSpec] = (),
            drawn: list[WorldSpec] = ()) -> tuple[list[dict], list[dict]]:
    """The corrective rounds of ``train``: in each of ``others`` (``recipe.round_worlds``, from
    their own start poses) and its copies scaled by ``recipe.round_scales``, then in each of
    ``drawn`` (randomised worlds, ``lab.generated``: of every size already), then in each copy of
    the training world so scaled, then in the training world (its corrections are the latest);
    with ``recipe.compact_rounds`` the tree is compacted after the demonstrations and after
    every round but the last. Returns the rounds' statistics and the compactions between
    them."""
    between: list[dict] = []  # the compactions before the last step (compact_rounds)
    round_stats: list[dict] = []
    if rounds <= 0:
        return round_stats, between
    after_round = None
    if compact is not None and recipe.compact_rounds:
        between.append(learner.compact(**compact, data="after the demonstrations"))
        todo = [rounds * ((len(recipe.round_scales) + 1) * (len(others) + 1) + len(drawn))]

        def after_round(where: str) -> bool:  # every round but the last (whose compaction
            todo[0] -= 1                      # is the last step)
            if todo[0] > 0:
                between.append(learner.compact(**compact, data=f"after {where}"))
            return todo[0] > 0
    range_noise, odom_noise = noise
    for other in others:  # another teaching world: its copies, then itself
        for f in (*recipe.round_scales, None):
            w = other if f is None else other.scaled(f)
            for st in _corrective_rounds(w, learner, policy, w.start_poses, recipe, seed,
                                         range_noise, odom_noise, ep, rng=rng, aug=aug,
                                         after_round=after_round, scale=f, on_step=on_step,
                                         record=record):
                round_stats.append(dict(st, scale=f, world=other.name))
    for w in drawn:
        for st in _corrective_rounds(w, learner, policy, w.start_poses, recipe, seed,
                                     range_noise, odom_noise, ep, rng=rng, aug=aug,
                                     after_round=after_round, on_step=on_step, record=record):
            round_stats.append(dict(st, world=w.name))
    for f in recipe.round_scales:
        scaled = spec.scaled(f)
        for st in _corrective_rounds(scaled, learner, policy, scaled.start_poses, recipe,
                                     seed, range_noise, odom_noise, ep, rng=rng, aug=aug,
                                     after_round=after_round, scale=f, on_step=on_step,
                                     record=record):
            round_stats.append(dict(st, scale=f))
    round_stats += _corrective_rounds(spec, learner, policy, fixed, recipe, seed,
                                      range_noise, odom_noise, ep, rng=rng, aug=aug,
                                      after_round=after_round, on_step=on_step, record=record)
    return round_stats, between


def _last_compaction(spec: WorldSpec, learner: DemonstrationLearner, recipe: Recipe,
                     compact: dict | None, seed: int, policy,
                     on_step: OnStep | None = None, b: Behaviour | None = None) -> dict | None:
    """The last step of ``train``: the tree compacted on every vector it learned, redone against
    held-out visited states with ``recipe.compact_visits``. Returns its record (None: no
    compaction)."""
    if compact is None:
        return None
    before = learner.classifier
    compaction = learner.compact(**compact, data="the last step")
    if recipe.compact_visits > 0:
        compaction = _compact_visits(spec, learner, before, compact, recipe, seed, policy,
                                     on_step, b)
    return compaction


def _session_record(spec: WorldSpec, recipe: Recipe, ep: Episode, *, seed: int, given: bool,
                    segment: float, demo_vectors: int, rounds: int, round_stats: list[dict],
                    noise: tuple[float, float], compaction: dict | None, between: list[dict],
                    compacted: bool) -> dict:
    """``learner.session`` after ``train``: the run's settings and what it did (``given``: a
    single demonstration from a given start)."""
    augment = recipe.augment
    return {"world": spec.name, "world_path": str(spec.path) if spec.path else None,
            "seconds": recipe.seconds, "seed": seed, "perturb": recipe.perturb,
            "start": list(ep.start), "starts": "given" if given else recipe.starts,
            "demonstrations": len(ep.segments), "segment": segment,
            "consistent": recipe.consistent, "demonstration_vectors": demo_vectors,
            "rounds": rounds,
            "round_seconds": recipe.round_seconds if rounds else None,
            "takeover": recipe.takeover if rounds else None,
            "round_stats": round_stats,
            "round_free": recipe.round_free if rounds else None,
            "round_scales": list(recipe.round_scales) if rounds else None,
            "round_worlds": list(recipe.round_worlds) if rounds and recipe.round_worlds
            else None,
            "round_generated": ({"worlds": recipe.round_generated, "kind": recipe.generator}
                                if rounds and recipe.round_generated else None),
            "augment": augment,
            "augment_scale": recipe.augment_scale if augment else None,
            "range_noise": noise[0], "odom_noise": noise[1],
            "vectors": ep.learned, "compaction": compaction,
            "compact_rounds": between if between else None,
            "compact_visits": ({"visits": recipe.compact_visits,
                                "scales": list(recipe.visit_scales),
                                "free": recipe.visit_free}
                               if compacted and recipe.compact_visits else None)}


def _compact_visits(spec: WorldSpec, learner: DemonstrationLearner, before, compact: dict,
                    recipe: Recipe, seed: int, policy, on_step: OnStep | None = None,
                    b: Behaviour | None = None) -> dict:
    """``recipe.compact_visits`` (see ``Recipe``): the last compaction redone against every
    learned vector plus the states the compacted tree reaches (``visited_states``, poses drawn
    with ``seed + 100 + 1000 k`` for the k-th visit); ``before``: the tree before the last
    compaction. Returns the last record."""
    X, y = learner.recorded()
    xs, ys = [X], [y]
    visit = recipe.replace(round_free=recipe.visit_free)
    for k in range(recipe.compact_visits):
        vx, vy = visited_states(spec, learner, visit, seed=seed + 100 + 1000 * k,
                                scales=recipe.visit_scales, policy=policy, on_step=on_step,
                                behaviour=b)
        xs.append(vx)
        ys.append(vy)
        learner.classifier = before.compact(
            np.concatenate(xs), np.concatenate(ys), **compact,
            data=f"the vectors this learner was trained on and {sum(map(len, xs[1:]))} "
                 f"held-out states its compacted tree reached ({k + 1} of "
                 f"{recipe.compact_visits})")
    return learner.classifier.metadata["compaction"][-1]


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


def _corrective_rounds(spec: WorldSpec, learner: DemonstrationLearner, policy, poses,
                       recipe: Recipe, seed: int, range_noise: float, odom_noise: float,
                       ep: Episode, rng=None, aug=None, after_round=None,
                       scale: float | None = None, collect: tuple[list, list] | None = None,
                       on_step: OnStep | None = None, record: dict | None = None) -> list[dict]:
    """DAgger rounds (see ``train``): the tree drives, the teacher labels; per round the number
    of steps, disagreements (learned labels that differed from the tree's choice) and takeovers.
    ``recipe.round_free`` > 0: each round also drives from that many fresh poses anywhere in the
    free space (``free_pose``), so the corrections cover states the start poses never lead to.
    ``after_round(where)`` (optional) is called after each round (``where``: "round 2", "round
    2 in the copy scaled 0.85"); it may replace the learner's tree (a compaction; it returns
    True then): each round drives the learner's tree as it is when the round starts.
    ``collect=(xs, ys)``: the learner learns nothing; each state's feature vector and the
    teacher's label are appended to ``xs`` and ``ys`` instead (``visited_states``)."""
    rounds, seconds, takeover, free = (recipe.rounds, recipe.round_seconds, recipe.takeover,
                                       recipe.round_free)
    dt = ep.dt
    world = World(spec, robots=1, seed=seed, range_noise=range_noise, odom_noise=odom_noise)
    record = record or {}
    stats = []
    for r in range(rounds):
        tree = TreePolicy.from_learner(learner)
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
                if collect is not None:
                    collect[0].append(learner.features.extract(ranges, odom[2]))
                    collect[1].append(label)
                elif learner.observe(ranges, odom[2], label):
                    ep.learned += 1
                if aug is not None and collect is None:
                    ep.learned += aug.offer(learner, ranges, odom)
                took_now = takes_over(ranges, takeover)
                if took_now:
                    drive = label
                    took += 1
                step_world(world, ep, learner.actions, drive, record.get("side"), ranges,
                           label=label, source="teacher" if took_now else "controller",
                           on_step=on_step, gaps=record.get("gaps", False))
                ep.labels.append(label)
                steps += 1
                if spec.goal is not None and world.at_goal(0):
                    break
        stats.append({"round": r + 1, "steps": steps, "disagreements": disagree, "takeovers": took,
                      "nodes": learner.nodes})
        log.debug("round %d: %s", r + 1, stats[-1])
        if after_round is not None and after_round(
                f"round {r + 1}" + ("" if scale is None else f" in the copy scaled {scale:g}")):
            stats[-1]["nodes_compacted"] = learner.nodes
    return stats


def visited_states(spec: WorldSpec, learner: DemonstrationLearner, recipe: Recipe | None = None,
                   *, seed: int = 0, scales: tuple[float, ...] | None = None, rounds: int = 1,
                   policy=None, on_step: OnStep | None = None,
                   behaviour: Behaviour | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Held-out states for pruning (``rhbl.compaction``): the states ``learner``'s tree reaches when
    it drives, labelled by the teacher, ``(X, y)``. The drives are ``rounds`` corrective rounds
    as ``recipe`` runs them (from every start pose and ``recipe.round_free`` free-space poses,
    ``round_seconds`` each, the teacher taking over near walls), first in copies of ``spec``
    scaled by each of ``scales`` (default: ``recipe.round_scales``), then in ``spec``, but the
    tree learns nothing. ``seed`` draws the poses (use one other than the training run's for
    held-out states)."""
    b = behaviour if behaviour is not None else behaviour_for_world(
        spec, recipe.task if recipe is not None else learner.task)
    recipe = recipe_of(b) if recipe is None else recipe
    recipe = recipe.replace(rounds=rounds)
    policy = policy or b.expert(actions=learner.actions)
    rng = np.random.default_rng(seed)
    ep = Episode(start=tuple(spec.pose), kind="round")
    xs: list = []
    ys: list = []
    for f in recipe.round_scales if scales is None else scales:
        scaled = spec.scaled(f)
        _corrective_rounds(scaled, learner, policy, scaled.start_poses, recipe, seed, 0.0, 0.0,
                           ep, rng=rng, collect=(xs, ys), on_step=on_step)
    _corrective_rounds(spec, learner, policy, demonstration_starts(spec, recipe.starts), recipe,
                       seed, 0.0, 0.0, ep, rng=rng, collect=(xs, ys), on_step=on_step)
    X = np.array(xs, dtype=np.float64).reshape(-1, learner.features.dim)
    return X, np.array(ys, dtype=str)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", type=world_arg,
                        help="world file (or a shipped world's name); default: the first world "
                             "--behaviour is taught in (one of the two is required unless "
                             "--from-recording)")
    parser.add_argument("--behaviour", default=None, type=behaviour_arg,
                        help="the behaviour to teach, with its scripted expert, perception and "
                             "recipe (a shipped behaviour's name, 'rhbl behaviours' lists them, "
                             "or a behaviour file); default: the world's")
    parser.add_argument("--out", required=True, type=arguments.output_file,
                        help="snapshot to write")
    add_paper_argument(parser)
    parser.add_argument("--resume", default=None, type=arguments.input_file,
                        help="continue training this snapshot (a corrective demonstration)")
    parser.add_argument("--start", type=parse_pose, default=None,
                        help="start pose x,y,yaw (default: the world's pose); use the pose of an "
                             "oscillation loop reported by 'rhbl evaluate --json'")
    parser.add_argument("--seed", type=arguments.seed, default=0)
    add_recipe_arguments(parser)
    parser.add_argument("--range-noise", type=arguments.non_negative_float, default=0.0)
    parser.add_argument("--odom-noise", type=arguments.non_negative_float, default=0.0)
    parser.add_argument("--record", metavar="FILE", default=None, type=arguments.output_file,
                        help="also write the run as an MCAP recording (docs/recording.md)")
    parser.add_argument("--from-recording", nargs="+", metavar="FILE", default=None,
                        type=arguments.input_file,
                        help="no simulation: learn the teacher labels of these recordings "
                             "(with --features and the tree options; docs/recording.md)")
    parser.add_argument("--teacher", choices=["auto", "script", "person"], default="auto",
                        help="with --from-recording, as rhbl learner: 'auto' (default) learns "
                             "by the person rule when the first label of the recordings came "
                             "from a person (rhbl console, rhbl teacher --policy keyboard), "
                             "else by the script rule; 'script' or 'person' force one "
                             "(docs/teaching.md)")
    add_person_arguments(parser)


def main(args) -> int:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.from_recording:
        from lab.retrain import train_main

        return train_main(args)  # every flag that cannot apply is a named error there
    if not args.world and not args.behaviour:
        raise ValueError("--world or --behaviour is required (or --from-recording FILE)")
    if args.teacher not in ("auto", "script") or args.lag is not None:
        raise ValueError("--teacher and --lag go with --from-recording (a simulated "
                         "run's teacher is the scripted expert)")
    b = get(args.behaviour) if args.behaviour else None
    if args.world is None:
        spec = teaching_world(b)
    else:
        spec = resolve_world(args.world) if b is None else world_of(b, args.world)
    b = behaviour_for_world(spec) if b is None else b
    recipe = recipe_from_args(recipe_of(b, args.paper), args)
    if b.goals is not None:  # goals in order: two trees, the goal learner (lab.goals)
        from lab.goals import train_main

        return train_main(args, b, spec, recipe)
    if args.resume:
        if recipe.compact != "none":
            raise ValueError(f"--compact {recipe.compact} needs a fresh tree: a resumed learner "
                             "kept no vectors to compact on (use 'rhbl compact' on its journal)")
        learner = DemonstrationLearner.resume(
            args.resume, features=recipe.feature_spec() if args.features else None)
    else:
        learner = make_learner(recipe)
    if args.record:  # imported only then (the recordings' writer and its libraries)
        from lab.sim_tap import record_run

        recording = record_run(args.record, "rhbl train")
    else:
        recording = contextlib.nullcontext()
    with recording as tap:  # None without --record
        ep = train(spec, learner, recipe, seed=args.seed, start=args.start,
                   range_noise=args.range_noise, odom_noise=args.odom_noise,
                   on_step=None if tap is None else tap.step, behaviour=b)
    out = learner.save(args.out)
    m = ep.metrics()
    note = _scales_note(learner.session.get('round_scales'), learner.session.get('round_worlds'))
    print(f"trained on {spec.name} ({b.name}) for {recipe.seconds:g} s from {list(ep.start)}: "
          f"{len(ep.segments)} demonstrations + {learner.session.get('rounds', 0)} corrective "
          f"rounds{note}, {ep.learned} vectors "
          f"learned, tree {_size_note(learner.session.get('compaction'))}{learner.nodes} nodes, "
          f"height {learner.height}; "
          f"teacher collisions {m['collisions']}; {ep.wall_time:.1f} s wall time")
    print(f"wrote {out}")
    return 0


def _size_note(rec) -> str:
    if not rec:
        return ""
    return (f"compacted ({rec['method']}) from {rec['nodes_before']} nodes, height "
            f"{rec['height_before']}, to ")


def _scales_note(scales, worlds=None) -> str:
    also = [f"copies scaled {', '.join(f'{f:g}' for f in scales)}"] if scales else []
    also += [f"{', '.join(worlds)}"] if worlds else []
    return f" (each also in {' and in '.join(also)})" if also else ""
