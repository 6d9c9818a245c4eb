"""Tree size against success: the trade-off study of docs/experiments.md.

    python benchmarks/bench_experiment.py [--trials 3] [--task wall-following] [--json out.json]
        [--study size|tradeoff|beams]

Each row trains on the task's shipped world with one recipe (spawn rule, teacher style,
perturbation, sample stride) for ``--trials`` seeds and evaluates from every start pose.
"""

from __future__ import annotations

import argparse
import json
import time

from client.behaviour.features import FeatureSpec
from lab.experiment import run_experiment
from lab.recipe import RECIPES

BEAMS = [
    ("wall side 0-90 deg (default)", (0.0, 22.5, 45.0, 67.5, 90.0)),
    ("even 0-180 deg (paper figure)", (0.0, 45.0, 90.0, 135.0, 180.0)),
    ("right side 0-60 deg", (0.0, 15.0, 30.0, 45.0, 60.0)),
    ("0-120 deg", (0.0, 30.0, 60.0, 90.0, 120.0)),
]

ROWS = [
    # name, teacher, spawn, perturb, stride
    ("paper literal, bang-bang teacher", "bangbang", "all", 0.0, 1),
    ("paper literal, smooth teacher", "smooth", "all", 0.05, 1),
    ("winner, bang-bang teacher", "bangbang", "winner", 0.05, 1),
    ("winner, smooth teacher (default)", "smooth", "winner", 0.05, 1),
    ("winner, smooth, no perturbation", "smooth", "winner", 0.0, 1),
    ("winner, smooth, perturb 0.2", "smooth", "winner", 0.2, 1),
    ("winner, smooth, 2 Hz samples", "smooth", "winner", 0.05, 5),
    ("winner, smooth, 1 Hz samples", "smooth", "winner", 0.05, 10),
]


# the size study of the current recipe (docs/experiments.md): reactive teacher, free-space
# demonstrations, corrective rounds; each row overrides one setting
SIZE_ROWS = [
    ("winner (default)", {}),
    ("literal spawn=all (paper)", {"spawn": "all"}),
    ("min_radius 0.005", {"min_radius": 0.005}),
    ("min_radius 0.02", {"min_radius": 0.02}),
    ("max_depth 20", {"max_depth": 20}),
    ("stride 2", {"stride": 2}),
    ("stride 5", {"stride": 5}),
    ("euclidean", {"distance": "euclidean"}),
    ("1 corrective round", {"rounds": 1}),
    ("no corrective round", {"rounds": 0}),
]


def size_study(task: str, trials: int) -> list[dict]:
    from lab.experiment import default_eval_worlds

    out = []
    print(f"{'setting':28} {'nodes':>7} {'height':>6}  success per world (mean/min)")
    for name, kw in SIZE_ROWS:
        res = run_experiment(task, trials=trials, eval_worlds=default_eval_worlds(task),
                             recipe=RECIPES[task].replace(**kw))
        s = res["summary"]
        worlds = {w: (v["success_rate"]["mean"], v["success_rate"]["min"])
                  for w, v in s["worlds"].items()}
        out.append({"setting": name, **kw, "nodes": s["nodes"]["mean"],
                    "height": s["height"]["mean"], "worlds": worlds})
        print(f"{name:28} {s['nodes']['mean']:>7.0f} {s['height']['mean']:>6.1f}  "
              + " ".join(f"{w}:{m:.0%}/{lo:.0%}" for w, (m, lo) in worlds.items()), flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--task", default="wall-following", choices=["wall-following", "maze"])
    ap.add_argument("--json", default=None)
    ap.add_argument("--study", default="size", choices=["size", "tradeoff", "beams"],
                    help="size: the current recipe's size study (default); tradeoff: the old "
                         "smooth-teacher study; beams: beam choice")
    args = ap.parse_args()
    out = []
    if args.study == "size":
        out = size_study(args.task, args.trials)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(out, fh, indent=1)
        return 0
    if args.study == "beams":
        print(f"{'beams':32} {'success':>8} {'min':>5} {'nodes':>7} {'height':>6} {'collisions':>10}")
        for name, beams in BEAMS:
            res = run_experiment(args.task, trials=args.trials, eval_worlds=[],
                                 recipe=RECIPES[args.task].replace(
                                     features=FeatureSpec(beams=beams)))
            s = res["summary"]
            w = next(iter(s["worlds"].values()))
            out.append({"beams": list(beams), "success": w["success_rate"]["mean"],
                        "nodes": s["nodes"]["mean"], "height": s["height"]["mean"]})
            print(f"{name:32} {w['success_rate']['mean']:>8.1%} {w['success_rate']['min']:>5.0%} "
                  f"{s['nodes']['mean']:>7.0f} {s['height']['mean']:>6.1f} {w['collisions']:>10}",
                  flush=True)
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(out, fh, indent=1)
        return 0
    print(f"{'recipe':36} {'success':>8} {'min':>5} {'nodes':>7} {'height':>6} {'collisions':>10}")
    for name, teacher, spawn, perturb, stride in ROWS:
        t0 = time.perf_counter()
        recipe = RECIPES[args.task].replace(perturb=perturb, stride=stride, spawn=spawn)
        res = run_experiment(args.task, trials=args.trials, eval_worlds=[], teacher=teacher,
                             recipe=recipe)
        s = res["summary"]
        w = next(iter(s["worlds"].values()))
        row = {"recipe": name, "teacher": teacher, "spawn": spawn, "perturb": perturb,
               "stride": stride, "success": w["success_rate"]["mean"], "success_min": w["success_rate"]["min"],
               "nodes": s["nodes"]["mean"], "height": s["height"]["mean"], "collisions": w["collisions"],
               "seconds": round(time.perf_counter() - t0, 1)}
        out.append(row)
        print(f"{name:36} {row['success']:>8.1%} {row['success_min']:>5.0%} {row['nodes']:>7.0f} "
              f"{row['height']:>6.1f} {row['collisions']:>10}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
