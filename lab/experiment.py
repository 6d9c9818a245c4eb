"""``rhbl experiment BEHAVIOUR|both``: repeat train-then-evaluate over N seeds and print the
paper's Table I beside ours, with success rates and their spread.

    result = run_experiment("wall-following", trials=5, ...)   # dict, see --json
    rows = tradeoff(task, variants, trials)                      # tree size vs success

Each trial: the behaviour's scripted expert demonstrates in its first teaching world (``room``
for wall following, ``maze`` for the maze) as its recipe says (``lab.behaviours.recipe_of``; the
recipe flags change it) with seed ``i`` (perturbations differ), then the tree is evaluated, by
the behaviour's success rule, from every start pose of the training world and of each of its
held-out worlds or ``--eval-world`` (generalisation), optionally with range/odometry noise.
BEHAVIOUR is a shipped behaviour's name or a behaviour file; ``both`` is wall following and the
maze, the paper's two.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

from client.behaviour.learning import TreePolicy
from client.behaviour.spec import Behaviour
from lab import metrics
from lab.behaviours import add_paper_argument, behaviour_arg, get, recipe_of, world_of
from lab.evaluate import evaluate
from lab.harness import make_learner
from lab.recipe import Recipe, add_recipe_arguments, recipe_from_args
from lab.report import table
from lab.train import train
from process import arguments, files
from server import world_arg

__all__ = ["PAPER", "TEACHERS", "add_arguments", "main", "run_experiment", "run_trial", "table_i"]

PAPER = {"wall-following": (53.4, 12.0), "maze": (412.5, 13.0)}
# teacher styles: the default smooth one (hysteresis + 0.3 s minimum dwell) and a bang-bang one
TEACHERS = {"reactive": {"style": "reactive"}, "smooth": {"style": "smooth"},
            "bangbang": {"style": "smooth", "dwell": 1, "off": 0.45}}


def default_eval_worlds(task: str | Behaviour) -> list[str]:
    """The held-out worlds of behaviour ``task`` (a name, a file or a Behaviour)."""
    return list(get(task).held_out)


def run_trial(task: str | Behaviour, seed: int, recipe: Recipe | None = None, world: str | None = None,
              eval_seconds: float | None = None, episodes: int | None = None,
              eval_worlds: list[str] = (), teacher: str = "reactive", range_noise: float = 0.0,
              odom_noise: float = 0.0, train_noise: bool = False,
              teacher_params: dict | None = None) -> dict:
    """Train ``recipe`` (default: the behaviour's) on ``world`` (default: the recipe's) with
    ``seed``, then evaluate the tree there and on each of ``eval_worlds``, all by the
    behaviour ``task``'s success rule (and, ``world`` not given, in its other teaching
    worlds)."""
    b = get(task)
    recipe = recipe_of(b) if recipe is None else recipe
    spec = world_of(b, world or recipe.world)
    learner = make_learner(recipe)
    policy = b.expert(actions=learner.actions, **TEACHERS[teacher], **(teacher_params or {}))
    t0 = time.perf_counter()
    train(spec, learner, recipe, seed=seed, policy=policy, behaviour=b,
          range_noise=range_noise if train_noise else 0.0,
          odom_noise=odom_noise if train_noise else 0.0)
    t_train = time.perf_counter() - t0
    tree = TreePolicy.from_learner(learner)
    rec = learner.session.get("compaction") or {}
    out = {"seed": seed, "nodes": learner.nodes, "height": learner.height,
           "nodes_before": rec.get("nodes_before", learner.nodes),
           "height_before": rec.get("height_before", learner.height),
           "compaction": rec.get("method"),
           "vectors": learner.vectors, "train_wall_s": round(t_train, 2), "worlds": {}}
    taught = [] if world is not None else [w for w in recipe.round_worlds if w != recipe.world]
    for w in [world or recipe.world, *taught, *eval_worlds]:
        wspec = world_of(b, str(w))
        rep = evaluate(wspec, tree, episodes=episodes, seconds=eval_seconds, seed=seed,
                       range_noise=range_noise, odom_noise=odom_noise, behaviour=b)
        out["worlds"][wspec.name] = {
            "success_rate": rep["success_rate"],
            "teacher_success_rate": rep["teacher_success_rate"],
            "collisions": sum(e["collisions"] for e in rep["learner"]),
            "oscillations": sum(e["oscillations"] for e in rep["learner"]),
            "loops": len(rep["loops"]),
            "agreement": metrics.summarize([e["teacher_agreement"] for e in rep["learner"]])["mean"],
            "episodes": rep["episodes"],
        }
    return out


def run_experiment(task: str | Behaviour, trials: int = 5, seed0: int = 0,
                   recipe: Recipe | None = None, **kw) -> dict:
    """``trials`` runs of ``run_trial`` (seeds ``seed0``, ``seed0 + 1``, ...) and their summary."""
    b = get(task)
    recipe = recipe_of(b) if recipe is None else recipe
    rows = [run_trial(b, seed0 + i, recipe, **kw) for i in range(trials)]
    worlds = list(rows[0]["worlds"]) if rows else []
    summary = {
        "nodes": metrics.summarize([r["nodes"] for r in rows]),
        "height": metrics.summarize([r["height"] for r in rows]),
        "nodes_before": metrics.summarize([r["nodes_before"] for r in rows]),
        "height_before": metrics.summarize([r["height_before"] for r in rows]),
        "worlds": {w: {"success_rate": metrics.summarize([r["worlds"][w]["success_rate"] for r in rows]),
                       "teacher_success_rate": metrics.summarize(
                           [r["worlds"][w]["teacher_success_rate"] for r in rows]),
                       "collisions": sum(r["worlds"][w]["collisions"] for r in rows),
                       "loops": sum(r["worlds"][w]["loops"] for r in rows)}
                   for w in worlds},
    }
    params = {k: v for k, v in kw.items() if isinstance(v, str | int | float | type(None))}
    return {"task": b.name, "trials": trials, "recipe": _plain(recipe),
            "params": params, "rows": rows, "summary": summary}


def _plain(recipe: Recipe) -> dict:
    """The recipe's fields as JSON data (an inline perception as its feature spec's dict)."""
    out = {f.name: getattr(recipe, f.name) for f in dataclasses.fields(recipe)}
    if not isinstance(out["features"], str):
        out["features"] = out["features"].to_dict()
    return out


def table_i(results: dict[str, dict], paper: bool = True) -> str:
    """The paper's Table I beside ours (markdown, ``lab.report``; ``paper`` False: the trees
    of the behaviours' own recipes, not the reproduction). When the recipe compacted the
    trees: also the nodes and height before compaction (means), and per trial in notes."""
    compacted = any(r.get("compaction") for res in results.values() for r in res["rows"])
    rows = []
    for task, res in results.items():
        s = res["summary"]
        pn, ph = PAPER.get(task, (None, None))
        sr = next(iter(s["worlds"].values()))["success_rate"]
        before = [f"{s['nodes_before']['mean']:.1f}", f"{s['height_before']['mean']:.1f}"] \
            if compacted else []
        rows.append([task, "-" if pn is None else f"{pn:.1f}", "-" if ph is None else f"{ph:.0f}",
                     *before,
                     f"{s['nodes']['mean']:.1f} +/- {s['nodes']['std']:.0f}",
                     f"{s['height']['mean']:.1f} +/- {s['height']['std']:.1f}",
                     f"{sr['mean']:.1%} (min {sr['min']:.0%}, max {sr['max']:.0%})"])
    notes = [f"{task} per trial (nodes/height before -> after compaction): " + ", ".join(
        f"s{r['seed']} {r['nodes_before']}/{r['height_before']} -> {r['nodes']}/{r['height']}"
        for r in res["rows"]) for task, res in results.items()] if compacted else []
    before_cols = ["nodes before compaction", "height before compaction"] if compacted else []
    return table(["scenario", "paper nodes", "paper height", *before_cols, "our nodes",
                  "our height", "success (training world)"], rows,
                 title="Table I. Spawned tree properties (paper vs "
                       + ("this reproduction" if paper else "the behaviour's own recipe: "
                          "--paper reproduces the paper's scenario")
                       + ", mean +/- std over trials)", notes=notes)


def format_worlds(res: dict) -> str:
    """Success per evaluation world over the trials (markdown, ``lab.report``)."""
    rows = []
    for w, s in res["summary"]["worlds"].items():
        sr = s["success_rate"]
        rows.append([w, f"{sr['mean']:.1%}", f"{sr['min']:.0%}", f"{sr['max']:.0%}",
                     f"{s['teacher_success_rate']['mean']:.0%}", s["collisions"], s["loops"]])
    return table(["world", "success mean", "min", "max", "teacher", "collisions", "loops"], rows)


BOTH = ("wall-following", "maze")  # the paper's two


def _check_task(text: str) -> str:
    return text if text == "both" else behaviour_arg.parse(text)


_task = arguments.Checked("behaviour", _check_task)
_task.kind, _task.example = "world", "wall-following"  # a shipped name or a file, as a world


def _check_eval_world(text: str) -> str:
    return text if text == "none" else world_arg.parse(text)


_eval_world = arguments.Checked("world", _check_eval_world)
_eval_world.kind, _eval_world.example = "world", "room"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", metavar="BEHAVIOUR", type=_task,
                        help="a shipped behaviour's name ('rhbl behaviours' lists them), a "
                             "behaviour file, or 'both' (wall-following and maze)")
    parser.add_argument("--trials", type=arguments.positive_int, default=5)
    parser.add_argument("--seed", type=arguments.seed, default=0, help="first trial's seed")
    parser.add_argument("--world", default=None, type=world_arg,
                        help="training world (default: the behaviour's first teaching world)")
    parser.add_argument("--seconds", type=arguments.seconds, default=None,
                        help="evaluation seconds per episode")
    parser.add_argument("--episodes", type=arguments.positive_int, default=None)
    parser.add_argument("--eval-world", action="append", default=None, type=_eval_world,
                        help="extra evaluation world (repeatable); default: the behaviour's "
                             "held-out worlds; 'none' for none")
    parser.add_argument("--teacher", choices=sorted(TEACHERS), default="reactive")
    add_paper_argument(parser)
    add_recipe_arguments(parser, seconds="--train-seconds")
    parser.add_argument("--range-noise", type=arguments.non_negative_float, default=0.0)
    parser.add_argument("--odom-noise", type=arguments.non_negative_float, default=0.0)
    parser.add_argument("--train-noise", action="store_true",
                        help="also demonstrate with the noise on (default: noise only in evaluation)")
    parser.add_argument("--json", default=None, type=arguments.output_file,
                        help="write every trial's results here (JSON)")


def _goal_experiment(b: Behaviour, args, ev: list[str]) -> dict:
    from lab.goals import goal_experiment_table, run_goal_trial

    recipe = recipe_from_args(recipe_of(b, args.paper), args)
    if args.world:
        recipe = recipe.replace(world=args.world)
    rows = [run_goal_trial(b, args.seed + i, recipe, [recipe.world, *ev], episodes=args.episodes,
                           seconds=args.seconds)
            for i in range(args.trials)]
    print(f"\n{b.name}: {args.trials} trials")
    print(goal_experiment_table(b, rows))
    return {"task": b.name, "trials": args.trials, "recipe": _plain(recipe), "rows": rows}


def main(args) -> int:
    tasks = [get(t) for t in (BOTH if args.task == "both" else [args.task])]
    results = {}
    t0 = time.perf_counter()
    for task in tasks:
        if args.eval_world == ["none"]:
            ev: list[str] = []
        else:
            ev = args.eval_world if args.eval_world is not None else default_eval_worlds(task)
        if task.goals is not None:  # goals in order: beside the reactive tree (lab.goals)
            results[task.name] = _goal_experiment(task, args, ev)
            continue
        recipe = recipe_from_args(recipe_of(task, args.paper), args)
        res = run_experiment(task, trials=args.trials, seed0=args.seed, recipe=recipe,
                             world=args.world,
                             eval_seconds=args.seconds, episodes=args.episodes, eval_worlds=ev,
                             teacher=args.teacher, range_noise=args.range_noise,
                             odom_noise=args.odom_noise, train_noise=args.train_noise)
        results[task.name] = res
        print(f"\n{task.name}: {args.trials} trials")
        print(format_worlds(res))
    print()
    paper = {k: v for k, v in results.items() if "summary" in v}
    if paper:
        print(table_i(paper, args.paper))
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.json:
        files.write_text(args.json, json.dumps(results, indent=1), "--json")
    return 0
