"""Goal behaviours in-process (``client.behaviour.goals``): their demonstrations, their drives
and their judgement, on ``server.world.World`` stepped at 10 Hz as ``lab.harness`` does, with
each step's fiducial sightings beside the scan.

    b = get("red-green")                                   # a behaviour with [goals]
    learner, reactive = train_goals(spec, b, recipe, seed=0)   # both learn the same demonstrations
    policy = learner.policy()                              # a GoalPolicy (or GoalPolicy.load(path))
    ep, events = drive_goals(spec, policy, start, b)       # an Episode and its goal changes
    report = evaluate_goals(spec, policy, b)               # as lab.evaluate.evaluate's report

``rhbl train``, ``rhbl evaluate`` and ``rhbl experiment`` come here for a behaviour with goals.
The success rule's ``goals`` is judged from the robot's true path (``lab.metrics.goals_in_order``),
not from what the robot believes: a completion tree that says ``done`` too early sends the
robot on before it was there, and the episode fails.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from client.behaviour.goals import (
    GoalExpert,
    GoalLearner,
    GoalPolicy,
    GoalStep,
    ReactiveBeaconPolicy,
    Sighting,
)
from client.behaviour.policies import Demonstrator, takes_over
from client.behaviour.spec import Behaviour
from lab import metrics
from lab.episode import DT, Episode
from lab.generated import generated
from lab.harness import OnStep, demonstration_starts, step_world
from lab.recipe import Recipe
from server.world import World, WorldSpec, free_pose

__all__ = ["drive_goals", "evaluate_goals", "expert_of", "judged_goal_episode", "sightings", "targets",
           "train_goals"]

log = logging.getLogger(__name__)


def sightings(world: World, i: int = 0) -> dict[int, Sighting]:
    """The beacons robot ``i`` sees now, by id (a beacon seen but not identified, id 0, is
    left out: a goal names its beacon by id)."""
    seen = world.fiducials([i])[0]
    return {int(b): Sighting(int(b), float(r), float(a))
            for b, r, a in zip(seen.ids, seen.ranges, seen.bearings, strict=True) if b}


def targets(spec: WorldSpec, b: Behaviour) -> list[tuple[float, float, float]]:
    """The behaviour's goals in the order they are to be reached, as the judge checks them:
    ``(x, y, radius)`` of each goal's beacon, radius its distance plus the rule's slack."""
    goals = b.goals
    slack = b.rules["goals"]["slack"]
    out = []
    for k in goals.visits:
        beacon = spec.beacon(goals.beacons[k])
        if beacon is None:
            raise ValueError(f"behaviour {b.name!r} names beacon {goals.beacons[k]}, which world "
                             f"{spec.name!r} does not have (its beacons: "
                             f"{', '.join(str(x.id) for x in spec.beacons) or 'none'})")
        out.append((beacon.pos[0], beacon.pos[1], goals.within[k] + slack))
    return out


def expert_of(b: Behaviour, actions=None) -> GoalExpert:
    """The behaviour's scripted teacher with its own goal state."""
    kw = {} if actions is None else {"actions": actions}
    return GoalExpert(b.goals, b.expert(**kw))


def _check(spec: WorldSpec, b: Behaviour) -> list:
    if b.goals is None:
        raise ValueError(f"behaviour {b.name!r} has no [goals]")
    return targets(spec, b)


def train_goals(spec: WorldSpec, b: Behaviour, recipe: Recipe, *, seed: int = 0,
                on_step: OnStep | None = None, dt: float = DT
                ) -> tuple[GoalLearner, ReactiveBeaconPolicy, Episode]:
    """The scripted teacher demonstrates ``b`` in ``spec`` as ``recipe`` says and two learners
    take every labelled step: the goal learner (action tree on the laser and the current goal's
    beacon, completion tree on the teacher's "reached" marks) and, as the baseline, today's
    reactive learner (one tree on the laser and every beacon, no goal state).

    Demonstrations: from each start pose of the world pursuing the first goal, each until the
    sequence is finished or ``segment`` s; then, until ``seconds`` are used, from poses anywhere
    in the free space (``random_segment`` > 0: ``segment * random_segment`` s each) pursuing a
    goal drawn at random (the teacher's state is set, as a person teaching at the console
    would start from any goal). Then ``rounds`` corrective rounds: the goal learner's action
    tree drives (the teacher's state says which goal is current and the teacher takes over
    within ``takeover`` m of a wall) from every start pose and ``round_free`` free-space poses,
    ``round_seconds`` each, while the teacher labels every step: first in ``round_generated``
    randomised worlds of the kind ``generator`` names (``lab.generated``, drawn from the seed;
    "beacons" for goals), then in copies of the world scaled by each of ``round_scales``, then
    in the world. The reactive learner learns the same labelled steps. With the recipe's
    radius "margin" the action tree is then learned again from every vector, each sphere
    bounded by its margin (``DemonstrationLearner.relearn``), and the reactive tree fitted so
    (the completion tree keeps the paper's radius)."""
    _check(spec, b)
    actions = None
    margin = recipe.radius == "margin"
    learner = GoalLearner(recipe.feature_spec(), b.goals, task=b.name, record=margin,
                          **recipe.tree_params())
    reactive = ReactiveBeaconPolicy(recipe.feature_spec(), b.goals, **recipe.tree_params())
    expert = expert_of(b, actions)
    rng = np.random.default_rng(seed)
    demo = Demonstrator(expert, perturb=recipe.perturb, rng=rng, dt=dt)
    world = World(spec, robots=1, seed=seed)
    ep = Episode(start=tuple(spec.pose), dt=dt, kind="training")
    fixed = demonstration_starts(spec, "world")
    total = int(round(recipe.seconds / dt))
    done, k = 0, 0
    t0 = time.perf_counter()
    while done < total:
        if k < len(fixed):
            pose, limit, visit = fixed[k], recipe.segment, 0
        else:
            pose = free_pose(spec, rng) or fixed[k % len(fixed)]
            limit = recipe.segment * (recipe.random_segment or 1.0)
            visit = int(rng.integers(len(b.goals.visits)))
        world.reset(poses=[pose], seed=seed * 1000 + k)
        demo.reset()
        expert.reset(visit)
        ep.segments.append(list(pose))
        steps = min(total - done, max(1, int(round(limit / dt))))
        done += _run(world, ep, expert, learner, reactive, steps, on_step=on_step,
                     demo=demo)
        k += 1
    # randomised worlds first (lab.generated, drawn from the seed), then the scaled copies, then
    # the world, as lab.train orders its corrective rounds
    drawn = generated(recipe.generator, recipe.round_generated if recipe.rounds else 0, seed)
    for where in drawn:  # the world and its scaled copies were checked above
        _check(where, b)
    for where in (*drawn, *(spec.scaled(f) for f in recipe.round_scales), spec):
        world = World(where, robots=1, seed=seed)
        starts = demonstration_starts(where, "world")
        for r in range(recipe.rounds):
            poses = [*starts, *[p for p in (free_pose(where, rng)
                                            for _ in range(recipe.round_free)) if p is not None]]
            for j, pose in enumerate(poses):
                world.reset(poses=[pose], seed=seed * 1000 + 500 + r * 50 + j)
                expert.reset(0 if j < len(starts) else int(rng.integers(len(b.goals.visits))))
                _run(world, ep, expert, learner, reactive,
                     int(round(recipe.round_seconds / dt)), on_step=on_step,
                     driver=_frozen(learner), takeover=recipe.takeover)
    learner.flush()
    if margin:  # as lab.train ends: the action tree learned again, bounded by the margin
        learner.relearn()
    reactive.flush()
    ep.wall_time = time.perf_counter() - t0
    return learner, reactive, ep


def _frozen(learner: GoalLearner) -> GoalPolicy:
    """The learner's trees as they are now, as a corrective drive's driver: copies, which the
    labels of that drive do not change."""
    from rhbl import loads

    p = learner.policy()
    return GoalPolicy(loads(p.classifier.to_bytes()), loads(p.completion.to_bytes()),
                      p.features, p.goals, p.actions, p.metadata)


def _run(world: World, ep: Episode, expert: GoalExpert, learner: GoalLearner,
         reactive: ReactiveBeaconPolicy, steps: int, *, on_step=None, demo=None, driver=None,
         takeover: float = 0.0) -> int:
    """One demonstration (``demo``) or corrective drive (``driver``: a GoalPolicy whose action
    tree drives in the teacher's goal state) of up to ``steps`` steps; both learners observe
    every step. Returns the steps taken."""
    n = 0
    for n in range(1, steps + 1):  # noqa: B007
        ranges, odom = world.scan(0), world.odom(0)
        seen = sightings(world)
        ev = expert.see(seen, t=n * ep.dt)
        if expert.tracker.finished:  # the last goal reached: its mark, and no action
            learner.observe_completion(learner.goals.completion_inputs(
                seen, learner.goals.visits[-1]), True)
            break
        step = GoalStep(expert.tracker.beacon, None if ev is None else ev["beacon"], seen)
        if demo is not None:
            label, executed = demo.step(ranges, odom)
        else:
            label = expert.act(ranges, odom)
            driver.tracker.visit = expert.tracker.visit
            driver._sightings = seen
            executed = label if takes_over(ranges, takeover) else driver.act(ranges, odom)
        learner.observe(ranges, odom[2], label, step)  # as the learner process learns it
        reactive.observe(reactive.vector(ranges, odom[2], seen), label)
        ep.labels.append(label)
        ep.learned += 1
        step_world(world, ep, learner.actions, executed, None, ranges, label=label,
                   on_step=on_step)
    return n


def drive_goals(spec: WorldSpec, driver, start, b: Behaviour, seconds: float | None = None, *,
                seed: int = 0, teacher=None, dt: float = DT, kind: str = "",
                on_step: OnStep | None = None) -> tuple[Episode, list[dict]]:
    """Drive ``driver`` (a GoalPolicy, a GoalExpert or a ReactiveBeaconPolicy: ``see`` then
    ``act`` each step) from ``start`` for the behaviour's time limit (or ``seconds``) or until
    every goal was reached in order (from its true path) or its own state says it finished.
    ``teacher`` (a GoalExpert, optional) is asked what it would do in the driver's goal state
    (teacher agreement). Returns the episode and the driver's goal changes."""
    goal_targets = _check(spec, b)
    seconds = b.seconds if seconds is None else float(seconds)
    world = World(spec, robots=1, seed=seed)
    world.reset(poses=[tuple(float(v) for v in start)])
    driver.reset()
    ep = Episode(start=tuple(float(v) for v in start), dt=dt, kind=kind)
    tracker = getattr(driver, "tracker", None)
    events: list[dict] = []
    reached = 0
    t0 = time.perf_counter()
    for n in range(int(round(seconds / dt))):
        t = round(n * dt, 6)
        seen = sightings(world)
        ev = driver.see(seen, t)
        if ev is not None:
            events.append(ev)
            log.debug("%s: %s", kind or "driver", ev["why"])
        if tracker is not None and tracker.finished:
            break
        ranges, odom = world.scan(0), world.odom(0)
        name = driver.act(ranges, odom)
        if teacher is not None:
            if tracker is not None:
                teacher.tracker.visit = tracker.visit
            teacher.seeker.see(seen.get(teacher.tracker.beacon)
                               if teacher.tracker.beacon is not None else None)
            ep.teacher_actions.append(teacher.act(ranges, odom))
        step_world(world, ep, driver.actions, name, None, ranges,
                   source="teacher" if isinstance(driver, GoalExpert) else "controller",
                   on_step=on_step)
        x, y, _ = ep.poses[-1]
        while reached < len(goal_targets) and math.hypot(
                x - goal_targets[reached][0], y - goal_targets[reached][1]) \
                <= goal_targets[reached][2]:
            reached += 1
        if reached == len(goal_targets):
            break
    ep.wall_time = time.perf_counter() - t0
    return ep, events


def episode_goal_metrics(ep: Episode, spec: WorldSpec, b: Behaviour) -> dict:
    """The episode's metrics with the goals reached in order (``lab.metrics``)."""
    return metrics.episode_metrics(ep.poses, ep.stalls, ep.actions, ep.dt, start=ep.start,
                                   teacher_actions=ep.teacher_actions or None, rules=b.rules,
                                   targets=targets(spec, b))


def judged_goal_episode(spec: WorldSpec, b: Behaviour, policy, start, seconds: float | None,
                        seed: int, on_step: OnStep | None = None):
    """One start of a goal behaviour judged (the goal behaviours' ``judged_episode``): its
    scripted expert and ``policy`` drive from ``start`` with ``seed``, each judged by the
    behaviour's rule: ``(learner metrics, expert metrics, learner episode, expert episode)``,
    each metrics with its ``goal_events``. The one place a goal episode is judged (``rhbl
    evaluate``, and ``lab.practice.run_episode`` on a pool or a cluster)."""
    tt, t_events = drive_goals(spec, expert_of(b, policy.actions), start, b, seconds,
                               seed=seed, kind="teacher", on_step=on_step)
    tm = episode_goal_metrics(tt, spec, b)
    tm["success"] = metrics.judge(b.rules, tm, None)
    tm["goal_events"] = t_events
    lt, events = drive_goals(spec, policy, start, b, seconds, seed=seed,
                             teacher=expert_of(b, policy.actions), kind="learner",
                             on_step=on_step)
    lm = episode_goal_metrics(lt, spec, b)
    lm["success"] = metrics.judge(b.rules, lm, tm)
    lm["goal_events"] = events
    return lm, tm, lt, tt


def mismatch(b: Behaviour, tree: str, goal_tree: bool) -> str:
    """What is wrong when a goal behaviour is given a reactive tree or the other way round."""
    if goal_tree:
        return (f"{tree} pursues goals in order (an action and a completion tree), but behaviour "
                f"{b.name!r} has none: judge it by the behaviour it was taught")
    return (f"behaviour {b.name!r} has goals in order, which {tree} (one reactive tree) "
            f"cannot pursue: give a goal snapshot (rhbl train --behaviour {b.name})")


def check_kind(b: Behaviour, policy, tree: str) -> None:
    """ValueError (``mismatch``) unless ``policy`` pursues goals exactly when ``b`` has them
    (``tree``: how the message names it)."""
    if (b.goals is not None) != is_goal_policy(policy):
        raise ValueError(mismatch(b, tree, is_goal_policy(policy)))


def evaluate_goals(spec: WorldSpec, policy, b: Behaviour, episodes: int | None = None,
                   seconds: float | None = None, seed: int = 0, on_step: OnStep | None = None,
                   keep_paths: bool = False, runner=None) -> dict:
    """``lab.evaluate.evaluate``'s report for a goal behaviour: ``policy`` and the scripted
    teacher from each start pose, judged by the behaviour's rule; each learner episode also
    lists its goal changes (``goal_events``: when, which goal, the next one and why).
    ``runner`` (a ``lab.practice.Runner``): the episodes run there (the same results); not with
    ``on_step`` or ``keep_paths``, which run here."""
    if b.goals is None:
        raise ValueError(mismatch(b, "the snapshot", goal_tree=True))
    starts = spec.start_poses
    episodes = len(starts) if episodes is None else int(episodes)
    learner_eps, teacher_eps, paths = [], [], {"teacher": [], "learner": []}
    if runner is not None and on_step is None and not keep_paths:
        from lab.practice import judged_on

        learner_eps, teacher_eps = judged_on(runner, b, spec, policy,
                                             [starts[k % len(starts)] for k in range(episodes)],
                                             seed, seconds)
    else:
        for k in range(episodes):
            lm, tm, lt, tt = judged_goal_episode(spec, b, policy, starts[k % len(starts)],
                                                 seconds, seed * 1000 + k, on_step)
            learner_eps.append(lm)
            teacher_eps.append(tm)
            if keep_paths:
                paths["teacher"].append(tt.poses)
                paths["learner"].append(lt.poses)
    clf = policy.classifier
    completion = getattr(policy, "completion", None)
    guard = policy if hasattr(policy, "overruled") else None
    report = {
        "world": spec.name, "world_path": str(spec.path) if spec.path else None,
        "task": b.name, "behaviour_file": str(b.path) if b.path else None,
        "episodes": episodes, "seconds": b.seconds if seconds is None else float(seconds),
        "seed": seed, "range_noise": 0.0, "odom_noise": 0.0,
        "goals": b.goals.to_dict(),
        "learner": learner_eps, "teacher": teacher_eps,
        "success": [e["success"] for e in learner_eps],
        "success_rate": sum(e["success"] for e in learner_eps) / max(1, len(learner_eps)),
        "teacher_success_rate": sum(e["success"] for e in teacher_eps) / max(1, len(teacher_eps)),
        "tree": {"nodes": int(clf.node_count_), "height": int(clf.height_)},
        "completion_tree": None if completion is None else {
            "nodes": int(completion.node_count_), "height": int(completion.height_)},
        "loops": [dict(loop, episode=k) for k, e in enumerate(learner_eps)
                  for loop in e["oscillation_loops"]],
        "guard": None if guard is None else {
            "clearance": guard.clearance, "overruled": guard.overruled,
            "avoided": guard.avoided, "straight_on": guard.straight_on},
    }
    if keep_paths:
        report["_paths"] = paths
    return report


def goal_notes(report: dict) -> list[str]:
    """One line per goal change of each learner episode (``rhbl evaluate``'s table notes)."""
    out = []
    for k, (lm, tm) in enumerate(zip(report["learner"], report["teacher"], strict=True)):
        out.append(f"episode {k}: learner reached {lm['goals_reached']}/{lm['goals_total']} goals "
                   f"in order (teacher {tm['goals_reached']}/{tm['goals_total']})")
        for ev in lm.get("goal_events") or []:
            nxt = "finished" if ev["next"] is None else f"on to beacon {ev['next']}"
            out.append(f"  t={ev['t']:g} s: goal {ev['visit'] + 1} (beacon {ev['beacon']}) "
                       f"done, {nxt}: {ev['why']}")
    return out


def is_goal_policy(policy) -> bool:
    """Whether ``policy`` pursues goals in order: a ``GoalPolicy``, or one behind a guard."""
    return isinstance(getattr(policy, "policy", policy), GoalPolicy)


# ------------------------------------------------------------------ the commands' goal paths


def train_main(args, b: Behaviour, spec: WorldSpec, recipe: Recipe, on_step=None) -> int:
    """``rhbl train`` for a behaviour with goals: the goal learner's snapshot (both trees)."""
    if args.resume or args.start or args.range_noise or args.odom_noise:
        raise ValueError("--resume, --start and the noise flags are not for a behaviour with "
                         "goals yet (docs/goals.md)")
    learner, reactive, ep = train_goals(spec, b, recipe, seed=args.seed, on_step=on_step)
    out = learner.save(args.out, {"provenance": {
        "vectors": learner.vectors, "marks": learner.marks, "world": spec.name,
        "seed": args.seed, "seconds": recipe.seconds, "rounds": recipe.rounds}})
    m = ep.metrics()
    print(f"trained on {spec.name} ({b.name}: goals {_goal_line(b)}) for {recipe.seconds:g} s "
          f"+ {recipe.rounds} corrective rounds: {learner.vectors} vectors, {learner.marks} "
          f"reached marks; action tree {learner.action_tree.node_count_} nodes, completion "
          f"tree {learner.completion_tree.node_count_} nodes; teacher collisions "
          f"{m['collisions']}; {ep.wall_time:.1f} s wall time")
    print(f"wrote {out}")
    return 0


def _goal_line(b: Behaviour) -> str:
    g = b.goals
    order = " -> ".join(str(g.beacons[k]) for k in g.visits)
    return f"beacons {order}" + (" (a cycle)" if g.cycle else "")


def format_goal_table(report: dict) -> str:
    """``rhbl evaluate``'s table for a goal behaviour, the goal changes in its notes."""
    from lab.report import table

    title = (f"world {report['world']} ({report['task']}), {report['episodes']} episodes of "
             f"{report['seconds']:g} s, action tree {report['tree']['nodes']} nodes, "
             f"completion tree {(report['completion_tree'] or {}).get('nodes', '-')} nodes")
    rows = []
    for k, (lm, tm) in enumerate(zip(report["learner"], report["teacher"], strict=True)):
        for who, m in (("learner", lm), ("teacher", tm)):
            rows.append([f"{k}: {who}", "(" + ", ".join(f"{v:.2f}" for v in m["start"]) + ")",
                         f"{m['seconds']:.0f}", m["collisions"],
                         f"{m['goals_reached']}/{m['goals_total']}",
                         "yes" if m["success"] else "no"])
    notes = [f"success rate: learner {report['success_rate']:.0%}, teacher "
             f"{report['teacher_success_rate']:.0%}", *goal_notes(report)]
    return table(["driver", "start (x, y, yaw)", "seconds", "collisions", "goals in order",
                  "success"], rows, title=title, notes=notes)


def guarded(policy, on: bool | None = None):
    """``policy`` (a goal snapshot's ``GoalPolicy``) driven as ``rhbl controller`` drives it:
    through the guard of its rule (``client.behaviour.guard.settings_for`` its metadata: the
    loop hysteresis and the path check, ``client.behaviour.rule.for_goals``), if the rule has
    it on (``on`` True: on whatever the rule says; False: ``policy`` as it is)."""
    import dataclasses

    from client.behaviour.guard import RotationGuard, settings_for

    settings = settings_for(policy.metadata)
    if on is not None:
        settings = dataclasses.replace(settings, on=bool(on))
    return RotationGuard.of(settings, policy) if settings.on else policy


def run_goal_trial(b: Behaviour, seed: int, recipe: Recipe, worlds: list[str],
                   episodes: int | None = None, guard: bool = True,
                   seconds: float | None = None) -> dict:
    """One trial of ``rhbl experiment`` for a goal behaviour: train both learners with
    ``seed``, evaluate in every world the goal learner's trees alone (what was learned, the
    figure judged), the reactive baseline's tree alone and, beside them (``guard``), the goal
    learner through the controller's guard (a safety layer)."""
    from lab.behaviours import world_of

    t0 = time.perf_counter()
    learner, reactive, _ = train_goals(world_of(b, recipe.world), b, recipe, seed=seed)
    policy = learner.policy()
    out = {"seed": seed, "nodes": int(policy.classifier.node_count_),
           "completion_nodes": int(policy.completion.node_count_),
           "reactive_nodes": int(reactive.classifier.node_count_),
           "vectors": learner.vectors, "marks": learner.marks,
           "train_wall_s": round(time.perf_counter() - t0, 2), "worlds": {}}
    for w in worlds:
        spec = world_of(b, w)
        rep = evaluate_goals(spec, policy, b, episodes=episodes, seed=seed, seconds=seconds)
        base = evaluate_goals(spec, reactive, b, episodes=episodes, seed=seed,
                              seconds=seconds)
        driven = guarded(policy) if guard else policy
        g = (evaluate_goals(spec, driven, b, episodes=episodes, seed=seed, seconds=seconds)
             if driven is not policy else None)
        out["worlds"][spec.name] = {
            "success_rate": rep["success_rate"], "reactive_success_rate": base["success_rate"],
            "guarded_success_rate": None if g is None else g["success_rate"],
            "guard": None if g is None else g["guard"],
            "teacher_success_rate": rep["teacher_success_rate"],
            "goals_reached": [e["goals_reached"] for e in rep["learner"]],
            "reactive_goals_reached": [e["goals_reached"] for e in base["learner"]],
            "goals_total": rep["learner"][0]["goals_total"] if rep["learner"] else 0,
            "collisions": sum(e["collisions"] for e in rep["learner"]),
            "reactive_collisions": sum(e["collisions"] for e in base["learner"]),
            "guarded_collisions": None if g is None else sum(e["collisions"]
                                                             for e in g["learner"]),
            "episodes": rep["episodes"]}
    return out


def goal_experiment_table(b: Behaviour, rows: list[dict]) -> str:
    """Per world over the trials: the goal learner's success, the reactive baseline's and the
    teacher's (markdown)."""
    from lab.report import table

    worlds = list(rows[0]["worlds"]) if rows else []
    out = []
    for w in worlds:
        per = [r["worlds"][w] for r in rows]
        kind = "taught" if w == worlds[0] else "held out"

        def mean(key: str, per=per) -> str:
            return f"{sum(p[key] for p in per) / len(per):.0%}"

        guarded_ = ("-" if per[0]["guarded_success_rate"] is None
                    else mean("guarded_success_rate"))
        out.append([w, kind, mean("success_rate"),
                    " ".join(f"{p['success_rate']:.0%}" for p in per),
                    mean("reactive_success_rate"), mean("teacher_success_rate"),
                    sum(p["collisions"] for p in per), sum(p["reactive_collisions"] for p in per),
                    guarded_])
    return table(["world", "", "goal learner", "per trial", "reactive tree", "teacher",
                  "collisions", "reactive collisions", "goal learner through the guard"], out,
                 title=f"{b.name}: goals {_goal_line(b)}, {len(rows)} trials (success: the "
                       f"goals reached in order, no collision, within {b.seconds:g} s; "
                       f"the learned trees alone, the controller's guard beside them)",
                 notes=["trees per trial (action/completion/reactive nodes): " + ", ".join(
                     f"s{r['seed']} {r['nodes']}/{r['completion_nodes']}/{r['reactive_nodes']}"
                     for r in rows)])
