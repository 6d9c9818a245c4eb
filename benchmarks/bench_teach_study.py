"""The in-process teaching study: models of people teach wall following at a simulated console.

    python benchmarks/bench_teach_study.py [--models steady,hurried] [--seeds 3] \
        [--methods today,literal,person,person:k=25,person:lag=auto] [--guard] \
        [--clearance 0.3] [--no-guard-straight] \
        [--restart-correct 20] [--restart-demo 20 --where starts|free|near] \
        [--task wall-following|maze] [--worlds room,eval-room-l,...] [--bare] [--json out.json]

No zenoh, no browser: the world is stepped at 10 Hz as ``lab.harness`` does, and the page's and
the console's semantics are reproduced. The person (``benchmarks/people.py``) sees each frame
(the scan and pose the page shows, ``--latency`` behind the world) and holds a key; while a key
is held every displayed scan is labelled with it (one label per scan) and the robot executes it;
no key: in demonstrate mode the console stops the robot and sends no label, in correct mode the
controller drives the tree the learner published last (a snapshot every ``refresh`` s, as
``rhbl learner --snapshot-every 2`` and ``rhbl controller --follow`` do) and the person takes
over when they judge it necessary (HG-DAgger: only their takeovers are labels).

A method is a learner and the scan its labels are tied to: ``today`` and ``literal`` (the
paper's rule, ``spawn="all"``) learn each label as it arrives, tied to the scan displayed when
the key went out (today's console); ``person`` ties each label to the scan the person answered
(``client.behaviour.teaching.answered_scan``, ``lag`` scans earlier) and builds the tree by the
neighbours' majority (``PersonLearner``). Options after a colon, joined by ``+``:
``person:lag=2+k=25+copies=3``.

Per person model and seed: ``--demo`` s of demonstrating from the world's pose, then
``--correct`` s of correcting, then the tree evaluated with ``lab.evaluate`` in the room it was
taught in and in unseen rooms. Printed per model and method (mean over seeds, min in brackets):
success as ``lab.evaluate`` judges it (no collision, >= 80% of the time with the right-hand wall
within 0.3-1.2 m, and at least 70% of the scripted teacher's distance), success at the person's
own pace (70% of the distance the person covers from the same start, the rest unchanged),
oscillation loops, collisions, tree size, labels, corrections, wrong keys and why episodes
failed. ``--task maze`` teaches in the tiered maze (``maze``) and evaluates there and in the
unseen mazes: success is then the maze's (the goal reached with no collision), and when the
robot reaches the goal while teaching the person puts it at the next start pose. ``--bare``
(with ``--guard``) also evaluates the tree alone. ``--alone`` also drives each person model by
itself from every start pose: what the person does, judged the same way (their own pace is
that reference).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from people import DEV, FRESH, HELD_OUT, PEOPLE, View  # noqa: E402

from client.behaviour.actions import DEFAULT_ACTIONS  # noqa: E402
from client.behaviour.features import FEATURES  # noqa: E402
from client.behaviour.guard import RotationGuard  # noqa: E402
from client.behaviour.learning import DemonstrationLearner, TreePolicy  # noqa: E402
from client.behaviour.rule import PERSON  # noqa: E402
from client.behaviour.teaching import PersonLearner, answered_scan  # noqa: E402
from lab import metrics  # noqa: E402
from lab.episode import DT, Episode  # noqa: E402
from lab.evaluate import evaluate, success  # noqa: E402
from lab.harness import resolve_world  # noqa: E402
from lab.recipe import EVAL_SECONDS  # noqa: E402
from server.world import World, free_pose, sample_pose  # noqa: E402

TAUGHT = "room"
UNSEEN_DEV = ("eval-room-l", "eval-room-ring", "eval-room-jagged", "eval-holdout-room-t")
UNSEEN_HELD_OUT = ("eval-holdout-room-oct", "eval-holdout2-room-spike", "eval-holdout4-room-open")
# --task maze: taught in the tiered maze, the unseen mazes of docs/experiments.md's first table
MAZE_WORLDS = ("maze", "eval-maze-3tier", "eval-maze-5tier", "eval-maze-narrow")
DEFAULT_WORLDS = {"wall-following": (TAUGHT, *UNSEEN_DEV), "maze": MAZE_WORLDS}


def task_of(spec) -> str:
    """The behaviour a world of this study is taught or judged for (worlds name none): a world
    with a goal is a maze, every other one a room to follow the right-hand wall in."""
    return "maze" if spec.goal is not None else "wall-following"

# --where near: the robot dragged off its path (m, normal), turned (rad, uniform), and left at
# least this far from every wall (m): the person then shows the way back
NEAR = (0.2, 0.8, 0.35)
SCAN_MEMORY = 128  # scans the console keeps (client/console/app.py)


@dataclass
class Session:
    """What happened in one teaching session."""

    model: str
    seed: int
    labels: int = 0                 # labels sent (one per displayed scan with a key held)
    demo_labels: int = 0
    corrections: int = 0            # labels given in correct mode (takeovers)
    takeovers: int = 0
    wrong: int = 0                  # labels whose key was not the one the person meant
    collisions: int = 0             # while teaching
    goals: int = 0                  # times the robot reached the goal (then put at a start)
    poses: list = field(default_factory=list)
    side: list = field(default_factory=list)   # right-hand wall distance (lab.metrics) per step

    def labelled(self, wrong: bool, mode: str, in_control: bool) -> None:
        """A label counted: a wrong key, a correction (a takeover when the controller was
        driving) or a demonstration."""
        self.labels += 1
        self.wrong += wrong
        if mode == "correct":
            self.corrections += 1
            self.takeovers += not in_control
        else:
            self.demo_labels += 1

    def stepped(self, world, name: str | None) -> None:
        """The world stepped with action ``name`` (None: stand), a new stall counted as a
        collision, the pose kept."""
        vx, va = DEFAULT_ACTIONS[name] if name else (0.0, 0.0)
        world.set_command(0, vx, va)
        world.step(DT)
        stalled = world.stall(0)
        if stalled and not (self.poses and self.poses[-1][3]):
            self.collisions += 1
        self.poses.append((*world.pose(0), stalled))


@dataclass(frozen=True)
class Method:
    """A learner and the lag of the scans its labels are tied to (``answered_scan``; None:
    estimated by the person's learner from the scans before each label's own)."""

    name: str
    lag: int | None
    options: dict
    # the perception (a FeatureSpec); None: the wall features of both tasks' recipes
    # (lab.recipe.RECIPES); another behaviour's: its own (bench_peers' person sessions)
    features: object = None

    def learner(self, task: str = "wall-following") -> DemonstrationLearner:
        spec = FEATURES["wall"] if self.features is None else self.features
        if self.name == "person":
            if "vote" in self.options:  # a study's vote (benchmarks/study_votes.py)
                from study_votes import StudyLearner

                return StudyLearner(spec, DEFAULT_ACTIONS, task=task, lag=self.lag,
                                    **self.options)
            return PersonLearner(spec, DEFAULT_ACTIONS, task=task, lag=self.lag, **self.options)
        spawn = "all" if self.name == "literal" else "winner"
        return DemonstrationLearner(spec, DEFAULT_ACTIONS, task=task, spawn=spawn,
                                    **self.options)


METHODS = {"today": 0, "literal": 0, "person": None}  # name -> the default lag (None: estimated)


def make_method(text: str) -> Method:
    """``person``, ``person:lag=2+k=25+vote=mean``: a method with those settings
    (``lag=auto``: estimated by the person's learner)."""
    name, _, opts = text.partition(":")
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; known: {', '.join(METHODS)}")
    options: dict = {}
    for part in filter(None, opts.split("+")):
        key, _, value = part.partition("=")
        options[key] = (value if value.replace("-", "").isalpha()
                        else float(value) if "." in value else int(value))
    lag = options.pop("lag", METHODS[name])
    lag = None if lag in (None, "auto") else int(lag)
    if lag is None and name != "person":
        raise ValueError(f"method {name!r} needs a fixed lag")
    return Method(name, lag, options)


def snapshot(learner: DemonstrationLearner) -> TreePolicy | None:
    """The tree as the learner would publish it now (a copy: learning goes on)."""
    if learner.vectors == 0:
        return None
    return TreePolicy(copy.deepcopy(learner.classifier), learner.features, learner.actions)


def _learn(learner, method: Method, scans: OrderedDict, shown: int, key: str) -> None:
    """The person's label ``key`` given on scan ``shown``, learned as ``method`` pairs it:
    with its own scan and the scans before it (``method.lag`` None: the lag estimated), or
    with the scan ``method.lag`` before it."""
    if method.lag is None:  # the label's own scan, and the scans before it
        ranges, odom, _ = scans[shown]
        earlier = []
        for lag in range(1, PERSON.alignment.max_lag + 1):
            sid = answered_scan(shown, scans, lag, pose=lambda s: s[2])
            if sid == shown:
                break
            earlier.append(learner.features.extract(scans[sid][0], scans[sid][1][2]))
        learner.observe(ranges, odom[2], key, earlier=earlier)
    else:
        ranges, odom, _ = scans[answered_scan(shown, scans, method.lag, pose=lambda s: s[2])]
        learner.observe(ranges, odom[2], key)


def _elsewhere(spec, world: World, where: str, rng) -> tuple | None:
    """Where the person puts the robot (``teach``'s ``where``): anywhere in the free space
    (``"free"``), a little off where it is (``"near"``), or None: the next start pose."""
    if where == "free":
        return free_pose(spec, rng)
    if where == "near":
        return sample_pose(spec, [world.pose(0)], rng, jitter=NEAR[0], turn=NEAR[1],
                           clearance=NEAR[2])
    return None


def teach(spec, person, method: Method, *, demo: float = 240.0, correct: float = 120.0,
          seed: int = 0, latency: float = 0.03, refresh: float = 2.0, guard: bool = False,
          restarts: tuple[float, float] = (0.0, 0.0), where: str = "starts",
          clearance: float = PERSON.guard.clearance,
          straight: bool = True) -> tuple[Session, DemonstrationLearner]:
    """One session (see the module's docstring). ``guard``: the controller drives through a
    ``RotationGuard`` (``clearance``: its path check, 0 off; ``straight``: an overruled
    reversal drives straight on while the path is clear). ``restarts`` = (demonstrate,
    correct) seconds: > 0, the person puts the robot elsewhere this often in that mode (the
    console's set_pose): at the world's next start pose (``where="starts"``), anywhere in the
    free space, any heading (``"free"``:
    ``server.world.free_pose``, as a person dragging the robot about would), or a little off
    where it is (``"near"``: ``server.world.sample_pose`` with ``NEAR``: dragged off its path
    and turned, so the person shows the way back). A world with a goal (the maze): when the
    robot reaches it, in either mode, the person puts it at the world's next start pose (the
    console's set_pose) and teaches the way again (``Session.goals`` counts them)."""
    rng = np.random.default_rng(seed + 555)
    task = task_of(spec)
    learner = method.learner() if task == "wall-following" else method.learner(task)
    world = World(spec, robots=1, seed=seed)
    world.reset(poses=[tuple(spec.pose)])
    walls = spec.segments()
    starts = list(spec.start_poses)
    person.reset()
    rec = Session(model=person.style.name, seed=seed)
    behind = int(latency // DT)  # scans the page is behind the world
    scans: OrderedDict = OrderedDict()  # id -> (ranges, odometry, true pose): the console's memory
    driver, action, drive, next_refresh = "", None, None, refresh
    moved_at, next_start, in_control = 0.0, 0, False
    for k in range(int(round((demo + correct) / DT))):
        t = k * DT
        mode = "demonstrate" if t < demo else "correct"
        if mode == "correct" and k == int(round(demo / DT)):
            in_control = False  # the person switches the page to correct mode
        every = restarts[0] if mode == "demonstrate" else restarts[1]
        if spec.goal is not None and k > 0 and math.dist(world.pose(0)[:2],
                                                         spec.goal.center) <= spec.goal.radius:
            rec.goals += 1
            moved_at, next_start = t, next_start + 1
            world.set_pose(0, starts[next_start % len(starts)])
        if every > 0 and t > 0 and (t - moved_at >= every - 1e-9
                                    or (mode == "correct" and moved_at < demo)):
            moved_at, next_start = t, next_start + 1  # the next start pose (set_pose)
            world.set_pose(0, _elsewhere(spec, world, where, rng)
                           or starts[next_start % len(starts)])
        scans[k] = (world.scan(0), world.odom(0), world.pose(0))
        while len(scans) > SCAN_MEMORY:
            scans.popitem(last=False)
        rec.side.append(metrics.side_distance(scans[k][0], "right"))
        shown = max(0, k - behind)
        key = person.observe(View(t=t, pose=scans[shown][2], walls=walls, mode=mode,
                                  driver=driver, action=action, scan_id=shown))
        if key is not None:
            _learn(learner, method, scans, shown, key)
            rec.labelled(person.wrong_now, mode, in_control)
            in_control = True
        # the learner publishes its tree every ``refresh`` s, the controller swaps it in (an
        # incremental build depends on when it is built: built as often while demonstrating)
        if t >= next_refresh and (mode == "correct" or getattr(learner, "build", "") == "repair"):
            next_refresh = t + refresh
            tree = snapshot(learner)
            if tree is not None:
                drive = (RotationGuard(tree, clearance=clearance, straight=straight)
                         if guard else tree)
                drive.reset()
        if key is not None:
            name, driver = key, "teacher"
        elif mode == "correct":
            in_control = False
            name = drive.act(scans[k][0], scans[k][1]) if drive is not None else None
            driver = "controller" if name else ""
        else:
            name, driver = None, ""
        rec.stepped(world, name)
        action = name
    return rec, learner


def drive_alone(spec, person, start, seconds: float, seed: int = 0) -> Episode:
    """The person drives by themselves from ``start`` (demonstrate mode, nothing learned)."""
    world = World(spec, robots=1, seed=seed)
    world.reset(poses=[tuple(start)])
    walls = spec.segments()
    person.reset()
    ep = Episode(start=tuple(start), kind="person")
    for k in range(int(round(seconds / DT))):
        ranges = world.scan(0)
        key = person.observe(View(t=k * DT, pose=world.pose(0), walls=walls))
        vx, va = DEFAULT_ACTIONS[key] if key else (0.0, 0.0)
        world.set_command(0, vx, va)
        world.step(DT)
        ep.actions.append(key or "stop")
        ep.poses.append(world.pose(0))
        ep.stalls.append(world.stall(0))
        ep.side.append(metrics.side_distance(ranges, "right"))
    return ep


_ALONE: dict = {}


def alone(model: str, seed: int, world: str) -> list[dict]:
    """Metrics of the person driving alone from each start pose of ``world`` (cached)."""
    key = (model, seed, world)
    if key not in _ALONE:
        spec = resolve_world(world)
        seconds = EVAL_SECONDS[task_of(spec)]
        _ALONE[key] = [drive_alone(spec, PEOPLE[model](seed=1000 * seed + i), st, seconds,
                                   seed=seed).metrics(spec.goal)
                       for i, st in enumerate(spec.start_poses)]
    return _ALONE[key]


def _why(lm: dict) -> str:
    """Why an episode failed (``lab.evaluate.success``): the first reason that holds."""
    if lm["oscillation_loops"]:
        return "loop"
    if lm["collisions"]:
        return "collision"
    if lm["goal_reached"] is False:  # a world with a goal (None: none)
        return "goal not reached"
    if lm["wall_band_fraction"] < 0.8:
        return "off the wall"
    return "too short"  # under 70% of the scripted teacher's distance


def score(policy, worlds, model: str, seed: int = 0) -> dict:
    """``lab.evaluate`` of ``policy`` on each world: success, success at the person's pace,
    loops, collisions, and why the failed episodes failed."""
    out = {}
    for name in worlds:
        rep = evaluate(resolve_world(name), policy, seed=seed)
        why: dict = {}
        for lm in rep["learner"]:
            if not lm["success"]:
                w = _why(lm)
                why[w] = why.get(w, 0) + 1
        # at the person's pace (wall following: 70% of their distance; the maze's rule has no
        # distance: the same as success)
        pace = [success(rep["task"], lm, own)
                for lm, own in zip(rep["learner"], alone(model, seed, name), strict=True)]
        out[name] = {"success": rep["success_rate"], "pace": float(np.mean(pace)),
                     "loops": len(rep["loops"]),
                     "collisions": sum(e["collisions"] for e in rep["learner"]),
                     "teacher": rep["teacher_success_rate"], "failed": why}
    return out


def _guard_name(clearance: float, straight: bool) -> str:
    """The guard's settings as the tables name them."""
    if not clearance:
        return "guard, no clearance"
    return f"guard, clearance {clearance:g}" + ("" if straight else ", turning on")


def run_one(model: str, seed: int, method: str, worlds, *, demo: float = 240.0,
            correct: float = 120.0, latency: float = 0.03, guard: bool = False,
            restarts: tuple[float, float] = (0.0, 0.0), where: str = "starts",
            clearance: float = PERSON.guard.clearance, straight: bool = True, bare: bool = False) -> dict:
    """One person model, one seed, one method: teach, then evaluate (``bare``, with ``guard``:
    also the tree alone, as ``rhbl evaluate`` and ``rhbl experiment`` judge it: ``"bare"``)."""
    t0 = time.perf_counter()
    rec, learner = teach(resolve_world(worlds[0]), PEOPLE[model](seed=seed), make_method(method),
                         demo=demo, correct=correct, seed=seed, latency=latency, guard=guard,
                         restarts=restarts, where=where, clearance=clearance,
                         straight=straight)
    policy = TreePolicy.from_learner(learner)
    scores = score(RotationGuard(policy, clearance=clearance, straight=straight) if guard
                   else policy, worlds, model, seed=seed)
    return {"model": model, "seed": seed, "method": method,
            "guard": guard and _guard_name(clearance, straight),
            "labels": rec.labels, "demo_labels": rec.demo_labels,
            "corrections": rec.corrections, "takeovers": rec.takeovers,
            "wrong": rec.wrong, "teaching_collisions": rec.collisions, "goals": rec.goals,
            "nodes": learner.nodes, "height": learner.height,
            "lag": getattr(learner, "estimated_lag", 0),
            "agreement": [round(a, 3) for a in getattr(learner, "lag_agreement", [])],
            "reaction": PEOPLE[model](seed=seed).style.reaction,
            "worlds": scores,
            **({"bare": score(policy, worlds, model, seed=seed)} if guard and bare else {}),
            "wall_time": round(time.perf_counter() - t0, 1)}


def person_row(model: str, seeds, worlds) -> dict:
    """The person driving alone, judged by ``lab.evaluate``'s rule (the scripted teacher's
    distance) in each world."""
    from lab.behaviours import get
    from lab.practice import teacher_episode

    out = {}
    for name in worlds:
        spec = resolve_world(name)
        seconds = EVAL_SECONDS[task_of(spec)]
        b = get(task_of(spec))
        ok = []
        for seed in seeds:
            for st, own in zip(spec.start_poses, alone(model, seed, name), strict=True):
                tt = teacher_episode(spec, b, DEFAULT_ACTIONS, st, seconds, 0, 0.0, 0.0, DT)
                ok.append(success(task_of(spec), own, tt.metrics(spec.goal)))
        out[name] = float(np.mean(ok))
    return out


def _mean(v):
    return sum(v) / len(v) if v else float("nan")


def _failures(rs: list[dict]) -> str:
    why: dict = {}
    for r in rs:
        for w in r["worlds"].values():
            for k, n in w.get("failed", {}).items():
                why[k] = why.get(k, 0) + n
    return ", ".join(f"{n} {k}" for k, n in sorted(why.items(), key=lambda kv: -kv[1])) or "-"


def table(rows: list[dict], taught: str, unseen) -> str:
    """Per model and method: means over seeds (min over seeds in brackets)."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["model"], r["method"] + (f" +{r['guard']}" if r["guard"] else "")),
                          []).append(r)
    lines = ["| model | method | seeds | taught world | unseen worlds | at the person's pace: "
             "taught / unseen | loops | collisions | nodes | labels | corrections | wrong keys "
             "| lag (scans) | failed episodes |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def cell(rs, key, worlds):
        if not worlds:
            return float("nan"), float("nan")
        v = [_mean([r["worlds"][w][key] for w in worlds]) for r in rs]
        return 100 * _mean(v), 100 * min(v)

    for (model, method), rs in groups.items():
        ts, tmin = cell(rs, "success", [taught])
        us, umin = cell(rs, "success", unseen)
        tp, _ = cell(rs, "pace", [taught])
        up, _ = cell(rs, "pace", unseen)
        loops = sum(w["loops"] for r in rs for w in r["worlds"].values())
        coll = sum(w["collisions"] for r in rs for w in r["worlds"].values())
        lines.append(
            f"| {model} | {method} | {len(rs)} | {ts:.0f}% ({tmin:.0f}) | {us:.0f}% ({umin:.0f}) "
            f"| {tp:.0f}% / {up:.0f}% | {loops} | {coll} | {_mean([r['nodes'] for r in rs]):.0f} "
            f"| {_mean([r['labels'] for r in rs]):.0f} | "
            f"{_mean([r['corrections'] for r in rs]):.0f} | "
            f"{100 * _mean([r['wrong'] / max(1, r['labels']) for r in rs]):.0f}% | "
            f"{'/'.join(str(r['lag']) for r in rs)} | {_failures(rs)} |")
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default=",".join(DEV),
                    help=f"person models (dev: {', '.join(DEV)}; held out: {', '.join(HELD_OUT)}; "
                         f"fresh: {', '.join(FRESH)})")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per model (0..N-1)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--methods", default="today,literal,person",
                    help=f"learning methods ({', '.join(METHODS)}; options after a colon: "
                         "person:lag=2+k=25)")
    ap.add_argument("--task", choices=sorted(DEFAULT_WORLDS), default="wall-following",
                    help="the default --worlds: the room and the unseen rooms, or the tiered "
                         "maze and the unseen mazes")
    ap.add_argument("--worlds", default=None,
                    help="worlds to evaluate in (the first is the one taught in; default: "
                         "--task's)")
    ap.add_argument("--demo", type=float, default=240.0, help="s of demonstrating")
    ap.add_argument("--correct", type=float, default=120.0, help="s of correcting")
    ap.add_argument("--latency", type=float, default=0.03, help="s the page is behind the world")
    ap.add_argument("--restart-demo", type=float, default=0.0, metavar="S",
                    help="demonstrating: put the robot at the next start pose every S s (0: never)")
    ap.add_argument("--restart-correct", type=float, default=0.0, metavar="S",
                    help="correcting: put the robot at the next start pose every S s (0: never)")
    ap.add_argument("--where", choices=["starts", "free", "near"], default="starts",
                    help="--restart-*: at the world's next start pose, anywhere in the free "
                         "space with any heading (as a person dragging the robot about), or "
                         "dragged a little off where it is and turned ('near')")
    ap.add_argument("--guard", action="store_true",
                    help="the controller (and the evaluation) drive the tree through "
                         "client.behaviour.guard.RotationGuard")
    ap.add_argument("--clearance", type=float, default=PERSON.guard.clearance, metavar="M",
                    help="with --guard: its path check (RotationGuard(clearance=M)): a forward "
                         "order with a laser return within 0.5 m ahead and M m of the centre "
                         f"line becomes a rotation in place (default {PERSON.guard.clearance:g}, as rhbl "
                         "controller; 0: off)")
    ap.add_argument("--guard-straight", action=argparse.BooleanOptionalAction, default=True,
                    help="with --guard and a clearance: an overruled reversal drives straight "
                         "on while the path is clear (RotationGuard(straight=...), as rhbl "
                         "controller; --no-guard-straight: the robot keeps turning)")
    ap.add_argument("--bare", action="store_true",
                    help="with --guard: also evaluate the tree alone (no guard, as rhbl "
                         "evaluate and rhbl experiment judge it) and print its table too")
    ap.add_argument("--alone", action="store_true",
                    help="also print how each person model does driving by itself")
    ap.add_argument("--json", default=None, help="write every run here")
    return ap


def _print_tables(rows: list[dict], args, models: list[str], seeds, worlds: list[str]) -> None:
    """The table of the sessions (and, as asked, of the tree alone and of each person alone)."""
    print()
    print(table(rows, worlds[0], worlds[1:]))
    if args.bare and args.guard:
        print()
        print(table([dict(r, worlds=r["bare"], guard="tree alone, no guard") for r in rows],
                    worlds[0], worlds[1:]))
    if args.alone:
        print()
        print("| person alone (lab.evaluate's rule) | " + " | ".join(worlds) + " |")
        print("|---|" + "---|" * len(worlds))
        for model in models:
            row = person_row(model, seeds, worlds)
            print(f"| {model} | " + " | ".join(f"{100 * row[w]:.0f}%" for w in worlds) + " |")


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    models = [m for m in args.models.split(",") if m]
    for m in models:
        if m not in PEOPLE:
            ap.error(f"unknown model {m!r}; known: {', '.join(PEOPLE)}")
    methods = [m for m in args.methods.split(",") if m]
    for m in methods:
        try:
            make_method(m)
        except (ValueError, TypeError) as exc:
            ap.error(str(exc))
    worlds = [w for w in (args.worlds or ",".join(DEFAULT_WORLDS[args.task])).split(",") if w]
    if not worlds:
        ap.error("--worlds: no world given")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = []
    for method in methods:
        for model in models:
            for seed in seeds:
                r = run_one(model, seed, method, worlds, demo=args.demo, correct=args.correct,
                            latency=args.latency, guard=args.guard,
                            restarts=(args.restart_demo, args.restart_correct),
                            where=args.where, clearance=args.clearance,
                            straight=args.guard_straight, bare=args.bare)
                rows.append(r)
                print(f"{method:>12} {model:>12} seed {seed}: "
                      + " ".join(f"{w} {100 * s['success']:.0f}%/{s['loops']}L"
                                 for w, s in r["worlds"].items())
                      + f" | lag {r['lag']} (reaction {r['reaction']:.2f} s)"
                      + (f" | goal {r['goals']}x while teaching" if r["goals"] else "")
                      + f" | {r['nodes']} nodes, {r['labels']} labels ({r['corrections']} "
                        f"corrections, {r['takeovers']} takeovers), {r['wrong']} wrong, "
                        f"{r['wall_time']} s", flush=True)
    _print_tables(rows, args, models, seeds, worlds)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
