"""The same labels, learned again: how a person's learner's settings and its build order move
the tree's success, on sessions already taught.

A session's labels (each with the scans shown before its own: ``PersonLearner``'s
``earlier``) come from a recording of the real page (``bench_teach.py``'s ``session.mcap``,
paired as ``rhbl train --from-recording`` pairs them), from the learner's own tree and journal
of a session (``bench_teach.py``'s ``tree.rhbl``: the labels it holds, as a restarted
``rhbl learner`` recovers them, withdrawn ones left out) or from an in-process session of the
teaching study (``model:seed``: ``bench_teach_study.teach`` with the default learner and the
guard, deterministic). Every method (``bench_teach_study.make_method``'s syntax:
``person``, ``person:k=25``, ``person:vote=median``: ``study_votes.StudyLearner``) learns each
session's labels again, once per shuffle seed (``PersonLearner(seed=...)``: the order the tree
learns its vectors in), and the tree is evaluated through the controller's guard (the rule's:
path check on) from every start pose of
``--worlds`` (the first: the taught room). Corrections were given while the session's own tree
drove; here they are labels like the others.

    python benchmarks/bench_vote.py --sessions novice:0,.../session.mcap,.../tree.rhbl \
        --methods person,person:k=25,person:vote=median --shuffles 0,1,2 [--json out.jsonl]

Prints a line per (session, method, shuffle), then per method the mean success, the runs under
90% in the taught room and under 80% unseen, and per session the mean over the shuffles.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_teach import UNSEEN, parse_seeds  # noqa: E402
from bench_teach_study import make_method, teach  # noqa: E402
from people import PEOPLE  # noqa: E402

from client.behaviour.guard import RotationGuard, settings_for  # noqa: E402
from client.behaviour.learning import TreePolicy  # noqa: E402
from client.journal import journal_path  # noqa: E402
from client.lineage import Lineage  # noqa: E402
from lab.evaluate import evaluate  # noqa: E402
from lab.harness import resolve_world  # noqa: E402
from lab.retrain import retrain  # noqa: E402

WORLDS = ",".join(("room", *UNSEEN))


def labels_of(session: str) -> tuple[np.ndarray, list[str]]:
    """(W, labels): per label its features at lags 0..MAX_LAG (the scan it names, then the
    scans shown before it) and the key, in the order given."""
    if session.endswith(".mcap"):
        learner, _ = retrain([session], teacher="person", lag=None)
    elif session.endswith(".rhbl"):
        learner = journaled(Path(session))
    else:
        model, _, seed = session.partition(":")
        if model not in PEOPLE:
            raise SystemExit(f"--sessions: no person model {model!r}; known: {', '.join(PEOPLE)}")
        try:
            seed = parse_seeds(seed or "0", f"--sessions {session!r}: the seed")[0]
        except ValueError as exc:
            raise SystemExit(str(exc)) from None
        _, learner = teach(resolve_world("room"), PEOPLE[model](seed=seed),
                           make_method("person"), seed=seed, guard=True)
    return learner.labelled()


def journaled(tree: Path):
    """The person's learner of ``tree``'s journal, recovered as ``rhbl learner`` does, from
    a copy (the session's files are never opened for writing)."""
    if not journal_path(tree).exists():
        raise SystemExit(f"--sessions: {tree} has no journal {journal_path(tree).name}")
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / tree.name
        for src in (tree, journal_path(tree)):
            if src.exists():
                shutil.copy(src, Path(tmp) / src.name)
        core = Lineage(copy)
        try:
            if not core.person:
                raise SystemExit(f"--sessions: {tree} is not a person's lineage")
            return core.learner
        finally:
            core.close()


def learn_again(method: str, W: np.ndarray, labels: list[str], shuffle: int):
    """The learner of ``method`` (seed ``shuffle``) given the labels again, through its
    public ``observe_vector`` (a fixed lag takes the scan that many before each label's)."""
    m = make_method(method)
    m.options["seed"] = shuffle
    learner = m.learner()
    for w, label in zip(W, labels, strict=True):
        if m.lag is None:
            learner.observe_vector(w[0], label, earlier=w[1:])
        else:
            learner.observe_vector(w[m.lag], label)
    return learner


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sessions", required=True,
                    help="comma-separated: recordings (.mcap) and/or in-process model:seed")
    ap.add_argument("--methods", default="person", help="comma-separated methods")
    ap.add_argument("--shuffles", default="0,1", help="comma-separated build-order seeds")
    ap.add_argument("--worlds", default=WORLDS, help="the taught room first, then unseen ones")
    ap.add_argument("--json", default=None, help="append a JSON line per run here")
    args = ap.parse_args(argv)
    worlds = args.worlds.split(",")
    try:
        shuffles = parse_seeds(args.shuffles, "--shuffles")
    except ValueError as exc:
        ap.error(str(exc))
    methods = args.methods.split(",")
    for m in methods:
        make_method(m)  # refuse a bad one before any session is taught
    rows = []
    for session in args.sessions.split(","):
        W, labels = labels_of(session)
        for method in methods:
            for shuffle in shuffles:
                t0 = time.perf_counter()
                learner = learn_again(method, W, labels, shuffle)
                tree = TreePolicy.from_learner(learner)  # through its rule's guard
                policy = RotationGuard.of(settings_for(tree.metadata), tree)
                res = {}
                for w in worlds:
                    rep = evaluate(resolve_world(w), policy)
                    res[w] = {"success": rep["success_rate"], "loops": len(rep["loops"]),
                              "collisions": sum(e["collisions"] for e in rep["learner"])}
                row = {"session": session, "method": method, "shuffle": shuffle,
                       "labels": len(labels), "lag": getattr(learner, "estimated_lag", None),
                       "nodes": learner.nodes, "worlds": res,
                       "taught": res[worlds[0]]["success"],
                       "unseen": float(np.mean([res[w]["success"] for w in worlds[1:]]))
                       if len(worlds) > 1 else None,
                       "seconds": round(time.perf_counter() - t0, 1)}
                rows.append(row)
                print(f"{session} {method} shuffle {shuffle}: taught {row['taught']:.0%}"
                      + (f", unseen {row['unseen']:.0%}" if row["unseen"] is not None else "")
                      + f", lag {row['lag']}, {row['nodes']} nodes", flush=True)
                if args.json:
                    with open(args.json, "a") as f:
                        f.write(json.dumps(row) + "\n")
    print()
    print("| method | runs | taught room | runs < 90% | unseen rooms | runs < 80% | loops | "
          "collisions |")
    print("|---|---|---|---|---|---|---|---|")
    for method in methods:
        rs = [r for r in rows if r["method"] == method]
        t = np.array([r["taught"] for r in rs])
        u = np.array([r["unseen"] if r["unseen"] is not None else np.nan for r in rs])
        loops = sum(v["loops"] for r in rs for v in r["worlds"].values())
        coll = sum(v["collisions"] for r in rs for v in r["worlds"].values())
        print(f"| {method} | {len(rs)} | {t.mean():.0%} | {(t < 0.9).sum()} | "
              f"{np.nanmean(u):.0%} | {(u < 0.8).sum()} | {loops} | {coll} |")
    print()
    for method in methods:
        per = []
        for session in args.sessions.split(","):
            rs = [r for r in rows if r["method"] == method and r["session"] == session]
            per.append(f"{Path(session).parent.name if session.endswith('.mcap') else session}"
                       f" {np.mean([r['taught'] for r in rs]):.0%}")
        print(f"{method}: " + ", ".join(per))
    return 0


if __name__ == "__main__":
    sys.exit(main())
