"""``rhbl experiment wall-following|maze``: repeat train-then-evaluate over N seeds and print the
paper's Table I beside ours, with success rates and their spread.

    result = run_experiment("wall-following", trials=5, ...)   # dict, see --json
    rows = tradeoff(task, variants, trials)                      # tree size vs success

Each trial: the task's scripted teacher demonstrates on the shipped world (``room`` for wall
following, ``maze`` for the maze) for ``--train-seconds`` with seed ``i`` (perturbations differ),
then the tree is evaluated from every start pose of the training world and of each
``--eval-world`` (generalisation), optionally with range/odometry noise.
"""

from __future__ import annotations

import argparse
import glob
import json
import time
from pathlib import Path

from client.behaviour.features import FEATURES
from client.behaviour.learning import TreePolicy
from client.behaviour.policies import make_policy
from lab import metrics
from lab.evaluate import evaluate
from lab.harness import (
    TRAINING,
    add_compact_arguments,
    compact_overrides,
    make_learner,
    parse_scales,
    resolve_world,
    train,
)

__all__ = ["PAPER", "TEACHERS", "add_arguments", "main", "run_experiment", "run_trial", "table_i"]

PAPER = {"wall-following": (53.4, 12.0), "maze": (412.5, 13.0)}
WORLD = {"wall-following": "room", "maze": "maze"}
# teacher styles: the default smooth one (hysteresis + 0.3 s minimum dwell) and a bang-bang one
TEACHERS = {"reactive": {"style": "reactive"}, "smooth": {"style": "smooth"},
            "bangbang": {"style": "smooth", "dwell": 1, "off": 0.45}}


def _worlds_dir() -> Path:
    return Path(__file__).resolve().parent.parent / "server" / "worlds"


def default_eval_worlds(task: str) -> list[str]:
    pat = "eval-room*.toml" if task == "wall-following" else "eval-maze*.toml"
    return sorted(glob.glob(str(_worlds_dir() / pat)))


def run_trial(task: str, seed: int, world: str | None = None, train_seconds: float | None = None,
              eval_seconds: float | None = None, episodes: int | None = None,
              eval_worlds: list[str] = (), perturb: float | None = None, teacher: str = "reactive",
              features: str | None = None, stride: int | None = None,
              min_delta: float | None = None, range_noise: float = 0.0,
              odom_noise: float = 0.0, train_noise: bool = False, starts: str | None = None,
              segment: float | None = None, random_segment: float | None = None,
              turn: float | None = None, consistent: bool | None = None,
              rounds: int | None = None, round_seconds: float | None = None,
              takeover: float | None = None, round_free: int | None = None,
              augment: int | None = None, augment_scale: float | None = None,
              round_scales: tuple[float, ...] | None = None,
              teacher_params: dict | None = None, compact: dict | None = None,
              **tree_params) -> dict:
    spec = resolve_world(world or WORLD[task])
    tree_params.setdefault("record", bool(compact if compact is not None
                                          else TRAINING[task].get("compact")))
    learner = make_learner(task, features=features, stride=stride, min_delta=min_delta,
                           **tree_params)
    seconds = train_seconds or TRAINING[task]["seconds"]
    policy = make_policy(task, actions=learner.actions, **TEACHERS[teacher], **(teacher_params or {}))
    t0 = time.perf_counter()
    train(spec, learner, seconds, seed=seed, perturb=perturb, policy=policy,
          range_noise=range_noise if train_noise else 0.0,
          odom_noise=odom_noise if train_noise else 0.0, starts=starts, segment=segment,
          random_starts=random_segment, turn=turn, consistent=consistent, rounds=rounds,
          round_seconds=round_seconds, takeover=takeover, round_free=round_free,
          augment=augment, augment_scale=augment_scale, round_scales=round_scales,
          compact=compact)
    t_train = time.perf_counter() - t0
    tree = TreePolicy.from_learner(learner)
    rec = learner.session.get("compaction") or {}
    out = {"seed": seed, "nodes": learner.nodes, "height": learner.height,
           "nodes_before": rec.get("nodes_before", learner.nodes),
           "height_before": rec.get("height_before", learner.height),
           "compaction": rec.get("method"),
           "vectors": learner.vectors, "train_wall_s": round(t_train, 2), "worlds": {}}
    for w in [spec.path or spec.name, *eval_worlds]:
        wspec = resolve_world(str(w))
        rep = evaluate(wspec, tree, episodes=episodes, seconds=eval_seconds, seed=seed,
                       range_noise=range_noise, odom_noise=odom_noise)
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


def run_experiment(task: str, trials: int = 5, seed0: int = 0, **kw) -> dict:
    rows = [run_trial(task, seed0 + i, **kw) for i in range(trials)]
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
    return {"task": task, "trials": trials, "params": {k: v for k, v in kw.items()
                                                       if isinstance(v, str | int | float | type(None))},
            "rows": rows, "summary": summary}


def table_i(results: dict[str, dict]) -> str:
    lines = ["Table I. Spawned tree properties (paper vs this reproduction, mean +/- std over trials)",
             f"{'scenario':16} | {'paper nodes':>11} {'paper height':>12} | {'our nodes':>15} "
             f"{'our height':>12} | {'success (training world)':>24}"]
    for task, res in results.items():
        s = res["summary"]
        pn, ph = PAPER[task]
        first = next(iter(s["worlds"]))
        sr = s["worlds"][first]["success_rate"]
        lines.append(f"{task:16} | {pn:>11.1f} {ph:>12.0f} | {s['nodes']['mean']:>8.1f} +/- {s['nodes']['std']:<4.0f}"
                     f" {s['height']['mean']:>5.1f} +/- {s['height']['std']:<3.1f} | "
                     f"{sr['mean']:>6.1%} (min {sr['min']:.0%}, max {sr['max']:.0%})")
    if any(r.get("compaction") for res in results.values() for r in res["rows"]):
        lines.append("compacted trees; before compaction (mean): " + "; ".join(
            f"{task} {res['summary']['nodes_before']['mean']:.1f} nodes, height "
            f"{res['summary']['height_before']['mean']:.1f}" for task, res in results.items()))
        lines.append("per trial (nodes, height before -> after): " + "; ".join(
            f"{task} " + ", ".join(f"s{r['seed']} {r['nodes_before']}/{r['height_before']} -> "
                                   f"{r['nodes']}/{r['height']}" for r in res["rows"])
            for task, res in results.items()))
    return "\n".join(lines)


def format_worlds(res: dict) -> str:
    lines = [f"{'world':24} {'success mean':>12} {'min':>5} {'max':>5} {'teacher':>8} {'collisions':>10} {'loops':>5}"]
    for w, s in res["summary"]["worlds"].items():
        sr = s["success_rate"]
        lines.append(f"{w:24} {sr['mean']:>12.1%} {sr['min']:>5.0%} {sr['max']:>5.0%} "
                     f"{s['teacher_success_rate']['mean']:>8.0%} {s['collisions']:>10} {s['loops']:>5}")
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("task", choices=["wall-following", "maze", "both"])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0, help="first trial's seed")
    parser.add_argument("--world", default=None, help="training world (default: room / maze)")
    parser.add_argument("--train-seconds", type=float, default=None)
    parser.add_argument("--seconds", type=float, default=None, help="evaluation seconds per episode")
    parser.add_argument("--episodes", type=int, default=None)
    parser.add_argument("--eval-world", action="append", default=None,
                        help="extra evaluation world (repeatable); default: server/worlds/eval-room*"
                             " or eval-maze*; 'none' for none")
    parser.add_argument("--perturb", type=float, default=None)
    parser.add_argument("--teacher", choices=sorted(TEACHERS), default="reactive")
    parser.add_argument("--features", choices=sorted(FEATURES), default=None)
    parser.add_argument("--stride", type=int, default=None)
    parser.add_argument("--spawn", choices=["all", "winner"], default=None)
    parser.add_argument("--starts", choices=["default", "world", "free"], default=None)
    parser.add_argument("--segment", type=float, default=None)
    parser.add_argument("--random-segment", type=float, default=None)
    parser.add_argument("--consistent", action="store_true", default=None)
    parser.add_argument("--rounds", type=int, default=None, help="corrective (DAgger) rounds")
    parser.add_argument("--round-seconds", type=float, default=None)
    parser.add_argument("--takeover", type=float, default=None)
    parser.add_argument("--round-free", type=int, default=None,
                        help="corrective rounds also drive from N random free-space poses "
                             "(default: the recipe's)")
    parser.add_argument("--augment", type=int, default=None,
                        help="scale augmentation copies per labelled state (see rhbl train)")
    parser.add_argument("--augment-scale", type=float, default=None)
    parser.add_argument("--round-scales", type=parse_scales, default=None, metavar="F,F",
                        help="corrective rounds also in the training world scaled by these "
                             "factors ('none': only the world itself; default: the recipe's)")
    parser.add_argument("--range-noise", type=float, default=0.0)
    parser.add_argument("--odom-noise", type=float, default=0.0)
    parser.add_argument("--train-noise", action="store_true",
                        help="also demonstrate with the noise on (default: noise only in evaluation)")
    add_compact_arguments(parser)
    parser.add_argument("--json", default=None)


def main(args) -> int:
    tasks = ["wall-following", "maze"] if args.task == "both" else [args.task]
    results = {}
    t0 = time.perf_counter()
    for task in tasks:
        if args.eval_world == ["none"]:
            ev: list[str] = []
        else:
            ev = args.eval_world if args.eval_world is not None else default_eval_worlds(task)
        tree = {"spawn": args.spawn} if args.spawn else {}
        res = run_experiment(task, trials=args.trials, seed0=args.seed, world=args.world,
                             train_seconds=args.train_seconds, eval_seconds=args.seconds,
                             episodes=args.episodes, eval_worlds=ev, perturb=args.perturb,
                             teacher=args.teacher, features=args.features, stride=args.stride,
                             range_noise=args.range_noise, odom_noise=args.odom_noise,
                             train_noise=args.train_noise, starts=args.starts,
                             segment=args.segment, random_segment=args.random_segment,
                             consistent=args.consistent, rounds=args.rounds,
                             round_seconds=args.round_seconds, takeover=args.takeover,
                             round_free=args.round_free, augment=args.augment,
                             augment_scale=args.augment_scale,
                             round_scales=args.round_scales,
                             compact=compact_overrides(task, args), **tree)
        results[task] = res
        print(f"\n{task}: {args.trials} trials")
        print(format_worlds(res))
    print()
    print(table_i(results))
    print(f"({time.perf_counter() - t0:.0f} s)")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0
