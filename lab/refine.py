"""``rhbl refine``: a taught tree practises in simulation and improves itself, judged by its
behaviour's own success rule (the judge of ``rhbl evaluate``), then is validated on the
behaviour's held-out worlds, which it never practised in.

    rhbl refine --behaviour wall-following --tree T --out T2 [--max-nodes 55] [--minutes 10]
                [--workers N | --cluster tcp://HOST:PORT] [--json REPORT]

    tree, report = refine(b, policy, runner, max_nodes=55, budget=600)

The practice set: every start pose of the behaviour's teaching worlds, in the worlds as they
are and scaled by ``scales`` (0.85 and 1.2 by default: the same rooms a little tighter and
wider), and ``free`` poses drawn in each one's free space, ``seeds`` per start; but those the
scripted expert itself fails from. Its fitness: per episode 1 for a success, else half the fraction
of the episode driven before its first collision (a failure that collides later is nearer a
success); summed over the set.

Every move keeps the tree an RHBL tree the controller drives unchanged (spheres with centres,
radii, labels and parents; nothing else):

1. **size** (with ``max_nodes``, for a larger tree): weakest-link pruning (``rhbl.compaction``,
   balanced) against the tree's *own* actions on the states it visited in practice (no teacher),
   down to ``max_nodes`` less ``room`` (10 by default): the repairs below may add that many
   spheres back where the pruned tree fails (pruned to ``max_nodes`` itself, only relabels were
   left, and one training seed's tree of five stayed at 87% of its practice set);
2. **repair**: credit assignment over the failing episodes: the spheres that decided the steps
   before each first collision (``window`` steps), or the steps off the wall band, are blamed;
   for the most blamed, every other action is tried (a relabelled sphere), and at the blamed
   states a new sphere with each other action is tried (``learn_one``: the paper's spawn rule);
   each candidate is driven in closed loop on just the episodes it can change (those in which
   the sphere decided a step: the others are the same episode), and the best that raises the
   fitness is kept; again until none does or the time is up;
3. **pruning** (``prune``): each leaf some practice episode reached (``"used"``, the default;
   ``"all"``: every leaf; ``"none"``: no pruning), least used first, is removed if the fitness
   does not fall: CART's cost-complexity pruning, each subtree chosen by closed-loop fitness on
   the practice set. A leaf no episode reached stays: removing it changes nothing the practice
   set can see, and those were what the held-out rooms lost (docs/studies/refine-by-practice.md).

With ``more`` (``--more N``), once no repair raises the fitness (every practice episode
succeeds, or none of the failures can be repaired) and time is left, N more worlds of the
drawn kind (the next ones of ``PRACTICE_SEED``) join the practice set, and the repairs go on
there, until the time is up: a practice set the tree has met, or cannot do better in, teaches
it nothing more, so the time left goes to worlds that may.

With ``validation`` (``--validation N``) N more worlds of the drawn kind, drawn with another
seed and never practised in, guard steps 2 and 3: a repair or a removal that lowers their
fitness is not kept (reduced-error pruning's validation set).

The snapshot's ``metadata["refinement"]`` records the lineage: the parent file and its sha256,
the fitness (and success rate) before and after on the practice set and on the held-out worlds,
the episodes run, the moves kept, the time; ``"asks"`` the practice episodes it could not fix
(``ask``: the world, the start, what went wrong first and where to put the robot before it):
where a person's correction is needed. A learner extending the tree keeps the record, and
``rhbl console`` lists the asks of the world it shows ("show me here": one click puts the robot
there).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np

from client.behaviour.goals import GoalPolicy, load_policy
from client.behaviour.learning import TreePolicy
from lab import practice
from lab.behaviours import behaviour_arg, get, recipe_of, world_of
from lab.practice import PRACTICE_SEED, EpisodeTask, Runner, practice_tasks
from lab.recipe import GENERATORS, parse_scales
from process import arguments, files

__all__ = ["add_arguments", "ask", "fitness", "main", "refine"]

SCALES = (0.85, 1.2)
VALIDATION_SEED = 501  # the drawn validation worlds' (never practised in)
PRUNE = ("all", "used", "none")
ROOM = 10  # spheres the size step leaves under --max-nodes for repairs that add (docs/practice.md)


def score(r: dict) -> float:
    """One episode's fitness: 1 for a success, else half the fraction of it driven before the
    first collision (the whole of it, when it failed otherwise)."""
    if r["success"]:
        return 1.0
    steps = max(1, r["steps"])
    first = r["stalls"][0] if r["stalls"] else steps
    return 0.5 * first / steps


def fitness(results: list[dict]) -> float:
    return float(sum(score(r) for r in results))


# ------------------------------------------------------------------------ the tree's moves


def _classifier(clf, centers, radii, parent, label, classes):
    from rhbl import HypersphereClassifier
    from rhbl.tree import SphereTree

    tree = SphereTree.from_arrays(centers, radii, parent, label, distance=clf.distance,
                                  eps=clf.eps, uncovered=clf.tree_.uncovered)
    params = {k: v for k, v in clf.get_params().items() if k not in ("distance", "eps")}
    return HypersphereClassifier.from_tree(tree, classes, n_seen=clf.n_seen_,
                                           n_skipped=clf.n_skipped_,
                                           n_relabelled=clf.n_relabelled_,
                                           metadata=dict(clf.metadata), **params)


def relabelled(clf, sphere: int, action: str):
    """``clf`` with sphere ``sphere`` deciding ``action``."""
    arr = clf.tree_arrays()
    classes = [str(v) for v in clf.classes_]
    if action not in classes:
        classes.append(action)
    arr["label"][sphere] = classes.index(action)
    return _classifier(clf, arr["centers"], arr["radii"], arr["parent"], arr["label"], classes)


def without(clf, spheres):
    """``clf`` without sphere(s) ``spheres`` (an index or several; never the root): each one's
    children go to its nearest kept ancestor; the kept spheres keep their order."""
    arr = clf.tree_arrays()
    n = len(arr["parent"])
    keep = np.ones(n, dtype=bool)
    keep[np.atleast_1d(np.asarray(spheres, dtype=np.int64))] = False
    if not keep[0]:
        raise ValueError("the root stays")
    parent = arr["parent"].copy()
    for i in range(1, n):  # parents precede children: a parent's own parent is final already
        if not keep[parent[i]]:
            parent[i] = parent[parent[i]]
    new = np.cumsum(keep) - 1
    parent = np.where(parent[keep] < 0, -1, new[np.maximum(parent[keep], 0)])
    return _classifier(clf, arr["centers"][keep], arr["radii"][keep], parent,
                       arr["label"][keep], [str(v) for v in clf.classes_])


def _prune_pass(pr, clf, unused: bool = True, left=None, val=None) -> list[int]:
    """One pass of closed-loop leaf pruning on ``pr`` (its results become those of ``clf``
    without the leaves returned): each leaf removed alone, all in one batch; kept out when
    the fitness does not fall and its episodes (before and after) meet no other kept-out
    leaf's. ``unused``: also the leaves no episode reached (else they stay); ``left()``: the
    seconds left (the leaves not tried when it is up stay); ``val``: a validation set
    (``_Practice``) whose fitness must not fall either (its results follow)."""
    use = Counter()
    for r in pr.results:
        use.update(r["winners"].tolist())
    order = sorted(leaves(clf), key=lambda s: (use.get(s, 0), -s))
    trials = [(s, idx, val.using(s) if val else []) for s in order
              if (idx := pr.using(s)) or unused]
    outs, vouts, step = [], [], max(8, 4 * pr.runner.workers)
    for at in range(0, len(trials), step):
        if at and left is not None and left() <= 0:
            trials = trials[:at]
            break
        part = trials[at:at + step]
        outs += pr.run_many([(without(clf, s), idx) for s, idx, _v in part])
        vouts += (val.run_many([(without(clf, s), v) for s, _i, v in part]) if val
                  else [[] for _ in part])
    gone, seen = [], set()  # removed; the spheres their episodes now use
    touched = [set(), set()]  # the episodes of the removals kept: practice's, validation's
    for (s, idx, vidx), out, vout in zip(trials, outs, vouts, strict=True):
        pairs = [(pr, idx, out)] + ([(val, vidx, vout)] if val else [])
        if any(q.change(i, o) < q.fitness - 1e-9 for q, i, o in pairs) or s in seen:
            continue
        if any(t & set(i) for t, (_q, i, _o) in zip(touched, pairs, strict=False)):
            continue
        now = set()
        for _q, _i, o in pairs:
            for r in o:  # the single-removal tree's indices, as the tree's
                w = r["winners"]
                r["winners"] = np.where(w >= s, w + 1, w).astype(np.int32)  # -1 stays
                now.update(r["winners"].tolist())
        if now & set(gone):
            continue
        gone.append(s)
        seen |= now
        for t, (q, i, o) in zip(touched, pairs, strict=False):  # one pair without validation
            t.update(i)
            q.keep(i, o)
    if gone:
        new = np.cumsum(~np.isin(np.arange(clf.node_count_), gone)) - 1
        for q in [pr, val] if val else [pr]:
            for r in q.results:
                w = r["winners"]
                r["winners"] = np.where(w < 0, -1, new[np.maximum(w, 0)]).astype(np.int32)
    return sorted(gone)


def added(clf, x: np.ndarray, action: str):
    """``clf`` having learned ``action`` at ``x`` (the paper's rule: a sphere spawns where the
    winner disagrees)."""
    arr = clf.tree_arrays()
    new = _classifier(clf, arr["centers"], arr["radii"], arr["parent"], arr["label"],
                      [str(v) for v in clf.classes_])
    new.learn_one(np.asarray(x, dtype=np.float64), action)
    return new


def _to_size(clf, X: np.ndarray, max_nodes: int):
    """``clf`` with at most ``max_nodes`` spheres: the weakest-link pruning keeps a sphere
    tied with another on some state (``rhbl.compaction``), so it may stop above; the leaves
    that decide the fewest of the states ``X`` go then, one at a time."""
    while clf.node_count_ > max_nodes:
        won = np.bincount(np.maximum(clf.tree_.apply(X), 0), minlength=clf.node_count_)
        leaf = min(leaves(clf), key=lambda s: (won[s], -s))
        clf = without(clf, [leaf])
    return clf


def leaves(clf) -> list[int]:
    parent = clf.tree_arrays()["parent"]
    has_child = np.zeros(len(parent), dtype=bool)
    has_child[parent[1:]] = True
    return [int(i) for i in np.flatnonzero(~has_child) if i != 0]


# ------------------------------------------------------------------------ practice


@dataclasses.dataclass
class _Practice:
    """The practice set, its episodes' results for the current tree, and the runner."""

    b: object
    policy: TreePolicy
    runner: Runner
    tasks: list  # EpisodeTask without the tree
    results: list = dataclasses.field(default_factory=list)
    episodes: int = 0

    def with_tree(self, clf, tasks=None) -> list:
        data = practice.tree_bytes(_with(self.policy, clf))
        return [dataclasses.replace(t, tree=data) for t in (self.tasks if tasks is None
                                                            else tasks)]

    def run(self, clf, idx=None, tasks=None) -> list:
        """``clf``'s results on the practice set (``idx``: those episodes; ``tasks``: these
        episodes instead)."""
        if tasks is None:
            tasks = None if idx is None else [self.tasks[i] for i in idx]
        tasks = self.with_tree(clf, tasks)
        self.episodes += len(tasks)
        return self.runner.map(tasks)

    def run_many(self, trials: list[tuple]) -> list[list]:
        """``[(clf, episode indices), ...]`` -> each one's results, in one map (all in
        parallel)."""
        batch, cut = [], [0]
        for clf, idx in trials:
            batch += self.with_tree(clf, [self.tasks[i] for i in idx])
            cut.append(len(batch))
        self.episodes += len(batch)
        out = self.runner.map(batch)
        return [out[cut[k]:cut[k + 1]] for k in range(len(trials))]

    @property
    def fitness(self) -> float:
        return fitness(self.results)

    def using(self, sphere: int) -> list[int]:
        return [i for i, r in enumerate(self.results) if (r["winners"] == sphere).any()]

    def reaching(self, grown, old: int) -> list[int]:
        """The episodes the spheres ``old ..`` of ``grown`` (added to the tree they ran with)
        can change: those with a step inside one of them (a sphere changes no answer outside
        itself; the traced states are float32, hence the slack)."""
        arr = grown.tree_arrays()
        centers, radii = arr["centers"][old:], arr["radii"][old:]
        slack = 1e-4 * (1.0 + radii)
        out = []
        for i, r in enumerate(self.results):
            x = r["states"].astype(np.float64)
            for c, rad, sl in zip(centers, radii, slack, strict=True):
                d = ((x - c) ** 2).sum(axis=1)
                if grown.distance == "euclidean":
                    d = np.sqrt(d)
                if (d <= rad + sl).any():
                    out.append(i)
                    break
        return out

    def changed_by(self, move: tuple, tree, old: int) -> list[int]:
        """The episodes a repair ``move`` (giving ``tree``, from a tree of ``old`` spheres)
        can change: a relabelled sphere's (``using``), an added sphere's (``reaching``)."""
        return self.using(move[1]) if move[0] == "relabel" else self.reaching(tree, old)

    def change(self, idx: list[int], new: list) -> float:
        """The fitness with the episodes ``idx`` replaced by ``new``."""
        return self.fitness - sum(score(self.results[i]) for i in idx) + sum(map(score, new))

    def keep(self, idx: list[int], new: list) -> None:
        for i, r in zip(idx, new, strict=True):
            self.results[i] = r


def _with(policy, clf):
    """``policy`` (a ``TreePolicy``, or a ``GoalPolicy``: its completion tree and goals kept)
    with the (action) tree ``clf``."""
    if isinstance(policy, GoalPolicy):
        return GoalPolicy(clf, policy.completion, policy.features, policy.goals, policy.actions,
                          policy.metadata)
    return TreePolicy(clf, policy.features, policy.actions, policy.metadata)


def _held_out(b, clf, policy, runner, seed: int = 0, seconds=None) -> dict:
    """Success per held-out world (and the teaching worlds), every start pose, as ``rhbl
    evaluate`` runs it (the tree alone)."""
    from lab.evaluate import evaluate

    p = _with(policy, clf)
    out = {}
    for w in (*b.teach, *b.held_out):
        rep = evaluate(world_of(b, w), p, seed=seed, behaviour=b, runner=runner,
                       seconds=seconds)
        out[w] = round(rep["success_rate"], 4)
    return out


def _off_band(result: dict, band: dict | None) -> np.ndarray | None:
    """The steps of a traced episode off the followed wall's band (None: no band to keep)."""
    if band is None or result.get("side") is None:
        return None
    side = np.asarray(result["side"])
    return np.flatnonzero((side < band["near"]) | (side > band["far"]))


def _blame(pr: _Practice, window: int, b) -> tuple[Counter, list]:
    """Spheres blamed for the failures (how many blamed steps each decided) and the blamed
    (episode, step) pairs, latest first."""
    band = b.rules.get("wall-band")
    blamed, where = Counter(), []
    for i, r in enumerate(pr.results):
        if r["success"]:
            continue
        w = r["winners"]
        if r["stalls"]:
            f = r["stalls"][0]
            steps = list(range(max(0, f - window), min(f, len(w))))
        elif (off := _off_band(r, band)) is not None:
            steps = [int(k) for k in off if k < len(w)]
        else:
            steps = list(range(max(0, len(w) - 4 * window), len(w)))
        blamed.update(int(w[k]) for k in steps if w[k] >= 0)
        where += [(i, k) for k in reversed(steps)]
    return blamed, where


def ask(task: EpisodeTask, result: dict, window: int, b) -> dict:
    """Where a person's correction is needed for a practice episode refinement could not fix
    (``asks``: the console's "show me here", docs/console.md): the world, its scale, the
    episode's start and seed, what went wrong first (``why``: ``collision``, ``band``: off the
    followed wall's band, else ``failed``) and at which step, and ``pose``: where to put the
    robot, ``window // 2`` steps before that step (the true pose then: a person placed there
    sees what comes and shows the way), the start when nothing went wrong at one step."""
    band = b.rules.get("wall-band")
    step, why = None, "failed"
    if result["stalls"]:
        step, why = int(result["stalls"][0]), "collision"
    elif (off := _off_band(result, band)) is not None and len(off):
        step, why = int(off[0]), "band"
    poses = result.get("poses")
    if step is not None and poses is not None and len(poses):
        pose = [float(v) for v in poses[max(0, min(step - window // 2, len(poses) - 1))]]
    else:
        pose = [float(v) for v in task.start]
    return {"world": task.world, "scale": float(task.scale), "start": list(task.start),
            "seed": int(task.seed), "why": why, "step": step, "pose": [round(v, 3) for v in pose]}


def _visited(pr: _Practice) -> tuple[np.ndarray, np.ndarray]:
    """The states the practice episodes visited and the tree's own actions there."""
    X = np.concatenate([r["states"] for r in pr.results]).astype(np.float64)
    y = np.concatenate([np.asarray(r["actions"][:len(r["states"])]) for r in pr.results])
    return X, y


def _sized(pr: _Practice, clf, max_nodes: int):
    """The size step: ``clf`` pruned to ``max_nodes`` spheres (weakest link) against its own
    actions on the states it visited in practice, then practised: (tree, states used)."""
    X, y = _visited(pr)
    clf = clf.compact(X, y, method="prune", max_nodes=max_nodes, class_weight="balanced",
                      data="refine: the states it visited in practice, its own actions")
    clf = _to_size(clf, X, max_nodes)
    pr.results = pr.run(clf)
    return clf, len(X)


def _size_step(pr: _Practice, clf, max_nodes: int | None, room: int, moves: Counter, say,
               t0: float):
    """The size step for a tree larger than ``max_nodes``: pruned to ``max_nodes - room``
    (``_sized``), said and counted: (tree, its standing; None when it was small enough)."""
    if max_nodes is None or clf.node_count_ <= max_nodes:
        return clf, None
    clf, visited = _sized(pr, clf, max(1, max_nodes - room))
    moves["pruned to size"] += 1
    say(f"size: pruned to {clf.node_count_} nodes against its own actions on {visited} visited "
        f"states: fitness {pr.fitness:.2f}, {time.perf_counter() - t0:.0f} s")
    return clf, _standing(pr, clf)


def _trials(pr: _Practice, clf, actions: list[str], blamed: Counter, where: list,
            window: int, candidates: int, max_nodes: int | None) -> list:
    """The repairs to try: each of the ``candidates`` most blamed spheres given every other
    action, and (room left under ``max_nodes``) a sphere added at the failing states with
    every other action; each ``(move, tree, the episodes it may change)``."""
    trials = []
    for s, _n in blamed.most_common(candidates):
        idx = pr.using(s)
        for a in actions:
            if a != str(clf.classes_[clf.tree_.label[s]]):
                trials.append((("relabel", s, a), relabelled(clf, s, a), idx))
    if max_nodes is None or clf.node_count_ < max_nodes:
        seen = set()
        for i, k in where[::max(1, window // 3)][:candidates]:
            x = pr.results[i]["states"][k]
            if (i, k) in seen:
                continue
            seen.add((i, k))
            now = pr.results[i]["actions"][k]
            for a in actions:
                if a != now:
                    grown = added(clf, x, a)
                    if grown.node_count_ > clf.node_count_:
                        trials.append((("add", i, k, a), grown,
                                       pr.reaching(grown, clf.node_count_)))
    return trials


def _best(pr: _Practice, trials: list, runner: Runner, left, val=None, clf=None):
    """The trial that raises the practice fitness most, ``(move, tree, episodes, results)``,
    or None; batches of candidates, the time (``left()``) checked between them. With a
    validation set ``val``: the best of those that raise it and do not lower ``val``'s
    (``_validated``; ``clf``: the tree they change)."""
    better = []  # (fitness, place, trial, results)
    step = max(1, 2 * runner.workers)  # candidates per batch: the time checked between
    for at in range(0, len(trials), step):
        if at and left() <= 0:
            break
        part = trials[at:at + step]
        outs = pr.run_many([(c, idx) for _m, c, idx in part])
        for k, ((m, c, idx), out) in enumerate(zip(part, outs, strict=True)):
            f = pr.change(idx, out)
            if f > pr.fitness + 1e-9:
                better.append((f, at + k, (m, c, idx, out)))
    better = [t for _f, _k, t in sorted(better, key=lambda b: (-b[0], b[1]))]
    if val is None or not better:
        return better[0] if better else None
    return _validated(val, better, clf, step, left)


def _validated(val: _Practice, better: list, clf, step: int, left):
    """The first of ``better`` (best first) that does not lower the validation set's fitness,
    its results kept in ``val``; None if none (or the time is up). A move is driven on the
    validation episodes it can change only (a relabelled sphere: those it decided a step of;
    a sphere added: those with a step inside it)."""
    for at in range(0, len(better), step):
        if at and left() <= 0:
            break
        part = better[at:at + step]
        vidx = [val.changed_by(m, c, clf.node_count_) for m, c, _i, _o in part]
        outs = val.run_many([(c, v) for (_m, c, _i, _o), v in zip(part, vidx, strict=True)])
        for t, v, out in zip(part, vidx, outs, strict=True):
            if val.change(v, out) >= val.fitness - 1e-9:
                val.keep(v, out)
                return t
    return None


def _pruned(pr: _Practice, clf, prune: str, left, val, moves: Counter, say, t0: float):
    """The prune step: every leaf tried at once (least used first), each kept out if the
    fitness (and ``val``'s) does not fall; removals whose episodes do not meet are
    independent, and kept together; again until nothing goes or the time is up; said and
    counted: (tree, leaves removed)."""
    removed = 0
    while left() > 0:
        gone = _prune_pass(pr, clf, unused=prune == "all", left=left, val=val)
        if not gone:
            break
        clf = without(clf, gone)
        removed += len(gone)
    if removed:
        moves["pruned"] += removed
        say(f"prune: {removed} leaves removed: {clf.node_count_} nodes, fitness "
            f"{pr.fitness:.2f}, {pr.episodes} episodes, {time.perf_counter() - t0:.0f} s")
    return clf, removed


def _more_worlds(pr: _Practice, clf, b, kind: str, first: int, n: int, seeds, seconds, free,
                 noise) -> int:
    """``n`` more drawn worlds of ``kind`` (the ``first``-th on, ``PRACTICE_SEED``) joined to
    the practice set with ``clf``'s results (those the expert fails from left out): how many
    episodes joined."""
    tasks = practice_tasks(b, seeds, (), seconds, free, noise, drawn=(kind, n), teach=False,
                           first=first)
    results = pr.run(clf, tasks=tasks)
    fair = [i for i, r in enumerate(results) if r["teacher"]["success"]]
    pr.tasks += [tasks[i] for i in fair]
    pr.results += [results[i] for i in fair]
    return len(fair)


def _first_practice(pr: _Practice, clf) -> int:
    """The taught tree practised once; a start the behaviour's own expert fails from teaches
    nothing, so it is left out (unless every one would be): how many were."""
    pr.results = pr.run(clf)
    fair = [i for i, r in enumerate(pr.results) if r["teacher"]["success"]]
    dropped = len(pr.tasks) - len(fair)
    if fair and dropped:
        pr.tasks, pr.results = [pr.tasks[i] for i in fair], [pr.results[i] for i in fair]
    return dropped


def _practice_set(b, scales, drawn, free: int, seeds) -> str:
    """What the practice set is made of, in words."""
    return (f"{', '.join(b.teach)}, scales 1{''.join(f', {s:g}' for s in scales)}"
            f"{f'; {drawn[1]} {drawn[0]} drawn' if drawn and drawn[1] else ''}; "
            f"{free} free-space starts each; {len(seeds)} seed(s)")


def _success(pr: _Practice) -> float:
    """The share of the set's episodes met."""
    return float(np.mean([r["success"] for r in pr.results]))


def _standing(pr: _Practice, clf) -> dict:
    """The practice fitness, the tree's size and the share of practice episodes met."""
    return {"fitness": round(pr.fitness, 4), "nodes": int(clf.node_count_),
            "success": round(_success(pr), 4)}


def _check_sizable(clf, max_nodes: int | None) -> None:
    """ValueError unless the size step (``_sized``: rhbl.compaction) can prune ``clf``."""
    if max_nodes is not None and clf.node_count_ > max_nodes and clf.tree_.uncovered != "root":
        raise ValueError(f"--max-nodes {max_nodes} prunes by the paper's rule (rhbl.compaction): "
                         "this tree has radius 'margin'; train it with --radius parent to "
                         "refine it to a size")


def _validation_set(b, policy, runner: Runner, clf, n: int, kind: str, seeds, seconds,
                    noise, say=lambda text: None) -> _Practice:
    """Every start pose of ``n`` worlds of ``kind`` drawn with ``VALIDATION_SEED`` (never
    practised in), driven by ``clf`` (those the expert fails from left out); said."""
    val = _Practice(b, policy, runner, practice_tasks(
        b, seeds, (), seconds, 0, noise, drawn=(kind, n), drawn_seed=VALIDATION_SEED,
        teach=False))
    _first_practice(val, clf)
    say(f"validation: {len(val.tasks)} episodes in {n} drawn worlds (seed {VALIDATION_SEED}, "
        f"never practised in): fitness {val.fitness:.2f}, success {_success(val):.0%}; a move "
        "that lowers it is not kept")
    return val


def _repairs(pr: _Practice, clf, b, left, val, moves: Counter, say, t0: float, *,
             window: int, candidates: int, max_nodes: int | None):
    """The repair step, again while a repair raises the practice fitness (and leaves
    ``val``'s no lower) and the time lasts: the tree."""
    actions = list(pr.policy.actions.names)
    while left() > 0 and _success(pr) < 1.0:
        blamed, where = _blame(pr, window, b)
        trials = _trials(pr, clf, actions, blamed, where, window, candidates, max_nodes)
        best = _best(pr, trials, pr.runner, left, val, clf) if trials else None
        if best is None:
            break
        m, clf, idx, out = best
        pr.keep(idx, out)
        moves[m[0]] += 1
        say(f"repair: {m[0]} {m[1:]}: fitness {pr.fitness:.2f}, success {_success(pr):.0%}"
            f"{f' (validation {val.fitness:.2f})' if val else ''}, {clf.node_count_} nodes, "
            f"{pr.episodes} episodes, {time.perf_counter() - t0:.0f} s")
    return clf


def refine(b, policy: TreePolicy, runner: Runner, *, max_nodes: int | None = None,
           budget: float = 600.0, seeds=(0,), scales=SCALES, window: int = 30,
           candidates: int = 6, prune: str = "used", say=None, validate: bool = True,
           seconds: float | None = None, free: int = 0, noise=(0.0, 0.0),
           drawn: tuple[str, int] | None = None, room: int = ROOM, validation: int = 0,
           more: int = 0):
    """``policy``'s tree refined by practice (the module's docstring): ``(classifier,
    report)``. ``seconds``: each episode's length (default: the behaviour's time limit);
    ``drawn`` = (kind, count): practise also in that many worlds drawn at random; ``room``:
    the size step prunes to ``max_nodes - room`` spheres (at least 1), leaving room for repairs
    that add spheres; ``validation``: that many more worlds of the drawn kind (another seed)
    whose fitness no repair or removal may lower (never practised in); ``more``: while time
    is left and no repair helps, that many more worlds of the drawn kind join the practice set
    (and repairs go on)."""
    t0 = time.perf_counter()
    say = say or (lambda text: print(text, flush=True))
    clf = policy.classifier
    _check_sizable(clf, max_nodes)
    pr = _Practice(b, policy, runner, practice_tasks(b, seeds, scales, seconds, free, noise,
                                                     drawn))
    dropped = _first_practice(pr, clf)
    before = _standing(pr, clf)
    say(f"practice: {len(pr.tasks)} episodes ({_practice_set(b, scales, drawn, free, seeds)}; "
        f"{dropped} left out: the expert fails there) on {runner.describe()}: fitness "
        f"{before['fitness']:.2f}, success {before['success']:.0%}, {before['nodes']} nodes")
    moves: Counter = Counter()

    def left() -> float:
        return budget - (time.perf_counter() - t0)

    # 1. size: weakest-link pruning against the tree's own actions where it drove
    clf, sized = _size_step(pr, clf, max_nodes, room, moves, say, t0)
    kind = drawn[0] if drawn else recipe_of(b).generator
    drawn_n = drawn[1] if drawn else 0
    val = _validation_set(b, policy, runner, clf, validation, kind, seeds, seconds, noise,
                          say) if validation else None
    val_before = _standing(val, clf) if val else None

    # 2./3. repair, then prune; again while either changes something (and, with ``more``,
    # with more drawn worlds while the time lasts)
    changed = True
    while left() > 0:
        if not changed:
            if not more:
                break
            joined = _more_worlds(pr, clf, b, kind, drawn_n, more, seeds, seconds, free, noise)
            drawn_n += more
            moves["worlds drawn"] += more
            say(f"no repair left to make: {more} more {kind} drawn ({joined} episodes), "
                f"success {_success(pr):.0%}, {time.perf_counter() - t0:.0f} s")
        # repairs go on until none helps: again only once pruning changed the tree
        clf = _repairs(pr, clf, b, left, val, moves, say, t0, window=window,
                       candidates=candidates, max_nodes=max_nodes)
        changed = False
        if prune != "none":
            clf, removed = _pruned(pr, clf, prune, left, val, moves, say, t0)
            changed = removed > 0
    after = _standing(pr, clf)
    asks = [ask(t, r, window, b) for t, r in zip(pr.tasks, pr.results, strict=True)
            if not r["success"]]
    report = {"before": before, "after": after, "episodes": pr.episodes,
              "practice": {"worlds": list(b.teach), "scales": [1.0, *scales],
                           "drawn": [kind, drawn_n] if drawn_n else None, "more": more,
                           "seeds": list(seeds), "free": free, "noise": list(noise),
                           "episodes": len(pr.tasks), "left_out": dropped},
              "moves": dict(moves), "seconds": round(time.perf_counter() - t0, 1),
              "asks": asks, "max_nodes": max_nodes, "room": room if max_nodes else None,
              "sized": sized,
              "prune": prune, "height": int(clf.height_)}
    if val is not None:
        report["validation"] = {"worlds": validation, "seed": VALIDATION_SEED,
                                "episodes": len(val.tasks), "before": val_before,
                                "after": _standing(val, clf)}
    if validate:
        report["worlds_before"] = _held_out(b, policy.classifier, policy, runner, 0, seconds)
        report["worlds_after"] = _held_out(b, clf, policy, runner, 0, seconds)
    return clf, report


# ------------------------------------------------------------------------ the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--behaviour", required=True, type=behaviour_arg,
                        help="the behaviour whose success rule is the fitness and whose "
                             "teaching worlds it practises in (its held-out worlds validate)")
    parser.add_argument("--tree", required=True, type=arguments.input_file,
                        help="the taught tree (a snapshot of rhbl train, rhbl learner, ...)")
    parser.add_argument("--out", required=True, type=arguments.output_file,
                        help="write the refined tree here (its lineage in its metadata)")
    parser.add_argument("--max-nodes", type=arguments.positive_int, default=None,
                        help="prune a larger tree to this many spheres first, and never grow "
                             "beyond (default: no limit)")
    parser.add_argument("--room", type=arguments.non_negative_int, default=ROOM, metavar="N",
                        help=f"with --max-nodes: prune to N spheres fewer first, so that repairs "
                             f"may add spheres where the pruned tree fails (default {ROOM})")
    parser.add_argument("--minutes", type=arguments.positive_float, default=10.0,
                        help="stop improving after this many minutes (default 10)")
    parser.add_argument("--seeds", type=arguments.positive_int, default=1,
                        help="episodes per start pose, seeds 0..N-1 (they differ with noise; "
                             "default 1)")
    parser.add_argument("--seconds", type=arguments.seconds, default=None,
                        help="sim seconds per episode (default: the behaviour's time limit)")
    parser.add_argument("--scales", type=parse_scales, default=SCALES, metavar="F,F",
                        help="practise also in the teaching worlds scaled by these factors "
                             "(default 0.85,1.2; 'none': the worlds as they are only)")
    parser.add_argument("--free", type=arguments.non_negative_int, default=0,
                        help="also practise from this many poses drawn in the free space of "
                             "each (scaled) teaching world (default 0)")
    parser.add_argument("--generated", type=arguments.non_negative_int, default=0,
                        metavar="N",
                        help="also practise in N worlds drawn at random by --generator "
                             f"(rhbl generate; seed {PRACTICE_SEED}, not a training run's), "
                             "from their start poses (default 0)")
    parser.add_argument("--generator", choices=list(GENERATORS), default=None,
                        help="the kind of world --generated draws (default: the behaviour's "
                             "recipe's generator)")
    parser.add_argument("--more", type=arguments.non_negative_int, default=0, metavar="N",
                        help="while time is left and no repair helps (the practice set met, "
                             "or its failures beyond repair), draw N more worlds by --generator "
                             "into the practice set and go on (default 0: stop there)")
    parser.add_argument("--validation", type=arguments.non_negative_int, default=0,
                        metavar="N",
                        help="N more worlds drawn by --generator (seed "
                             f"{VALIDATION_SEED}), never practised in: a repair or a removal "
                             "that lowers their fitness is not kept (default 0: none)")
    parser.add_argument("--range-noise", type=arguments.non_negative_float, default=0.0,
                        help="practise with this laser noise (server option; the seeds then "
                             "differ; the held-out worlds are judged without)")
    parser.add_argument("--odom-noise", type=arguments.non_negative_float, default=0.0,
                        help="practise with this odometry noise (server option)")
    parser.add_argument("--prune", choices=PRUNE, default="used",
                        help="remove the leaves whose removal keeps the practice fitness: "
                             "'used': those some practice episode reached (default; a leaf no "
                             "episode reached stays: the practice set says nothing of it), "
                             "'all' of them, 'none': repair only (docs/studies/"
                             "refine-by-practice.md: 'all' lost the held-out rooms)")
    parser.add_argument("--window", type=arguments.positive_int, default=30,
                        help="steps before a collision whose spheres are blamed (default 30: "
                             "3 s)")
    parser.add_argument("--json", default=None, type=arguments.output_file,
                        help="write the report here")
    practice.add_arguments(parser)


def main(args) -> int:
    b = get(args.behaviour)
    policy = load_policy(args.tree)
    from lab.goals import check_kind

    check_kind(b, policy, args.tree)  # a goal behaviour's tree has goals, and only its
    goals = isinstance(policy, GoalPolicy)
    if goals and (args.range_noise or args.odom_noise):
        raise ValueError("--range-noise/--odom-noise: a tree with goals in order practises "
                         "without noise")
    raw = Path(args.tree).read_bytes()
    with practice.runner_from_args(args) as runner:
        clf, report = refine(b, policy, runner, max_nodes=args.max_nodes,
                             budget=args.minutes * 60.0, seeds=tuple(range(args.seeds)),
                             window=args.window, seconds=args.seconds,
                             scales=tuple(f for f in args.scales if f != 1.0), free=args.free,
                             prune=args.prune, noise=(args.range_noise, args.odom_noise),
                             drawn=(args.generator or recipe_of(b).generator, args.generated),
                             room=args.room, validation=args.validation,
                             more=args.more)
    record = {"parent": str(args.tree), "parent_sha256": hashlib.sha256(raw).hexdigest(),
              "behaviour": b.name, **report}  # with the asks: the console shows them
    meta = dict(clf.metadata)
    meta["refinement"] = [*list(meta.get("refinement") or []), record]
    meta["features"], meta["actions"] = policy.features.to_dict(), policy.actions.to_dict()
    clf.save(args.out, metadata=meta)
    wb, wa = report.get("worlds_before", {}), report.get("worlds_after", {})
    print(f"refined {args.tree} -> {args.out}: {report['before']['nodes']} -> "
          f"{report['after']['nodes']} nodes; practice fitness {report['before']['fitness']:.2f}"
          f" -> {report['after']['fitness']:.2f} (success {report['before']['success']:.0%} -> "
          f"{report['after']['success']:.0%}); {report['episodes']} episodes, "
          f"{report['seconds']:g} s")
    if report["after"]["fitness"] < report["before"]["fitness"]:
        print(f"  the tree is worse than its parent on the practice set: --max-nodes "
              f"{args.max_nodes} cost more than the repairs gave back in the time (more "
              f"--minutes, or a larger --max-nodes)")
    if v := report.get("validation"):
        print(f"  validation ({v['worlds']} drawn worlds, never practised in): success "
              f"{v['before']['success']:.0%} -> {v['after']['success']:.0%}")
    for w in wb:
        tag = "taught" if w in b.teach else "held out"
        print(f"  {w} ({tag}): success {wb[w]:.0%} -> {wa[w]:.0%}")
    for a in report["asks"]:
        pose = ",".join(f"{v:g}" for v in a["pose"])
        what = {"collision": "collides", "band": "leaves the wall's band"}.get(a["why"], "fails")
        if a["world"].startswith(practice.DRAWN + ":"):
            _, kind, seed, i, side = a["world"].split(":")
            where = (f"drawn world {kind}-{seed}-{i} (rhbl generate {kind} --seed {seed} "
                     f"--count {int(i) + 1}{' --side ' + side if side != 'right' else ''} "
                     "--out DIR writes it)")
            shown = "not on the console: a world no server runs"
        else:
            where = f"{a['world']} scaled {a['scale']:g}"
            shown = ("rhbl console lists it" if a["scale"] == 1.0
                     else "not on the console: a scaled copy")
        print(f"  could not fix: {where}, the episode from "
              f"{','.join(f'{v:g}' for v in a['start'])} (seed {a['seed']}) {what}"
              + (f" at step {a['step']}" if a["step"] is not None else "")
              + f": show me there, from {pose} ({shown})")
    if args.json:
        files.write_text(args.json, json.dumps(report, indent=1), "--json")
        print(f"wrote {args.json}")
    return 0
