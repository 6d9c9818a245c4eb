"""RHBL beside the standard learners: the same demonstrations learned by the project's tree and
by scikit-learn's k-nearest neighbours (k=1, k=5), decision tree and a small MLP (behaviour
cloning), each then driven in closed loop in the behaviour's teaching and held-out worlds.
``rhbl-vote`` is a study of this benchmark's own (``OrderVote``): five RHBL trees, each fitted on
the same vectors in another order, answering by their majority. ``rhbl-script`` (not run by
default) is for a person's labels: the scripted teacher's rule on them as paired, not edited.

For each behaviour and seed the scripted expert teaches exactly as ``rhbl train --behaviour``
does (``lab.train.train`` with the behaviour's recipe, ``lab.behaviours.recipe_of``), the learner
keeping every vector it learned (``make_learner(recipe, record=True)``): those ``(X, y)``, the
demonstrations and the corrective rounds' labels, are what every learner fits. RHBL is fitted
again on them, in the same order, with the recipe's tree parameters, as ``rhbl train`` ends
(``lab.harness.learned_from``: the same tree as the trained one, the table says so), so its
learning time is measured as the others' are. Each model
drives through ``lab.evaluate.evaluate`` (what ``rhbl evaluate`` runs: the same start poses,
time limit and success rule, the expert's episode beside it), with the same feature spec and
action set, no guard for anyone.

    python benchmarks/bench_peers.py [--behaviour wall-following,maze,left-wall] [--seeds 0,1,2]
                                     [--quick] [--json out.json]

Prints one table (per behaviour and learner, over the seeds: success in the teaching worlds
and in the held-out worlds, collisions per seed, model size, learning time, prediction time per
query alone, as the controller asks, and per vector in a batch of 1,000), then the success per
world. ``--quick``: a small run (60 s of demonstrations and one corrective round, in one
randomised world at most; one start pose per world for 20 s, the first held-out world only), to
check that it runs.

Model size: RHBL nodes (spheres; rhbl-vote: of its five trees together), decision tree nodes,
kNN stored vectors, MLP weights and biases.

``--people calm,steady,...`` (or ``all``): also a session of each person model
(``benchmarks/people.py``) teaching each ``--people-behaviour`` (default wall following, in the
room; any shipped behaviour, in its first teaching world, for the people of ``people.ANY``),
in-process as the teaching study runs it (``bench_teach_study.teach``: 240 s of demonstrating,
120 s of correcting while the person's tree drives through the guard; one session a seed); RHBL
is the person's learner rebuilt from the labels (its person rule), the others learn each label
with the scan the person's learner paired it with (its estimated lag). Each behaviour and model
has its rows, and with more than one model of a behaviour, the rows "B by N people" pool every
model's sessions of it (the success over all their episodes). ``--behaviour ""`` with it: the
people only.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from client.behaviour.spec import shipped  # noqa: E402
from lab.behaviours import get, recipe_of, world_of  # noqa: E402
from lab.evaluate import evaluate  # noqa: E402
from lab.harness import learned_from, make_learner  # noqa: E402
from lab.report import table  # noqa: E402
from lab.train import train  # noqa: E402
from server import world_path  # noqa: E402
from server.worldfile import load_world  # noqa: E402

VOTERS = 5  # rhbl-vote's trees (chosen on development worlds: docs/studies/order-vote.md)
# the learners, in the table's order: name -> what it is
LEARNERS = {
    "rhbl": "the project's hypersphere tree, the recipe's parameters",
    "rhbl-script": "on a person's labels: the scripted teacher's rule (the behaviour's own "
                   "recipe, the margin radius) on the labels as paired, not edited",
    "rhbl-vote": f"{VOTERS} such trees, each fitted on the vectors in an order of its own "
                 "(seeded), the majority of their answers (OrderVote)",
    "1-nn": "KNeighborsClassifier(n_neighbors=1)",
    "5-nn": "KNeighborsClassifier(n_neighbors=5)",
    "tree": "DecisionTreeClassifier(random_state=seed)",
    "mlp": "MLPClassifier(hidden_layer_sizes=(32, 32), max_iter=300, random_state=seed)",
}
DEFAULT = [n for n in LEARNERS if n != "rhbl-script"]  # (a study's: for a person's labels)
# the person models of benchmarks/people.py (their names; the module is loaded when used): a
# person for any behaviour (people.ANY), then the right-hand wall's own (wall following only)
PEOPLE_MODELS = ["calm", "rushed", "lapsing", "arcless", "tapping", "heavy", "muddled",
                 "steady", "hurried", "cautious", "oversteerer", "novice", "tapper", "pilot",
                 "bang", "jitter", "wide"]
QUICK = {"seconds": 60.0, "rounds": 1, "round_scales": (), "round_free": 0}
SINGLE_QUERIES = 100   # queries timed one at a time, per repeat
BATCH = 1000           # vectors in the batch query
REPEATS = 5            # the prediction times are the best of these


class OrderVote:
    """Bagging by order: ``n`` RHBL trees with the recipe's parameters, each offered every
    vector of ``(X, y)`` once in a random order of its own (RHBL's tree depends on the order it
    learns in: that is each tree's diversity; a bootstrap sample of the vectors in their order
    was tried and was not as good, docs/studies/order-vote.md), answering by the majority of
    the trees (a tie: the answer of the first tree among the tied). A benchmark's learner, not
    the product's: a snapshot holds one tree."""

    def __init__(self, X: np.ndarray, y: np.ndarray, recipe, seed: int, n: int = VOTERS):
        rng = np.random.default_rng(seed)
        self.members = []
        for _ in range(n):
            order = rng.permutation(len(X))
            self.members.append(learned_from(recipe, X[order], y[order]).classifier)
        self.node_count_ = sum(int(m.node_count_) for m in self.members)
        self.height_ = max(int(m.height_) for m in self.members)

    def predict_one(self, x):
        answers = [m.predict_one(x) for m in self.members]
        counts = {a: answers.count(a) for a in answers}
        top = max(counts.values())
        return next(a for a in answers if counts[a] == top)

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.array([self.predict_one(x) for x in X])


class PeerPolicy:
    """A scikit-learn model driving as a tree does (``TreePolicy``'s ``act``): the scan's
    features by the same ``FeatureSpec``, one query per step, an action of the same set.
    ``classifier`` is what ``lab.evaluate.evaluate`` reports as the tree's size (``node_count_``:
    the model's size; ``height_``: its depth, 0 when it has none). ``decide``: the model's
    answer for one feature vector (default: its ``predict`` of one row; ``exact_decider``: the
    same answers without the per-call checks, so that closed-loop runs take minutes, not
    hours)."""

    def __init__(self, model, features, actions, size: int, depth: int = 0, decide=None):
        self.model, self.features, self.actions = model, features, actions
        self.classifier = SimpleNamespace(node_count_=int(size), height_=int(depth))
        self.decide = decide or (lambda x: model.predict(x.reshape(1, -1))[0])
        self.queries = 0

    def reset(self) -> None:
        pass

    def act(self, ranges, pose) -> str:
        yaw = float(pose[2]) if pose is not None else 0.0
        self.queries += 1
        return str(self.decide(self.features.extract(ranges, yaw)))


def exact_decider(name: str, model, X: np.ndarray):
    """The answer of fitted model ``name`` for one vector, computed from its fitted state as its
    ``predict`` computes it (a decision tree's walk with the features as float32, the MLP's
    forward pass to the largest output, the kNN's search tree and the neighbours' most frequent
    class, the lowest on a tie), checked against ``predict`` on 2,000 rows of ``X``: None when
    any differs (or the model is another kind), so the caller drives with ``predict``."""
    if name == "tree":
        t = model.tree_
        left, right, feat, thr = (t.children_left.tolist(), t.children_right.tolist(),
                                  t.feature.tolist(), t.threshold.tolist())
        best = model.classes_[np.argmax(t.value[:, 0, :], axis=1)]

        def decide(x):
            v = x.astype(np.float32).tolist()
            node = 0
            while left[node] != -1:
                node = left[node] if v[feat[node]] <= thr[node] else right[node]
            return best[node]
    elif name == "mlp" and model.out_activation_ in ("softmax", "logistic"):
        layers = list(zip(model.coefs_, model.intercepts_, strict=True))
        binary = model.out_activation_ == "logistic"

        def decide(x):
            a = x
            for i, (w, b) in enumerate(layers):
                a = a @ w + b
                if i < len(layers) - 1:
                    a = np.maximum(a, 0.0)  # relu, the default activation
            return model.classes_[int(a[0] > 0.0) if binary else int(np.argmax(a))]
        if model.activation != "relu":
            return None
    elif name in ("1-nn", "5-nn") and getattr(model, "_fit_method", "") in ("kd_tree",
                                                                              "ball_tree"):
        tree, ys, k, n = model._tree, model._y, model.n_neighbors, len(model.classes_)

        def decide(x):
            ind = tree.query(x.reshape(1, -1), k=k, return_distance=False)[0]
            return model.classes_[int(np.argmax(np.bincount(ys[ind], minlength=n)))]
    else:
        return None
    rows = X[np.random.default_rng(0).integers(0, len(X), size=min(2000, len(X)))]
    if any(decide(x) != p for x, p in zip(rows, model.predict(rows), strict=True)):
        return None
    return decide


def demonstrations(b, seed: int, quick: bool = False):
    """The expert's demonstrations of behaviour ``b`` as ``rhbl train --behaviour`` teaches them
    with ``seed``: ``(learner, X, y, recipe)``, the trained learner and every vector it learned,
    in order."""
    recipe = recipe_of(b)
    if quick:  # and one randomised world at most (lab.generated), when the recipe has them
        recipe = recipe.replace(**QUICK, round_generated=min(recipe.round_generated, 1))
    learner = make_learner(recipe, record=True)
    train(world_of(b, b.teach[0]), learner, recipe, seed=seed, behaviour=b)
    X, y = learner.recorded()
    return learner, X, y, recipe


def fit(name: str, X: np.ndarray, y: np.ndarray, recipe, seed: int, learner):
    """Learner ``name`` fitted on ``(X, y)``: ``(policy, seconds, size, model)``, the fit timed
    alone (for RHBL the vectors offered in their order to a fresh learner, as the trained one
    learned them)."""
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.neural_network import MLPClassifier
    from sklearn.tree import DecisionTreeClassifier

    t0 = time.perf_counter()  # imports above: not part of a fit
    if name in ("rhbl", "rhbl-script"):
        fresh = learned_from(recipe, X, y)
        clf = fresh.classifier
        seconds = time.perf_counter() - t0
        from client.behaviour.learning import TreePolicy

        return TreePolicy(clf, fresh.features, fresh.actions), seconds, fresh.nodes, clf
    if name == "rhbl-vote":
        model = OrderVote(X, y, recipe, seed)
        seconds = time.perf_counter() - t0
        policy = PeerPolicy(model, learner.features, learner.actions, model.node_count_,
                            model.height_, model.predict_one)
        return policy, seconds, model.node_count_, model
    make = {"1-nn": lambda: KNeighborsClassifier(n_neighbors=1),
            "5-nn": lambda: KNeighborsClassifier(n_neighbors=5),
            "tree": lambda: DecisionTreeClassifier(random_state=seed),
            "mlp": lambda: MLPClassifier(hidden_layer_sizes=(32, 32), max_iter=300,
                                         random_state=seed)}
    if name not in make:
        raise ValueError(f"unknown learner {name!r}; known: {', '.join(LEARNERS)}")
    import warnings

    from sklearn.exceptions import ConvergenceWarning

    model = make[name]()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(X, y)
    seconds = time.perf_counter() - t0
    depth = 0
    if name == "tree":
        size, depth = model.tree_.node_count, model.get_depth()
    elif name == "mlp":
        size = sum(w.size for w in model.coefs_) + sum(v.size for v in model.intercepts_)
    else:
        size = model.n_samples_fit_
    decide = exact_decider(name, model, X)
    policy = PeerPolicy(model, learner.features, learner.actions, size, depth, decide)
    policy.exact = decide is not None
    return policy, seconds, size, model


def prediction_times(name: str, model, X: np.ndarray, seed: int) -> tuple[float, float]:
    """Microseconds per query: one vector at a time (the controller's query: RHBL's
    ``predict_one``, scikit-learn's ``predict`` of one row) and per vector in a batch of
    ``BATCH`` (``predict``), on vectors drawn from ``X``; each the best of ``REPEATS``."""
    rng = np.random.default_rng(seed)
    rows = X[rng.integers(0, len(X), size=max(SINGLE_QUERIES, BATCH))]
    one = model.predict_one if name.startswith("rhbl") else (lambda x: model.predict(x.reshape(1, -1)))
    one(rows[0])  # warm (a compiled kernel, a first call's set-up)
    single = batch = math.inf
    for _ in range(REPEATS):  # the best of a few: the least disturbed by a busy machine
        t0 = time.perf_counter()
        for x in rows[:SINGLE_QUERIES]:
            one(x)
        single = min(single, (time.perf_counter() - t0) / SINGLE_QUERIES)
        t0 = time.perf_counter()
        model.predict(rows[:BATCH])
        batch = min(batch, (time.perf_counter() - t0) / BATCH)
    return single * 1e6, batch * 1e6


def measured(b, name: str, policy, fit_s: float, size, model, X, seed: int, worlds_of,
             quick: bool, what: str) -> dict:
    """One fitted learner's entry: its prediction times, and ``policy`` driven in the
    teaching and held-out worlds ``worlds_of`` (two lists of names) by ``b``'s rule."""
    single, batch = prediction_times(name, model, X, seed)
    worlds = {}
    for kind, names in zip(("taught", "held_out"), worlds_of, strict=True):
        for w in names:
            spec = world_of(b, w)
            rep = evaluate(spec, policy, episodes=1 if quick else None,
                           seconds=20.0 if quick else None, seed=seed, behaviour=b)
            worlds[spec.name] = {
                "kind": kind, "episodes": rep["episodes"],
                "successes": sum(rep["success"]),
                "collisions": sum(e["collisions"] for e in rep["learner"]),
                "teacher_success_rate": rep["teacher_success_rate"]}
    print(f"  {what} {name}: size {size}, fit {fit_s:.2f} s, "
          + ", ".join(f"{w} {r['successes']}/{r['episodes']}" for w, r in worlds.items()),
          file=sys.stderr, flush=True)
    return {"size": int(size), "fit_s": fit_s, "single_us": single, "batch_us": batch,
            "worlds": worlds, "queries": getattr(policy, "queries", None),
            "exact_decider": getattr(policy, "exact", None)}


def run_seed(b, seed: int, learners: list[str], quick: bool = False,
             held_out: list[str] | None = None) -> dict:
    """One seed of behaviour ``b``: the demonstrations, every learner fitted on them and driven
    in the teaching and held-out worlds (``held_out``: these worlds instead, names or files).
    Returns ``{"vectors", "trained_nodes", "learners": {name: {...}}}``."""
    learner, X, y, recipe = demonstrations(b, seed, quick)
    out = {"seed": seed, "vectors": len(X), "trained_nodes": learner.nodes, "learners": {}}
    teach = list(b.teach)
    held = list(b.held_out if held_out is None else held_out)
    held = held[:1] if quick else held
    for name in learners:
        policy, fit_s, size, model = fit(name, X, y, recipe, seed, learner)
        out["learners"][name] = measured(b, name, policy, fit_s, size, model, X, seed,
                                         (teach, held), quick, f"{b.name} seed {seed}")
    return out


def _person_method(b):
    """The teaching study's person method with ``b``'s perception."""
    import dataclasses

    from bench_teach_study import make_method

    return dataclasses.replace(make_method("person"), features=b.features)


def person_session(model: str, seed: int, quick: bool = False, behaviour: str = "wall-following"):
    """A person model's session teaching ``behaviour`` in its first teaching world (wall
    following: the room), in-process as the teaching study runs it (``bench_teach_study.teach``:
    the person's learner with the behaviour's perception, the guard while the tree drives in
    correct mode): ``(learner, X, y)``, the person's learner and every label the person gave,
    each with the scan the learner paired it with (its estimated lag). ``model``: a person for
    any behaviour or the right-hand wall's own (``people.person``)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_teach_study import teach
    from people import person

    b = get(behaviour)
    who = person(model, b, seed=seed)  # ValueError naming the models
    times = {"demo": 60.0, "correct": 30.0} if quick else {}
    _, learner = teach(world_of(b, b.teach[0]), who, _person_method(b), seed=seed, guard=True,
                       **times)
    W, labels = learner.labelled()
    return learner, W[:, learner.estimated_lag if W.shape[1] > 1 else 0], np.array(labels)


def run_person(model: str, seed: int, learners: list[str], quick: bool = False,
               behaviour: str = "wall-following") -> dict:
    """One person model's session teaching ``behaviour`` (``person_session``) learned by every
    learner: RHBL is the person's learner rebuilt from the same labels (its person rule: the
    lag, the neighbours' vote), the others clone the labels as paired; each driven, without the
    guard, in the behaviour's teaching and held-out worlds."""
    b = get(behaviour)
    learner, X, y = person_session(model, seed, quick, behaviour)
    out = {"seed": seed, "vectors": len(X), "trained_nodes": learner.nodes, "learners": {}}
    held = list(b.held_out)[:1] if quick else list(b.held_out)
    for name in learners:
        if name == "rhbl":
            W, labels = learner.labelled()
            t0 = time.perf_counter()
            again = _person_method(b).learner()  # the session's learner, new
            for w, label in zip(W, labels, strict=True):
                if learner.lag is None:
                    again.observe_vector(w[0], label, earlier=w[1:])
                else:
                    again.observe_vector(w[0], label)
            clf = again.classifier
            fit_s = time.perf_counter() - t0
            from client.behaviour.learning import TreePolicy

            policy, size, model_ = TreePolicy(clf, again.features, again.actions), again.nodes, clf
        else:
            # rhbl-vote: the scripted rule's trees on the labels as paired, as the peers learn
            policy, fit_s, size, model_ = fit(name, X, y, recipe_of(b), seed, learner)
        out["learners"][name] = measured(b, name, policy, fit_s, size, model_, X, seed,
                                         (list(b.teach), held), quick,
                                         f"person {model} seed {seed}")
    return out


def _rate(runs: list[dict], name: str, kind: str) -> tuple[int, int]:
    """(successes, episodes) of learner ``name`` over ``runs`` in the worlds of ``kind``."""
    ok = n = 0
    for run in runs:
        for r in run["learners"][name]["worlds"].values():
            if r["kind"] == kind:
                ok += r["successes"]
                n += r["episodes"]
    return ok, n


def _num(v: float) -> str:
    """``v`` with 3 significant digits (a whole number: all its digits), never in exponent
    form."""
    if v == int(v):
        return f"{int(v):,}"
    if v >= 100:
        return f"{v:,.0f}"
    return f"{v:.1f}" if v >= 10 else f"{v:.2g}" if v < 0.1 else f"{v:.2f}"


def _mean(values) -> str:
    values = list(values)
    m = statistics.fmean(values)
    if len(values) < 2:
        return _num(m)
    return f"{_num(m)} ± {_num(statistics.stdev(values))}"


def summary_rows(results: dict[str, list[dict]], learners: list[str]) -> list[list[str]]:
    """The peer table's rows: per behaviour and learner, over the seeds."""
    rows = []
    for bname, runs in results.items():
        for name in learners:
            if any(name not in run["learners"] for run in runs):
                rows.append([bname, name, *["not measured"] * (len(HEADER) - 2)])
                continue
            per = [run["learners"][name] for run in runs]
            ok_t, n_t = _rate(runs, name, "taught")
            ok_h, n_h = _rate(runs, name, "held_out")
            coll = statistics.fmean(sum(w["collisions"] for w in p["worlds"].values()) for p in per)
            rows.append([
                bname, name,
                f"{ok_t / n_t:.0%} ({ok_t}/{n_t})" if n_t else "-",
                f"{ok_h / n_h:.0%} ({ok_h}/{n_h})" if n_h else "-",
                _num(coll) if coll else "0",
                _mean(p["size"] for p in per),
                _mean(p["fit_s"] for p in per),
                _num(statistics.median(p["single_us"] for p in per)),
                _num(statistics.median(p["batch_us"] for p in per))])
    return rows


def world_rows(results: dict[str, list[dict]], learners: list[str]) -> list[list[str]]:
    """Success per world (over the seeds), a row per behaviour and world."""
    rows = []
    for bname, runs in results.items():
        for w, first in runs[0]["learners"][learners[0]]["worlds"].items():
            cells = []
            for name in learners:
                if any(name not in run["learners"] for run in runs):
                    cells.append("-")
                    continue
                ok = sum(run["learners"][name]["worlds"][w]["successes"] for run in runs)
                n = sum(run["learners"][name]["worlds"][w]["episodes"] for run in runs)
                cells.append(f"{ok / n:.0%}")
            teacher = statistics.fmean(run["learners"][learners[0]]["worlds"][w]
                                       ["teacher_success_rate"] for run in runs)
            rows.append([bname, f"{w} ({'taught' if first['kind'] == 'taught' else 'held out'})",
                         *cells, f"{teacher:.0%}"])
    return rows


PERSON = " by "  # the results' key of a person model's sessions: behaviour + this + its name


def pooled(results: dict[str, list[dict]]) -> dict[str, list[dict]]:
    """``results`` and, for each behaviour taught by more than one person model, those sessions
    together under "B by N people" (every model's seeds: the success over all their episodes,
    sizes and times over all their sessions)."""
    by: dict[str, list[str]] = {}
    for k in results:
        if PERSON in k:
            by.setdefault(k.split(PERSON, 1)[0], []).append(k)
    out = dict(results)
    for bname, people in by.items():
        if len(people) > 1:
            out[f"{bname}{PERSON}{len(people)} people"] = [r for k in people for r in results[k]]
    return out


HEADER = ["behaviour", "learner", "success taught", "success held out", "collisions / seed",
          "model size", "learning s", "predict µs (one)", "predict µs/vector (batch)"]


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seeds must be integers like 0,1,2, got {text!r}") from None
    if not seeds or any(s < 0 or s > 2**31 for s in seeds):
        raise argparse.ArgumentTypeError(f"--seeds must be integers >= 0 like 0,1,2, got {text!r}")
    return seeds


def _names(known: list[str], what: str, empty: bool = False, every: bool = False):
    def check(text: str) -> list[str]:
        if every and text.strip() == "all":
            return list(known)
        names = [v.strip() for v in text.split(",") if v.strip()]
        bad = [v for v in names if v not in known]
        if (not names and not (empty and text == "")) or bad:
            raise argparse.ArgumentTypeError(
                f"--{what}: unknown {', '.join(map(repr, bad)) or 'empty list'}; "
                f"known: {', '.join(known)}")
        return names
    return check


def _write(path: str, results: dict, args, wall: float) -> None:
    """The measurements so far as JSON (``--json``)."""
    seeds = sorted({r["seed"] for runs in results.values() for r in runs})
    Path(path).write_text(json.dumps({"seeds": seeds, "quick": args.quick,
                                      "learners": LEARNERS, "results": results,
                                      "wall_s": wall}, indent=1))


def merged(paths: list[str]) -> tuple[dict, list[int], bool, list[str]]:
    """The results of several ``--json`` files as one run's (a behaviour's seeds from several
    files together, and other learners of the same seed's demonstrations): ``(results, seeds,
    quick, learners)``, the learners any file measured; ValueError when they differ in size
    (``--quick``), measure a learner of a behaviour's seed twice or learn other vectors."""
    results: dict = {}
    seen = None
    learners: set[str] = set()
    for path in paths:
        data = json.loads(Path(path).read_text())
        for bname, runs in data["results"].items():
            for run in runs:
                if seen is not None and data["quick"] != seen:
                    raise ValueError(f"{path}: --quick differs from the first file's")
                seen = data["quick"]
                learners |= set(run["learners"])
                have = results.setdefault(bname, [])
                same = next((r for r in have if r["seed"] == run["seed"]), None)
                if same is None:
                    have.append(run)
                elif set(same["learners"]) & set(run["learners"]):
                    raise ValueError(f"{path}: {bname} seed {run['seed']} measured twice")
                elif same["vectors"] != run["vectors"]:
                    raise ValueError(f"{path}: {bname} seed {run['seed']}: {run['vectors']} "
                                     f"vectors, another file's {same['vectors']}")
                else:  # other learners on the same demonstrations
                    same["learners"].update(run["learners"])
    if seen is None:
        raise ValueError(f"{', '.join(paths)}: no measurement")
    for runs in results.values():
        runs.sort(key=lambda r: r["seed"])
    seeds = sorted({r["seed"] for runs in results.values() for r in runs})
    return results, seeds, seen, [n for n in LEARNERS if n in learners]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    behaviours = sorted(shipped())
    ap.add_argument("--behaviour", type=_names(behaviours, "behaviour", empty=True),
                    default=behaviours,
                    help=f"comma-separated shipped behaviours (default: all: {','.join(behaviours)})")
    ap.add_argument("--learners", type=_names(list(LEARNERS), "learners"), default=DEFAULT,
                    help=f"comma-separated, of {','.join(LEARNERS)} (default: "
                         f"{','.join(DEFAULT)})")
    ap.add_argument("--seeds", type=_seeds, default=[0, 1, 2], help="training seeds (default 0,1,2)")
    ap.add_argument("--people", type=_names(PEOPLE_MODELS, "people", every=True), default=[],
                    help="also these person models' sessions teaching each --people-behaviour "
                         "(in-process, benchmarks/people.py), one a seed; 'all': "
                         f"{','.join(PEOPLE_MODELS)}; default none")
    ap.add_argument("--people-behaviour", type=_names(behaviours, "people-behaviour"),
                    default=["wall-following"],
                    help="the behaviours the --people teach, comma-separated (default "
                         "wall-following; the right-hand wall's own models teach only that)")
    ap.add_argument("--quick", action="store_true", help="a small run (see above)")
    ap.add_argument("--eval-world", action="append", default=None, metavar="WORLD",
                    help="drive in this world (a name or file; repeatable) instead of each "
                         "behaviour's held-out worlds: a development set of your own "
                         "(rhbl generate rooms|mazes --seed S --out DIR), so that a choice is "
                         "made without seeing the held-out worlds; not with --people")
    ap.add_argument("--json", default=None, help="write every measurement here")
    ap.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                    help="measure nothing: print the tables of these --json files together "
                         "(runs of other behaviours, made side by side)")
    return ap


def _checked(ap: argparse.ArgumentParser, args) -> None:
    """What the options say together (``ap.error``: one line, exit 2)."""
    if not args.from_json and not args.behaviour and not args.people:
        ap.error("nothing to measure: --behaviour is empty and no --people given")
    if args.eval_world and args.people:
        ap.error("--eval-world is for the scripted demonstrations, not with --people")
    for w in args.eval_world or []:
        try:
            load_world(world_path(w))
        except (OSError, ValueError) as exc:
            ap.error(f"--eval-world {w}: {exc}")
    if args.people:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from people import person

        try:
            for bname in args.people_behaviour:
                for model in args.people:
                    person(model, bname)
        except ValueError as exc:
            ap.error(f"--people: {exc}")


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    _checked(ap, args)
    t0 = time.perf_counter()
    results: dict[str, list[dict]] = {}
    if args.from_json:
        try:
            results, args.seeds, args.quick, args.learners = merged(args.from_json)
        except (OSError, ValueError, KeyError) as exc:
            print(f"bench_peers: --from-json: {exc}", file=sys.stderr)
            return 2
    for bname in [] if args.from_json else args.behaviour:
        b = get(bname)
        results[bname] = []
        for seed in args.seeds:
            results[bname].append(run_seed(b, seed, args.learners, args.quick,
                                           args.eval_world))
            if args.json:  # after every seed: a run stopped part-way keeps what it measured
                _write(args.json, results, args, time.perf_counter() - t0)
    for bname, model in [] if args.from_json else [(bn, m) for bn in args.people_behaviour
                                                    for m in args.people]:
        key = f"{bname}{PERSON}{model}"
        results[key] = []
        for seed in args.seeds:
            results[key].append(run_person(model, seed, args.learners, args.quick, bname))
            if args.json:
                _write(args.json, results, args, time.perf_counter() - t0)
    wall = time.perf_counter() - t0
    shown = pooled(results)
    vectors = {k: round(statistics.fmean(r["vectors"] for r in runs)) for k, runs in shown.items()}
    print(table(HEADER, summary_rows(shown, args.learners),
                title=f"Peers: the same demonstrations, seeds {','.join(map(str, args.seeds))}"
                      f"{' (quick)' if args.quick else ''}; vectors learned per seed: "
                      + ", ".join(f"{k} {v}" for k, v in vectors.items())))
    print()
    print(table(["behaviour", "world", *args.learners, "expert"], world_rows(shown, args.learners),
                title="Success per world (all seeds' episodes)"))
    same = all(r["learners"]["rhbl"]["size"] == r["trained_nodes"]
               for runs in results.values() for r in runs
               if "rhbl" in r["learners"]) if "rhbl" in args.learners else None
    if same is not None:
        print(f"rhbl refitted on the vectors = the tree rhbl train grew: {'yes' if same else 'NO'}")
    if not args.from_json:
        print(f"wall time {wall:.0f} s")
    if args.json and not args.from_json:
        _write(args.json, results, args, wall)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
