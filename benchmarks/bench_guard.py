"""The rotation guard on the scripted teacher's trees: the same trees evaluated with and without
``client.behaviour.guard.RotationGuard``, side by side.

    python benchmarks/bench_guard.py [--task wall-following|maze] [--trials 5] [--clearance M] \
        [--json out.json]

Each trial trains the task's default recipe (``lab.recipe``, as ``rhbl experiment`` does) with
seed ``i`` and evaluates the tree, then the same tree through the guard, from every start pose
of the training world and of the task's eval worlds. Printed per world: success mean (min over
trials), loops and collisions, without and with the guard, and how many rotation reversals the
guard overruled. The guard's path check is ``rhbl controller``'s default for these trees
(``settings_for``: the tree's rule's, off for the scripted teacher's) unless ``--clearance M`` forces it.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from client.behaviour.guard import RotationGuard, settings_for
from client.behaviour.learning import TreePolicy
from lab.evaluate import evaluate
from lab.experiment import default_eval_worlds
from lab.harness import make_learner, resolve_world
from lab.recipe import recipe_for
from lab.train import train


def trial(task: str, seed: int, worlds, clearance: float | None = None) -> dict:
    recipe = recipe_for(task)
    learner = make_learner(recipe)
    train(resolve_world(recipe.world), learner, recipe, seed=seed)
    tree = TreePolicy.from_learner(learner)
    out = {"seed": seed, "nodes": learner.nodes, "worlds": {}}
    for w in worlds:
        spec = resolve_world(w)
        row = {}
        guard = RotationGuard(tree, clearance=(settings_for(tree.metadata).clearance if clearance is None
                                               else clearance))
        for name, policy in (("plain", tree), ("guard", guard)):
            rep = evaluate(spec, policy, seed=seed)
            row[name] = {"success": rep["success_rate"], "loops": len(rep["loops"]),
                         "collisions": sum(e["collisions"] for e in rep["learner"])}
        row["overruled"] = guard.overruled  # reversals the guard overruled in these episodes
        row["avoided"] = guard.avoided  # forward orders it turned into a rotation in place
        out["worlds"][spec.name] = row
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="wall-following", choices=["wall-following", "maze"])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--clearance", type=float, default=None, metavar="M",
                    help="the guard's path check (default: rhbl controller's for the tree)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    recipe = recipe_for(args.task)
    worlds = [recipe.world, *default_eval_worlds(args.task)]
    rows = []
    for seed in range(args.trials):
        t0 = time.perf_counter()
        rows.append(trial(args.task, seed, worlds, args.clearance))
        print(f"trial {seed}: {rows[-1]['nodes']} nodes, {time.perf_counter() - t0:.0f} s: "
              + ", ".join(f"{w} {100 * r['plain']['success']:.0f}/{100 * r['guard']['success']:.0f}%"
                          for w, r in rows[-1]["worlds"].items()), flush=True)
    print(f"\n{args.task}, {args.trials} trials: success mean (min over trials), loops, "
          "collisions; without | with the guard")
    print("| world | without the guard | with the guard | reversals overruled | forward orders "
          "avoided |")
    print("|---|---|---|---|---|")
    for w in rows[0]["worlds"]:
        cells = []
        for name in ("plain", "guard"):
            s = [r["worlds"][w][name]["success"] for r in rows]
            loops = sum(r["worlds"][w][name]["loops"] for r in rows)
            coll = sum(r["worlds"][w][name]["collisions"] for r in rows)
            cells.append(f"{100 * sum(s) / len(s):.1f}% ({100 * min(s):.0f}), {loops} loops, "
                         f"{coll} collisions")
        print(f"| {w} | {cells[0]} | {cells[1]} | "
              f"{sum(r['worlds'][w]['overruled'] for r in rows)} | "
              f"{sum(r['worlds'][w]['avoided'] for r in rows)} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
