"""``rhbl evaluate``: run a learned tree (and, as a baseline, the scripted teacher) from each start
pose of a world and measure how well it behaves (metrics in ``lab.metrics``).

    report = evaluate(spec, policy, episodes=K, seconds=S, seed=N, range_noise=0, odom_noise=0)
    report["learner"][k], report["teacher"][k]   per-episode metrics (start, seconds, collisions,
        distance, wall_band_fraction, goal_reached, time_to_goal, oscillations, oscillation_loops,
        teacher_agreement, stuck, success)
    report["success_rate"], report["teacher_success_rate"], report["tree"] = {"nodes", "height"}

Success is the behaviour's rule (``--behaviour NAME|FILE``, default the world's: the shipped
behaviour its ``task`` names or that names it; ``client.behaviour.spec``), judged by
``lab.metrics.judge``, the same code whatever the behaviour: wall following = no collision, wall
band fraction >= 0.8 and distance >= 70% of the teacher's from the same start; maze = goal
reached with no collision within S.

What was learned is judged by the tree alone: ``success_rate`` (and the table) are the tree's
own answers driven as they are. Beside it, when the tree's learning rule has the controller's
guard on (``client.behaviour.rule.GuardSettings``: the loop hysteresis, and for a tree taught
by hand the path check), the same episodes are driven through that guard, as ``rhbl
controller`` drives the tree: the report's ``guarded`` has that run's success and collisions,
``guard`` the settings used and the guard's interventions (reversals overruled, of them driven
straight on, forward orders turned into rotations). ``--no-guard``: the tree alone only; the
other ``--guard-*`` options replace a part of the rule's guard.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json

from client.behaviour import guard
from client.behaviour.learning import TreePolicy
from client.behaviour.spec import Behaviour
from lab import metrics, practice
from lab.behaviours import behaviour_arg, behaviour_for_world, get, teaching_world, world_of
from lab.harness import DT, OnStep, resolve_world
from lab.recipe import EVAL_SECONDS, per_task
from lab.report import episode_table
from lab.sim_tap import record_run
from process import arguments, files
from server import world_arg
from server.world import WorldSpec

__all__ = ["add_arguments", "evaluate", "format_table", "main", "success"]


def success(task: str | Behaviour, m: dict, teacher_m: dict | None) -> bool:
    """The success rule of behaviour ``task`` (a name, a file or a Behaviour) on an episode's
    metrics ``m`` (``teacher_m``: the teacher's from the same start, for a distance compared
    with the teacher's; None: not compared): ``lab.metrics.judge``."""
    return metrics.judge(get(task).rules, m, teacher_m)


def evaluate(spec: WorldSpec, policy: TreePolicy, episodes: int | None = None,
             seconds: float | None = None, seed: int = 0, range_noise: float = 0.0,
             odom_noise: float = 0.0, keep_paths: bool = False, dt: float = DT,
             on_step: OnStep | None = None, behaviour: Behaviour | str | None = None,
             runner=None) -> dict:
    """Run ``policy`` and the behaviour's scripted expert from the start poses (cycled over
    ``episodes``) and judge each episode by the behaviour's success rule (``behaviour``: a
    Behaviour, a shipped one's name or a file; default: the world's, ``lab.behaviours``, and
    in a world no shipped behaviour names, the one the tree was taught: its snapshot's task);
    ``on_step`` sees every step (``lab.harness.step_world``). ``runner`` (a
    ``lab.practice.Runner``): the episodes run there (a process pool, a Dask cluster), the same
    results; not with ``on_step`` or ``keep_paths``, which run here."""
    taught = (getattr(policy, "metadata", None) or {}).get("task")
    b = behaviour_for_world(spec, taught) if behaviour is None else get(behaviour)
    from lab.goals import check_kind

    check_kind(b, policy, "the tree")
    if "goal" in b.rules and spec.goal is None:
        raise ValueError(f"behaviour {b.name!r} is judged by a goal, but world {spec.name!r} "
                         "has no [goal]")
    task = b.name
    starts = spec.start_poses
    episodes = len(starts) if episodes is None else int(episodes)
    seconds = b.seconds if seconds is None else float(seconds)
    learner_eps, teacher_eps, paths = [], [], {"teacher": [], "learner": []}
    starts_k = [starts[k % len(starts)] for k in range(episodes)]
    if runner is not None and on_step is None and not keep_paths and dt == DT:
        learner_eps, teacher_eps = practice.judged_on(runner, b, spec, policy, starts_k, seed,
                                                      seconds, range_noise, odom_noise)
    else:
        for k, start in enumerate(starts_k):
            lm, tm, lt, tt = practice.judged_episode(
                spec, b, policy, start, seconds, seed * 1000 + k, range_noise, odom_noise, dt,
                on_step, both=True)
            learner_eps.append(lm)
            teacher_eps.append(tm)
            if keep_paths:
                paths["teacher"].append(tt.poses)
                paths["learner"].append(lt.poses)
    clf = policy.classifier
    rate = sum(e["success"] for e in learner_eps) / max(1, len(learner_eps))
    report = {
        "world": spec.name,
        "world_path": str(spec.path) if spec.path else None,
        "task": task,
        "behaviour_file": str(b.path) if b.path else None,
        "episodes": episodes,
        "seconds": seconds,
        "seed": seed,
        "range_noise": range_noise,
        "odom_noise": odom_noise,
        "learner": learner_eps,
        "teacher": teacher_eps,
        "success": [e["success"] for e in learner_eps],
        "success_rate": rate,
        "teacher_success_rate": sum(e["success"] for e in teacher_eps) / max(1, len(teacher_eps)),
        "tree": {"nodes": int(clf.node_count_), "height": int(clf.height_)},
        "loops": [dict(loop, episode=k) for k, e in enumerate(learner_eps)
                  for loop in e["oscillation_loops"]],
    }
    if keep_paths:
        report["_paths"] = paths
    return report


def format_table(report: dict) -> str:
    """The report as a markdown table (``lab.report``): per episode the learner's row, then
    the teacher's; the success rates and every oscillation loop after it."""
    title = (f"world {report['world']} ({report['task']}), {report['episodes']} episodes of "
             f"{report['seconds']:g} s, tree {report['tree']['nodes']} nodes, height "
             f"{report['tree']['height']}")
    entries = [(f"{k}: {who}", m)
               for k, (lm, tm) in enumerate(zip(report["learner"], report["teacher"], strict=True))
               for who, m in (("learner", lm), ("teacher", tm))]
    notes = [f"success rate: learner {report['success_rate']:.0%}, teacher "
             f"{report['teacher_success_rate']:.0%}"]
    for loop in report["loops"]:
        x, y, yaw = loop["pose"]
        notes.append(f"rotate-left/rotate-right loop in episode {loop['episode']} at "
                     f"t={loop['time']:g} s; correct it with: rhbl train --resume TREE "
                     f"--start {x:g},{y:g},{yaw:g} ...")
    return episode_table(entries, title=title, notes=notes)


def _feature_pair(text: str) -> tuple[int, int]:
    try:
        i, j = (int(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"must be two feature indices I,J (e.g. 0,1), got {text!r}") from None
    if not (0 <= i < 10_000 and 0 <= j < 10_000) or i == j:
        raise ValueError(f"must be two different feature indices >= 0, got {text!r}")
    return i, j


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default=None, type=world_arg,
                        help="world file (or a shipped world's name); default: the first world "
                             "--behaviour is taught in")
    parser.add_argument("--behaviour", default=None, type=behaviour_arg,
                        help="judge by this behaviour's success rule, with its scripted expert "
                             "as the baseline (a shipped behaviour's name, 'rhbl behaviours' "
                             "lists them, or a behaviour file); default: the world's")
    parser.add_argument("--tree", required=True, type=arguments.input_file,
                        help="the tree's snapshot (of rhbl train, rhbl learner, rhbl refine, ...)")
    parser.add_argument("--episodes", type=arguments.positive_int, default=None,
                        help="episodes, cycling over the world's start poses (default: one per pose)")
    parser.add_argument("--seconds", type=arguments.seconds, default=None,
                        help=f"sim seconds per episode (default: the behaviour's time limit: "
                             f"{per_task(EVAL_SECONDS)})")
    parser.add_argument("--seed", type=arguments.seed, default=0,
                        help="episode k runs with seed SEED*1000+k (the noise; default 0)")
    parser.add_argument("--range-noise", type=arguments.non_negative_float, default=0.0,
                        help="laser noise (server option)")
    parser.add_argument("--odom-noise", type=arguments.non_negative_float, default=0.0,
                        help="odometry noise (server option)")
    parser.add_argument("--json", default=None, type=arguments.output_file,
                        help="write the full report here")
    parser.add_argument("--plot", default=None, type=arguments.output_file,
                        help="draw world and paths to this PNG")
    parser.add_argument("--spheres", default=None, metavar="I,J",
                        type=arguments.checked_list("feature pair", _feature_pair, "0,1"),
                        help="with --plot: also draw the tree's spheres projected on features I,J")
    guard.add_arguments(parser)
    parser.add_argument("--record", metavar="FILE", default=None, type=arguments.output_file,
                        help="also write the episodes (tree and teacher runs) as an MCAP "
                             "recording (docs/recording.md)")
    practice.add_arguments(parser)


def _goals_main(args, spec: WorldSpec, policy, b: Behaviour | None) -> int:
    """``rhbl evaluate`` of a goal behaviour's snapshot: the goal changes in the table's
    notes (when, which goal, the next one and why) and in the JSON report."""
    from lab.goals import evaluate_goals, format_goal_table, guarded

    given = [flag for flag, on in (
        ("--range-noise", bool(args.range_noise)), ("--odom-noise", bool(args.odom_noise)),
        ("--spheres", bool(args.spheres)), ("--guard-hold", args.guard_hold is not None),
        ("--guard-straight" if args.guard_straight else "--no-guard-straight",
         args.guard_straight is not None),
        ("--guard-clearance", args.guard_clearance is not None)) if on]
    if given:
        raise ValueError(f"{', '.join(given)}: not for a tree with goals yet (its trees are "
                         "judged alone and, beside them, driven through the controller's guard; "
                         "--no-guard: alone only; docs/goals.md)")
    b = get(policy.metadata.get("task")) if b is None else b
    driven = guarded(policy, args.guard)  # beside the trees alone: through the rule's guard
    here = bool(args.record or args.plot)
    if here and (args.workers or args.cluster):
        raise ValueError("--record and --plot run the episodes in this process: leave out "
                         "--workers and --cluster")
    run = {"episodes": args.episodes, "seconds": args.seconds, "seed": args.seed}
    with (contextlib.nullcontext() if here else practice.runner_from_args(args)) as runner:
        with record_run(args.record, "rhbl evaluate") as tap:
            report = evaluate_goals(spec, policy, b, on_step=None if tap is None else tap.step,
                                    keep_paths=bool(args.plot), runner=runner, **run)
        g = (evaluate_goals(spec, driven, b, runner=runner, **run)  # (None: here)
             if driven is not policy else None)
    paths = report.pop("_paths", None)
    report["judged"] = "the trees alone"
    report["guard"] = report["guarded"] = None
    if g is not None:
        report["guard"] = g["guard"]
        report["guarded"] = _guarded(g)
    print(format_goal_table(report))
    print(_beside(report, "trees") if g is not None else "driven by the trees alone")
    return _write(args, spec, report, paths)


def _guarded(g: dict) -> dict:
    """The guarded run's figures for the report (``guarded``)."""
    return {"success_rate": g["success_rate"], "success": g["success"],
            "collisions": sum(e["collisions"] for e in g["learner"]), "loops": len(g["loops"])}


def _beside(report: dict, what: str) -> str:
    """The line that says the judged figure (the ``what`` alone) and, beside it, the guarded
    run and what the guard did."""
    gd, gr = report["guarded"], report["guard"]
    return (f"judged by the {what} alone: {report['success_rate']:.0%} "
            f"({sum(e['collisions'] for e in report['learner'])} collisions); driven through "
            f"the controller's guard as its rule says (rhbl controller; a safety layer, "
            f"--no-guard: the {what} alone only): {gd['success_rate']:.0%} "
            f"({gd['collisions']} collisions), the guard overruled {gr['overruled']} "
            f"rotation reversals ({gr['straight_on']} of them driven straight on) and turned "
            f"{gr['avoided']} forward orders into a rotation (path check "
            f"{gr['clearance']:g} m)")


def main(args) -> int:
    if args.spheres and not args.plot:
        raise ValueError("--spheres goes with --plot (it draws the spheres in the picture)")
    if args.world is None and args.behaviour is None:
        raise ValueError("give --world W or --behaviour B (or both)")
    b = get(args.behaviour) if args.behaviour else None
    if args.world is None:
        spec = teaching_world(b)
    else:
        spec = resolve_world(args.world) if b is None else world_of(b, args.world)
    from client.behaviour.goals import GoalPolicy, load_policy

    policy = load_policy(args.tree)
    if isinstance(policy, GoalPolicy):  # goals in order (lab.goals)
        return _goals_main(args, spec, policy, b)
    dims = args.spheres or (0, 1)
    if args.spheres and max(dims) >= policy.classifier.n_features_in_:
        raise ValueError(f"--spheres {dims[0]},{dims[1]}: the tree {args.tree} has "
                         f"{policy.classifier.n_features_in_} features (0 .. "
                         f"{policy.classifier.n_features_in_ - 1})")
    settings = guard.settings(args, policy.metadata)
    if (args.record or args.plot) and (args.workers or args.cluster):
        raise ValueError("--record and --plot run the episodes in this process: leave out "
                         "--workers and --cluster")
    here = bool(args.record or args.plot)
    run = {"episodes": args.episodes, "seconds": args.seconds, "seed": args.seed,
           "range_noise": args.range_noise, "odom_noise": args.odom_noise, "behaviour": b}
    with (contextlib.nullcontext() if here else practice.runner_from_args(args)) as runner:
        with record_run(args.record, "rhbl evaluate") as tap:  # None without --record
            report = evaluate(spec, policy, keep_paths=bool(args.plot),
                              on_step=None if tap is None else tap.step, runner=runner, **run)
        guarded = g = None
        if settings.on:  # the same episodes as the controller drives them: through the guard
            guarded = guard.RotationGuard.of(settings, policy)
            g = evaluate(spec, guarded, runner=runner, **run)
    paths = report.pop("_paths", None)
    report["judged"] = "the tree alone"
    report["guard"] = report["guarded"] = None
    if settings.on:
        report["guard"] = {**dataclasses.asdict(settings), **guarded.interventions}
        report["guarded"] = _guarded(g)
    print(format_table(report))
    if settings.on:
        print(_beside(report, "tree"))
    return _write(args, spec, report, paths,
                  spheres=policy.classifier if args.spheres else None, dims=dims)


def _write(args, spec: WorldSpec, report: dict, paths, **draw) -> int:
    """``--json`` (the report) and ``--plot`` (the paths; ``draw``: the spheres to draw)."""
    if args.json:
        files.write_text(args.json, json.dumps(report, indent=1), "--json")
        print(f"wrote {args.json}")
    if args.plot:
        from lab.plot import plot_paths

        plot_paths(spec, paths, args.plot,
                   title=f"{spec.name}: teacher (blue) and learned robot (red), "
                         f"success {report['success_rate']:.0%}", **draw)
        print(f"wrote {args.plot}")
    return 0
