"""Tree size against success: the trade-off study of docs/experiments.md.

    python benchmarks/bench_experiment.py [--trials 3] [--task wall-following] [--json out.json]
        [--study size|tradeoff|beams|compact]
    python benchmarks/bench_experiment.py --study compact --task wall-following --trials 5 \
        --dir DIR [--methods exact,prune,prune-balanced:400,...] [--offline]
        (also rounds:prune-balanced:53, visited2:prune-balanced:53: see _staged_tree)

Each row trains on the task's shipped world with one recipe (spawn rule, teacher style,
perturbation, sample stride) for ``--trials`` seeds and evaluates from every start pose.
"""

from __future__ import annotations

import argparse
import json
import time

from client.behaviour.features import FeatureSpec
from lab.experiment import run_experiment
from lab.recipe import COMPACT, RECIPES

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


# --study compact: each trial's default training run is recorded once (tree + every labelled
# vector it learned, DIR/<task>-s<seed>.rhbl/.npz); the methods are then applied to that tree
# offline and the results evaluated closed loop on the training world and every eval world.
# the methods are the recipe's compaction choices (lab.recipe.COMPACT)


# sample selection, offline: a fresh tree (the recipe's parameters) grown on part of a trial's
# learned vectors, in order: "changes" = only where the teacher's label changes (like a
# person's key presses), "dedup:Q" = the first vector of each label in each grid cell of side
# Q, "condense" = passes over all of them until a pass changes nothing (at most 20)
SELECTIONS = ("changes", "dedup", "condense")


def _selected_tree(name: str, clf, X, y):
    import numpy as np

    from rhbl import HypersphereClassifier

    base, _, arg = name.partition(":")
    params = clf.get_params()
    fresh = HypersphereClassifier(**params)
    if base == "changes":
        keep = np.r_[True, y[1:] != y[:-1]]
        return fresh.fit(X[keep], y[keep])
    if base == "dedup":
        cells = np.floor(X / float(arg)).astype(np.int64)
        codes = np.unique(y, return_inverse=True)[1]
        _, first = np.unique(np.c_[cells, codes], axis=0, return_index=True)
        first.sort()
        return fresh.fit(X[first], y[first])
    fresh.fit(X, y)
    for _ in range(20):
        before = fresh.node_count_
        fresh.partial_fit(X, y)
        if fresh.node_count_ == before:
            break
    return fresh


# compaction with more data than the tree's own vectors: "rounds:M[:N]" = a new training run
# of the recipe with compaction M (to at most N spheres) after the demonstrations and after
# every corrective round (Recipe.compact_rounds; the next round corrects what the compacted
# tree does); "visited:M[:N]" (and "visitedK:M[:N]") = M applied to the recorded tree against
# its own vectors plus held-out visited states: the tree drives one corrective round (no
# learning) from every start pose and 4 free-space poses in the world scaled by VISIT_SCALES
# and in the world itself, poses drawn with seed 100 + trial seed, the teacher labelling;
# visitedK repeats it K times, each time driving the last compacted tree and compacting the
# recorded tree against all the states gathered so far; "roundsvisitedK:M[:N]" = both: the
# "rounds:" training run, then its last compaction done again K times as in visitedK (the tree
# before the last compaction against every vector it learned plus the visited states of the
# tree compacted last; Recipe.compact_visits)
VISIT_SCALES = (0.85, 1.2)
VISIT_FREE = 4
STAGED = ("rounds", "visited", "roundsvisited")


def _staged(name: str) -> tuple[str, int, dict] | None:
    """'visited2:prune-balanced:53' -> ("visited", 2, compaction keywords); None otherwise."""
    head, _, rest = name.partition(":")
    kind = head.rstrip("0123456789")
    if kind not in STAGED or not rest:
        return None
    times = int(head[len(kind):] or 1)
    return kind, times, _compact_method(rest) or {}


def _staged_tree(name: str, task: str, seed: int, folder, clf, feats, acts, meta, X, y):
    """The tree of a "rounds:" or "visited:" method (see above), cached in ``folder``."""
    from pathlib import Path

    import numpy as np

    from client.behaviour.learning import DemonstrationLearner, load_snapshot
    from lab.harness import make_learner, resolve_world
    from lab.train import train, visited_states

    kind, times, kw = _staged(name)
    tag = Path(folder) / f"{task}-s{seed}-{name.replace(':', '-')}.rhbl"
    if tag.exists():
        return load_snapshot(tag)[0]
    recipe = RECIPES[task]
    base, _, size = name.partition(":")[2].partition(":")
    if kind in ("rounds", "roundsvisited"):  # the recipe's options: one training run
        r = recipe.replace(compact=base, compact_max_nodes=int(size) if size else None,
                           compact_rounds=True,
                           compact_visits=times if kind == "roundsvisited" else 0,
                           visit_scales=VISIT_SCALES, visit_free=VISIT_FREE)
        learner = make_learner(r)
        train(resolve_world(r.world), learner, r, seed=seed)
        learner.save(tag)
        return learner.classifier
    spec = resolve_world(recipe.world)
    visit = recipe.replace(round_free=VISIT_FREE)
    xs, ys, small = [X], [y], clf
    for k in range(times):
        driver = DemonstrationLearner(feats, acts, task=task, classifier=small)
        vx, vy = visited_states(spec, driver, visit, seed=100 + seed + 1000 * k,
                                scales=VISIT_SCALES)
        xs.append(vx)
        ys.append(vy)
        small = clf.compact(np.concatenate(xs), np.concatenate(ys), **kw,
                            data=f"own vectors + {k + 1} x held-out visited states")
    small.save(str(tag), metadata=meta)
    return small


def _compact_method(name: str) -> dict | None:
    """'prune-balanced:400' -> prune with class_weight='balanced' to at most 400 spheres,
    applied after the exact step."""
    if _staged(name) is not None:
        return {"staged": name}
    base, _, size = name.partition(":")
    if base in SELECTIONS:
        return {"select": name}
    if base not in COMPACT:
        raise SystemExit(f"unknown method {base!r}; known: {', '.join(COMPACT)}")
    kw = dict(COMPACT[base])
    if size:
        kw["max_nodes"] = int(size)
    return kw or None


def record_trial(task: str, seed: int, folder) -> tuple:
    """The default recipe's tree of one seed and its learned vectors (cached in ``folder``)."""
    from pathlib import Path

    import numpy as np

    from client.behaviour.learning import load_snapshot
    from lab.harness import make_learner, resolve_world
    from lab.train import train

    tag = Path(folder) / f"{task}-s{seed}"
    tree, data = tag.with_suffix(".rhbl"), tag.with_suffix(".npz")
    if not (tree.exists() and data.exists()):
        recipe = RECIPES[task]  # the default recipe (no compaction step): the methods are
        learner = make_learner(recipe, record=True)  # applied below, offline
        train(resolve_world(recipe.world), learner, recipe, seed=seed)
        X, y = learner.recorded()
        learner.save(tree)
        np.savez_compressed(data, X=X, y=y)
    with np.load(data) as d:
        X, y = d["X"], d["y"].astype(str)
    return (*load_snapshot(tree), X, y)


def compact_study(task: str, trials: int, folder: str, methods: list[str],
                  offline: bool = False, eval_worlds: list[str] | None = None,
                  first_seed: int = 0) -> list[dict]:
    from pathlib import Path

    import numpy as np

    from client.behaviour.learning import TreePolicy
    from lab.evaluate import evaluate
    from lab.experiment import default_eval_worlds
    from lab.harness import resolve_world

    Path(folder).mkdir(parents=True, exist_ok=True)
    worlds = [RECIPES[task].world, *(default_eval_worlds(task) if eval_worlds is None else eval_worlds)]
    out = []
    seeds = range(first_seed, first_seed + trials)
    data = {seed: record_trial(task, seed, folder) for seed in seeds}
    for seed in seeds:
        clf, feats, acts, meta, X, y = data[seed]
        others = [data[s] for s in seeds if s != seed]
        for name in methods:
            kw = _compact_method(name)
            t0 = time.perf_counter()
            small = clf
            if kw is not None and "staged" in kw:
                small = _staged_tree(name, task, seed, folder, clf, feats, acts, meta, X, y)
            elif kw is not None and "select" in kw:
                small = _selected_tree(name, clf, X, y)
            elif kw is not None:
                small = clf.compact(X, None if kw["method"] == "exact" else y, **kw)
            row = {"task": task, "seed": seed, "method": name, "nodes": small.node_count_,
                   "height": small.height_, "agreement": float(np.mean(small.predict(X) == y)),
                   "heldout_agreement": float(np.mean(np.concatenate(
                       [small.predict(o[4]) == o[5] for o in others]))) if others else None,
                   "compact_s": round(time.perf_counter() - t0, 1), "worlds": {}}
            if not offline:
                policy = TreePolicy(small, feats, acts, meta)
                for w in worlds:
                    rep = evaluate(resolve_world(w), policy, seed=seed)
                    row["worlds"][rep["world"]] = {
                        "success_rate": rep["success_rate"],
                        "collisions": sum(e["collisions"] for e in rep["learner"])}
            out.append(row)
            print(json.dumps(row), flush=True)
    print(f"\n{'method':24} {'nodes':>7} {'height':>6} {'agree':>6} {'held':>6}  success per "
          "world (mean/min over trials), collisions")
    for name in methods:
        rows = [r for r in out if r["method"] == name]
        line = (f"{name:24} {np.mean([r['nodes'] for r in rows]):>7.1f} "
                f"{np.mean([r['height'] for r in rows]):>6.1f} "
                f"{np.mean([r['agreement'] for r in rows]):>6.3f} "
                f"{np.mean([r['heldout_agreement'] or 0.0 for r in rows]):>6.3f} ")
        for w in rows[0]["worlds"]:
            sr = [r["worlds"][w]["success_rate"] for r in rows]
            col = sum(r["worlds"][w]["collisions"] for r in rows)
            line += f" {w}:{np.mean(sr):.0%}/{min(sr):.0%}/{col}"
        print(line)
    return out


def _parse() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--task", default="wall-following", choices=["wall-following", "maze"])
    ap.add_argument("--json", default=None)
    ap.add_argument("--study", default="size", choices=["size", "tradeoff", "beams", "compact"],
                    help="size: the current recipe's size study (default); tradeoff: the old "
                         "smooth-teacher study; beams: beam choice; compact: compaction methods "
                         "on the recipe's trees")
    ap.add_argument("--dir", default="compact-study",
                    help="compact: folder for the recorded trees and vectors (reused)")
    ap.add_argument("--methods", default="none,exact,prune-balanced",
                    help="compact: comma-separated none, exact, prune, prune-balanced (each "
                         "optionally :N, at most N spheres), or the sample selections changes, "
                         "dedup:Q, condense (fresh trees grown on part of the vectors), or "
                         "rounds:M[:N] (compaction M between the corrective rounds of a new "
                         "training run), visited[K]:M[:N] (M against the tree's vectors and "
                         "held-out visited states, K times)")
    ap.add_argument("--eval-world", action="append", default=None,
                    help="compact: evaluation world (repeatable; default: server/worlds/"
                         "eval-room* or eval-maze*)")
    ap.add_argument("--seed", type=int, default=0, help="compact: first trial's seed")
    ap.add_argument("--offline", action="store_true",
                    help="compact: sizes and agreement only, no closed-loop evaluation")
    return ap.parse_args()


def beams_study(task: str, trials: int) -> list[dict]:
    """Each beam choice of ``BEAMS`` in the task's recipe: success, size."""
    out = []
    print(f"{'beams':32} {'success':>8} {'min':>5} {'nodes':>7} {'height':>6} {'collisions':>10}")
    for name, beams in BEAMS:
        res = run_experiment(task, trials=trials, eval_worlds=[],
                             recipe=RECIPES[task].replace(features=FeatureSpec(beams=beams)))
        s = res["summary"]
        w = next(iter(s["worlds"].values()))
        out.append({"beams": list(beams), "success": w["success_rate"]["mean"],
                    "nodes": s["nodes"]["mean"], "height": s["height"]["mean"]})
        print(f"{name:32} {w['success_rate']['mean']:>8.1%} {w['success_rate']['min']:>5.0%} "
              f"{s['nodes']['mean']:>7.0f} {s['height']['mean']:>6.1f} {w['collisions']:>10}",
              flush=True)
    return out


def tradeoff_study(task: str, trials: int) -> list[dict]:
    """Each recipe of ``ROWS`` (teacher, spawn rule, perturbation, stride): success, size."""
    out = []
    print(f"{'recipe':36} {'success':>8} {'min':>5} {'nodes':>7} {'height':>6} {'collisions':>10}")
    for name, teacher, spawn, perturb, stride in ROWS:
        t0 = time.perf_counter()
        recipe = RECIPES[task].replace(perturb=perturb, stride=stride, spawn=spawn)
        res = run_experiment(task, trials=trials, eval_worlds=[], teacher=teacher,
                             recipe=recipe)
        s = res["summary"]
        w = next(iter(s["worlds"].values()))
        row = {"recipe": name, "teacher": teacher, "spawn": spawn, "perturb": perturb,
               "stride": stride, "success": w["success_rate"]["mean"],
               "success_min": w["success_rate"]["min"], "nodes": s["nodes"]["mean"],
               "height": s["height"]["mean"], "collisions": w["collisions"],
               "seconds": round(time.perf_counter() - t0, 1)}
        out.append(row)
        print(f"{name:36} {row['success']:>8.1%} {row['success_min']:>5.0%} {row['nodes']:>7.0f} "
              f"{row['height']:>6.1f} {row['collisions']:>10}", flush=True)
    return out


def main() -> int:
    args = _parse()
    if args.study == "compact":
        out = compact_study(args.task, args.trials, args.dir, args.methods.split(","),
                            offline=args.offline, eval_worlds=args.eval_world,
                            first_seed=args.seed)
    elif args.study == "size":
        out = size_study(args.task, args.trials)
    elif args.study == "beams":
        out = beams_study(args.task, args.trials)
    else:
        out = tradeoff_study(args.task, args.trials)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
