"""The demo's run: its scenarios (one per task, from the training recipe) and the loop as
separate OS processes (``Demo``), which ``rhbl demo`` (``lab.demo``) starts; ``lab.by_hand``
is the same run with a person teaching."""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from client.behaviour.given import as_argument, rule_words
from client.behaviour.spec import Behaviour
from client.behaviour.tasks import TASKS
from lab import children
from lab.behaviours import get, recipe_of, world_of
from lab.children import free_port
from lab.children import rhbl_argv as _rhbl
from lab.episode import Episode, EpisodeCollector
from lab.goals import targets
from lab.metrics import goals_in_order, judge
from lab.recipe import EVAL_SECONDS, RECIPES, Recipe
from process import files

__all__ = ["SCENARIOS", "Child", "Demo", "DemoError", "Scenario", "demo_behaviour",
           "scenario_of"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Scenario:
    """What ``rhbl demo --scenario TASK`` runs, derived from the task's training recipe
    (``Recipe.for_demo``): each start pose demonstrates ``recipe.segment`` sim seconds, then
    ``recipe.rounds`` corrective rounds of ``recipe.round_seconds`` per start pose, then the
    final tree drives ``drive`` seconds (``EVAL_SECONDS``) from each; each phase ends early at
    the goal."""

    recipe: Recipe
    drive: float
    behaviour: Behaviour | None = None  # its expert, perception and rule (None: the task's)

    @property
    def task(self) -> str:
        return self.recipe.task

    @property
    def world(self) -> str:
        return self.recipe.world

    @property
    def policy(self) -> str:
        if self.behaviour is not None:
            return self.behaviour.expert_name
        return TASKS[self.recipe.task].teacher

    def _expert(self) -> list[str]:
        """The teacher's expert: the behaviour's (its file's parameters), else the task's."""
        if self.behaviour is not None:
            return ["--behaviour", as_argument(self.behaviour)]
        return ["--policy", self.policy]

    def replace(self, teach: float | None = None, rounds: int | None = None,
                round_seconds: float | None = None, drive: float | None = None) -> Scenario:
        """This scenario with the phase lengths given (None: unchanged)."""
        changes = {k: v for k, v in (("segment", teach), ("rounds", rounds),
                                     ("round_seconds", round_seconds)) if v is not None}
        return Scenario(self.recipe.replace(**changes), self.drive if drive is None else drive,
                        self.behaviour)

    def learner_args(self) -> list[str]:
        """``rhbl learner`` options that make its tree the recipe's (task, features, tree)."""
        r = self.recipe
        if (self.behaviour is None and not isinstance(r.features, str)) or any(
                getattr(r, k) is not None for k in ("distance", "min_radius", "max_depth")):
            raise ValueError(f"{r.task}'s recipe: rhbl learner takes a named feature spec (or "
                             "a behaviour's) and no distance, min_radius or max_depth option")
        perception = (["--behaviour", as_argument(self.behaviour)] if self.behaviour is not None
                      else ["--task", r.task, "--features", r.features])
        args = [*perception, "--spawn", r.spawn,
                "--stride", str(r.stride), "--min-delta", f"{r.min_delta:g}"]
        return args + (["--max-nodes", str(r.max_nodes)] if r.max_nodes is not None else [])

    def teacher_args(self, style: str, seed: int) -> list[str]:
        """``rhbl teacher`` options of the demonstrations."""
        return [*self._expert(), "--style", style, "--seed", str(seed),
                "--perturb", f"{self.recipe.perturb:g}"]

    def corrector_args(self, style: str) -> list[str]:
        """``rhbl teacher --correct`` options of the corrective rounds."""
        return [*self._expert(), "--style", style, "--correct",
                "--takeover", f"{self.recipe.takeover:g}"]


# scenario -> the task's recipe with the demo's changes (lab.recipe.DEMO, the time budget);
# the demo cannot run rounds in scaled copies or from free-space poses (one server serves one
# world, the demo teleports only to its start poses): those parts of the recipe are left out;
# the demo has no compaction step either (the learner process keeps no vectors)
SCENARIOS: dict[str, Scenario] = {
    task: Scenario(recipe.for_demo(), EVAL_SECONDS[task]) for task, recipe in RECIPES.items()}


def scenario_of(b: Behaviour) -> Scenario:
    """What ``rhbl demo --behaviour B`` runs: the behaviour's recipe (``lab.behaviours.
    recipe_of``) with the demo's changes, its final drives as long as its ``time-limit``; its
    expert teaches, its perception is the learner's, its rule judges the final tree. A shipped
    behaviour of a task runs what ``--scenario TASK`` ran (the same recipe, the same lengths)."""
    return Scenario(recipe_of(b).for_demo(), b.seconds, b)


# goals in order (docs/goals.md): the paper's own example, the red beacon and then the green one
SCENARIOS["goals"] = scenario_of(get("red-green"))
GOALS_GRACE = 3.0  # sim s an episode goes on after its last goal was reached (the last mark)



def demo_behaviour(args: argparse.Namespace) -> Behaviour:
    """The behaviour a demo runs: ``--behaviour`` (a name or a file), else ``--scenario``'s (a
    task is the shipped behaviour of its name), else wall following; ValueError for both."""
    if args.behaviour is not None and args.scenario is not None:
        raise ValueError(f"--scenario {args.scenario} and --behaviour {args.behaviour}: give "
                         "one (a scenario is the shipped behaviour of its name)")
    scenario = SCENARIOS.get(args.scenario)
    if scenario is not None and scenario.behaviour is not None:
        return scenario.behaviour
    return get(args.behaviour or args.scenario or "wall-following")


def _over(teacher_m: dict, m: dict) -> dict | None:
    """The teacher's metrics with its distance over the length of the episode ``m`` (at the
    pace of its demonstration), for ``distance``'s ``of_teacher``; None when it has no length."""
    if not teacher_m.get("seconds"):
        return None
    return {**teacher_m, "distance": teacher_m["distance"] * m["seconds"] / teacher_m["seconds"]}


# ---- children ------------------------------------------------------------------------------
class DemoError(Exception):
    pass


class Child(children.Child):
    """One child process, logging into the output folder; stopped with SIGINT first (the
    learner then writes its final snapshot), SIGTERM and SIGKILL by PID if it does not end; and
    sent SIGTERM by the system when the demo dies, even killed (``die_with_parent``)."""

    def __init__(self, name: str, argv: list[str], logdir: Path) -> None:
        super().__init__(name, argv, logdir, stop_signal=signal.SIGINT, die_with_parent=True)


# ---- the demo ------------------------------------------------------------------------------
class Demo:
    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.behaviour = demo_behaviour(args)
        self.name = self.behaviour.name  # the scenario's name: a task's, or the behaviour's
        self.scenario = scenario_of(self.behaviour).replace(
            teach=args.teach_seconds, rounds=args.rounds, round_seconds=args.round_seconds,
            drive=args.drive_seconds)
        self.scenario.learner_args()  # a recipe the learner process cannot run: refused now
        # the world with the behaviour's own start poses for it
        self.spec = world_of(self.behaviour, args.world or self.scenario.world)
        # goals in order: the beacons to reach, in order (the judge's view, lab.goals.targets)
        self.targets = None if self.behaviour.goals is None else targets(self.spec,
                                                                         self.behaviour)
        # a tree with goals pursues them from the first again at each start pose it is put at
        self.again = [] if self.targets is None else ["--goals-again"]
        stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        self.out = Path(args.out or Path("rhbl-out") / f"{stamp}-{self.name}")
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "logs").mkdir(exist_ok=True)
        self.port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.children: list[Child] = []
        self.failures: list[str] = []
        self.t0 = time.monotonic()
        self.tree = self.out / "tree.rhbl"
        self.teach = self.scenario.recipe.segment
        self.drive = self.scenario.drive
        self.rounds = self.scenario.recipe.rounds
        self.round_seconds = self.scenario.recipe.round_seconds
        self.recording: Path | None = None  # --record: the recording's file

    # -- helpers --
    def say(self, msg: str) -> None:
        if not self.args.quiet:
            print(f"[{time.monotonic() - self.t0:6.1f}s] {msg}", flush=True)

    def child(self, name: str, *args: str) -> Child:
        """``rhbl ARGS...`` connected to the rendezvous, logging into logs/<name>.log, its
        counters at exit in logs/<name>.json (``--stats``)."""
        stats = self.out / "logs" / f"{name}.json"
        c = Child(name, _rhbl(*args, "--connect", self.endpoint, "--stats", str(stats)),
                  self.out / "logs").start()
        self.children.append(c)
        return c

    def deadline_check(self) -> None:
        if time.monotonic() - self.t0 > self.args.timeout:
            raise DemoError(f"the demo took longer than --timeout {self.args.timeout:g} s")

    def check_alive(self, *cs: Child) -> None:
        for c in cs:
            if c.poll() is not None and not c.expected_stop:
                raise DemoError(f"{c.name} (pid {c.pid}) exited early with status {c.rc}:\n"
                                f"{c.tail()}")

    def wait_token(self, role: str, child: Child, timeout: float = 30.0) -> None:
        """Until ``child`` declared its liveliness token (its subscriptions are in place)."""
        from protocol import keys

        key = keys.alive_key(role, f"r0-{child.pid}")
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.check_alive(child)
            if any(r.ok is not None for r in self.session.liveliness().get(key, timeout=1.0)):
                return
            time.sleep(0.05)
        raise DemoError(f"{child.name} (pid {child.pid}) did not come up within {timeout:g} s:\n"
                        f"{child.tail()}")

    def start_console(self) -> Child:
        """``rhbl console --view-only`` beside the others; prints the URL it serves."""
        c = self.child("console", "console", "--view-only", "--http", self.args.console)
        if c.wait_for_line("console: ", timeout=30.0):
            url = next(ln.split(" ", 1)[1] for ln in c.lines if ln.startswith("console: "))
            print(f"console: {url}  (watch the loop live)", flush=True)
            return c
        self.check_alive(c)
        raise DemoError(f"the console did not start within 30 s:\n{c.tail()}")

    def start_server(self) -> Child:
        """One server for the whole demo, at the world's own start pose."""
        pace = (["--speedup", f"{self.args.speedup:g}"] if self.args.speedup is not None
                else ["--lockstep", "--lockstep-timeout", "0.5"])
        return self.child("server", "server", "--mode", "client", "--world",
                          str(self.spec.path), *pace)

    def wait_commands(self, source: str, *cs: Child, timeout: float = 60.0) -> None:
        """Until a command of ``source`` went through the rendezvous (the process drives)."""
        deadline = time.monotonic() + timeout
        while not self.rec.sources.get(source):
            self.deadline_check()
            self.check_alive(*cs)
            if time.monotonic() > deadline:
                raise DemoError(f"no command from the {source} within {timeout:g} s:\n"
                                f"{cs[-1].tail() if cs else ''}")
            time.sleep(0.05)

    def teleport(self, pose, *cs: Child) -> int:
        """Put the robot at ``pose`` (sim-only set_pose; odometry reset); returns the id of the
        first scan taken there."""
        from client.player import RequestError

        self.check_alive(*cs)
        for attempt in range(3):
            try:
                ack = self.sim.set_pose2d(*pose, reset_odom=True, timeout=5.0)
                return int(ack.extra["scan_id"])
            except RequestError as exc:
                if "NACK" in str(exc) or attempt == 2:
                    raise DemoError(f"cannot put the robot at {tuple(pose)}: {exc}") from exc
        raise AssertionError("unreachable")  # pragma: no cover

    def wait_episode(self, ep: Episode, seconds: float, what: str, *cs: Child,
                     until_exit: Child | None = None) -> None:
        """Until ``seconds`` of sim time were recorded (or ``until_exit`` exits, or the goal)."""
        goal = self.spec.goal
        goals, done_at = self.targets, None
        next_note = time.monotonic() + 2.0  # a line every 2 s, and one when the episode ends
        first_scan_by = time.monotonic() + 20.0
        while True:
            self.deadline_check()
            if until_exit is not None and until_exit.poll() is not None:
                if until_exit.rc != 0:
                    raise DemoError(f"{until_exit.name} failed with status {until_exit.rc}:\n"
                                    f"{until_exit.tail()}")
                return
            self.check_alive(*cs)
            t = ep.sim_time
            if not ep.ts and time.monotonic() > first_scan_by:
                raise DemoError(f"{what}: no scan from the server within 20 s")
            if until_exit is None and t >= seconds:
                self.say(f"{what}: sim {t:5.0f}/{seconds:g} s{self.tree_notice()}")
                return
            if goal is not None and ep.poses and until_exit is None:
                x, y, _ = ep.poses[-1]
                if np.hypot(x - goal.center[0], y - goal.center[1]) <= goal.radius:
                    self.say(f"{what}: goal reached at {t:.0f} s")
                    return
            if goals and ep.poses and until_exit is None and done_at is None and len(
                    goals_in_order(ep.poses, goals, ep.dt)) == len(goals):
                done_at = t  # (judged within the goal's distance plus the rule's slack: the
                # teacher says the last one is reached a little later, nearer; then it ends)
            if done_at is not None and t >= min(done_at + GOALS_GRACE, seconds):
                self.say(f"{what}: every goal reached in order at {done_at:.0f} s")
                return
            if time.monotonic() >= next_note:
                n = self.tree_notice()
                self.say(f"{what}: sim {t:5.0f}/{seconds:g} s{n}")
                next_note = time.monotonic() + 2.0
            time.sleep(0.05)

    def wait_labels(self, *cs: Child, timeout: float = 60.0) -> None:
        """Until a teacher label went through the rendezvous (the teacher labels)."""
        n0 = self.rec.labels
        deadline = time.monotonic() + timeout
        while self.rec.labels <= n0:
            self.deadline_check()
            self.check_alive(*cs)
            if time.monotonic() > deadline:
                raise DemoError(f"no teacher label within {timeout:g} s:\n"
                                f"{cs[-1].tail() if cs else ''}")
            time.sleep(0.05)

    def wait_labels_of(self, ep: Episode, last: int | None, quiet: float = 0.5,
                       timeout: float = 5.0) -> None:
        """Until the teacher's label of scan ``last`` (the episode's last) arrived, or none came
        for ``quiet`` s (a teacher that does not label every scan), at most ``timeout`` s: a
        teacher behind the server labels the episode's last scans after it stopped."""
        if last is None:
            return
        deadline = time.monotonic() + timeout
        seen, since = len(ep.labels), time.monotonic()
        while time.monotonic() < deadline:
            self.tap.sync()
            got = self.rec.last_label_scan
            if got is not None and got >= last:
                return
            if len(ep.labels) != seen:
                seen, since = len(ep.labels), time.monotonic()
            elif time.monotonic() - since >= quiet:
                return
            time.sleep(0.02)

    def episodes(self, kind: str, starts, seconds: float, what: str, *cs: Child,
                 round_: int = 0) -> list[Episode]:
        """One episode from each start pose (teleported there), ``seconds`` or until the goal."""
        out = []
        for k, pose in enumerate(starts):
            self.tap.sync()  # what arrived before belongs to no episode
            ep = self.rec.begin(kind, pose, round_)
            self.rec.trim(ep, self.teleport(pose, *cs))
            self.wait_episode(ep, seconds, f"{what}, start {k + 1}/{len(starts)}", *cs)
            self.tap.sync()  # what arrived until now belongs to it
            self.wait_labels_of(ep, self.rec.stop(ep))
            self.rec.end()
            out.append(ep)
        return out

    def tree_notice(self) -> str:
        n = self.rec.notice
        return (f", tree {n['nodes']} nodes, height {n['height']}, {n['vectors']} vectors"
                if n else "")

    # -- phases --
    def run(self) -> int:
        import zenoh

        from process.session import make_config

        args = self.args
        self.say(f"rhbl demo: scenario {self.name}, world {self.spec.name}, output "
                 f"{self.out}")
        self.say(f"rendezvous (router) on {self.endpoint}; children log into {self.out / 'logs'}")
        from client.behaviour.actions import DEFAULT_ACTIONS
        from client.player import PlayerClient
        from client.recording.record import demo_recording, say_demo_recording
        from client.recording.tap import BusTap

        with zenoh.open(make_config(mode="router", listen=[self.endpoint])) as session:
            self.session = session
            self.sim = PlayerClient(session=session, robot="r0", source="demo").simulation
            # the learner's actions (``rhbl learner`` has no other set)
            self.rec = EpisodeCollector("r0", DEFAULT_ACTIONS, self.behaviour.band_side)
            writer = demo_recording(args.record, self.out, self.say)  # None without --record
            self.recording = None if writer is None else Path(writer.path)
            # a tap each: a recording that falls behind (a loaded machine) never delays what
            # the demo sees of its episodes
            self.tap = BusTap(session, [self.rec], world=False)
            recording = None if writer is None else BusTap(session, [writer], world=True)
            try:
                return self._phases()
            finally:
                self.tap.close()
                if recording is not None:
                    recording.close()
                    say_demo_recording(recording, writer, self.say)

    def _phases(self) -> int:
        args = self.args
        starts = self.spec.start_poses[: args.starts] if args.starts else self.spec.start_poses
        server, learner, demos = self.teach_phase(starts)
        rounds = self.round_phase(starts, server, learner)
        clf, actions, meta = self.final_tree(learner)
        learned = self.drive_phase(starts, server)
        for c in self.children:
            if c.rc not in (0, None) and not (c.expected_stop and c.rc in (-2, 130)):
                raise DemoError(f"{c.name} exited with status {c.rc}:\n{c.tail()}")
        return self.report(clf, actions, meta, demos, rounds, learned)

    def teach_phase(self, starts) -> tuple[Child, Child, list[Episode]]:
        """1. The learner, the server and the teacher, who demonstrates from each start pose;
        (server, learner, the demonstrations)."""
        args, scenario = self.args, self.scenario
        learner = self.child("learner", "learner", *scenario.learner_args(), "--out",
                             str(self.tree), "--wait-server", "60", "--snapshot-every", "0.5")
        self.wait_token("learner", learner)  # no demonstration before the learner listens
        if args.console:
            self.start_console()
        server = self.start_server()
        teacher = self.child("teacher", "teacher", *scenario.teacher_args(args.style, args.seed),
                             "--wait-server", "30")
        self.say(f"teaching: the {args.style} {scenario.policy} teacher demonstrates from each "
                 f"of {len(starts)} start poses, {self.teach:g} s of sim time each (pids: "
                 f"server {server.pid}, learner {learner.pid}, teacher {teacher.pid})")
        self.wait_labels(server, learner, teacher)
        demos = self.episodes("teacher", starts, self.teach, "teaching", server, learner, teacher)
        teacher.stop()
        self.say(f"demonstrations done ({sum(ep.sim_time for ep in demos):.0f} s sim, "
                 f"{sum(len(ep.labels) for ep in demos)} labels){self.tree_notice()}")
        return server, learner, demos

    def round_phase(self, starts, server: Child, learner: Child) -> list[Episode]:
        """2. Corrective rounds: the controller drives the latest tree, the teacher corrects."""
        rounds: list[Episode] = []
        if self.rounds <= 0:
            return rounds
        follower = self.child("controller-follow", "controller", "--from-learner", "--follow",
                              "--wait-server", "60", "--query-timeout", "10", *self.again)
        self.wait_commands("controller", server, learner, follower)
        corrector = self.child("teacher-correct", "teacher",
                               *self.scenario.corrector_args(self.args.style), "--wait-server", "30")
        self.say(f"corrective rounds: the controller drives the learner's latest tree "
                 f"(pid {follower.pid}), the teacher labels every scan and takes over near "
                 f"walls (pid {corrector.pid}); {self.rounds} rounds x {len(starts)} starts, "
                 f"{self.round_seconds:g} s each")
        self.wait_labels(server, learner, follower, corrector)
        for r in range(1, self.rounds + 1):
            eps = self.episodes("round", starts, self.round_seconds, f"round {r}", server,
                                learner, follower, corrector, round_=r)
            rounds.extend(eps)
            self.say(f"round {r} done: {sum(len(ep.ts) for ep in eps)} scans, "
                     f"{sum(len(ep.labels) for ep in eps)} labels, teacher took over "
                     f"{sum(ep.teacher_ticks for ep in eps)} ticks{self.tree_notice()}")
        corrector.stop()
        follower.stop()
        return rounds

    def final_tree(self, learner: Child):
        """The learner stopped (its final snapshot); the tree, its actions and metadata."""
        from client.behaviour.learning import load_snapshot

        self.say("stopping the learner (SIGINT: final snapshot)")
        rc = learner.stop(timeout=30)
        if rc != 0:
            raise DemoError(f"learner exited with status {rc}:\n{learner.tail()}")
        if not self.tree.exists():
            raise DemoError(f"the learner wrote no snapshot at {self.tree}")
        clf, _features, actions, meta = load_snapshot(self.tree)
        prov = meta.get("provenance") or {}
        self.say(f"learned tree: {clf.node_count_} nodes, height {clf.height_}, "
                 f"{prov.get('vectors')} labeled vectors -> {self.tree}")
        return clf, actions, meta

    def drive_phase(self, starts, server: Child) -> list[Episode]:
        """3. The final tree alone from each start pose; then the server stops."""
        controller = self.child("controller", "controller", "--tree", str(self.tree),
                                "--wait-server", "60", *self.again)
        self.wait_commands("controller", server, controller)
        learned = self.episodes("learner", starts, self.drive, "learned robot", server,
                                controller)
        controller.stop()
        server.stop()
        return learned

    def report(self, clf, actions, meta, demos: list[Episode], rounds: list[Episode],
               learned: list[Episode]) -> int:
        """4. The output folder (summary.json, trajectories.npz, paths.png) and the tables."""
        goal, rules = self.spec.goal, self.behaviour.rules
        tms = [ep.metrics(goal, rules, self.targets) for ep in demos]
        lms = [ep.metrics(goal, rules, self.targets) for ep in learned]
        # each final drive by the behaviour's rule, beside the teacher from the same start (its
        # demonstration's distance over the drive's length: the two last different times)
        self.success = [bool(judge(rules, m, _over(tms[k], m) if k < len(tms) else None))
                        for k, m in enumerate(lms)]
        per_round = self.round_rows(rounds)
        wall_time = time.monotonic() - self.t0
        picture = self.write_outputs(clf, meta, demos, rounds, learned, tms, lms, per_round,
                                     wall_time)
        self.print_tables(clf, meta, demos, tms, lms, per_round)
        ok = sum(1 for m in lms if m["collisions"] == 0 and m["goal_reached"] is not False)
        print()
        print(f"learned robot: {ok}/{len(lms)} starts without collision"
              f"{'' if goal is None else ' and reaching the goal'}")
        good = sum(self.success)
        print(f"success by {self.name}'s rule ({rule_words(self.behaviour)}): "
              f"{good}/{len(lms)} starts")
        made = ["tree.rhbl", "tree.rhbl.journal", "paths.png", "summary.json",
                "trajectories.npz", "logs/"]
        if self.recording is not None:  # --record: in the folder, or where it was asked for
            rec = self.recording
            made.insert(-1, rec.name if rec.parent.resolve() == self.out.resolve() else str(rec))
        print(f"output: {self.out}  ({', '.join(made)})")
        print(f"picture: {picture}")
        print(f"wall time {wall_time:.1f} s")
        return 0

    def round_rows(self, rounds: list[Episode]) -> list[dict]:
        """Per corrective round: its episodes, sim seconds, scans, labels, the teacher's
        ticks, collisions and goals reached."""
        goal = self.spec.goal
        out = []
        for r in range(1, self.rounds + 1):
            eps = [ep for ep in rounds if ep.round == r]
            ms = [ep.metrics(goal, targets=self.targets) for ep in eps]
            out.append({
                "round": r, "episodes": len(eps),
                "seconds": round(sum(m["seconds"] for m in ms), 1),
                "scans": sum(len(ep.ts) for ep in eps), "labels": sum(len(ep.labels) for ep in eps),
                "teacher_ticks": sum(ep.teacher_ticks for ep in eps),
                "collisions": sum(m["collisions"] for m in ms),
                "goals": (sum(m["goals_reached"] == m["goals_total"] for m in ms)
                          if self.targets else
                          None if goal is None else sum(bool(m["goal_reached"]) for m in ms))})
        return out

    def write_outputs(self, clf, meta, demos, rounds, learned, tms, lms, per_round,
                      wall_time: float) -> Path:
        """summary.json, trajectories.npz and the picture (its path) in the output folder."""
        from lab.plot import plot_paths

        prov = meta.get("provenance") or {}
        paths = {"teacher": [np.asarray(ep.poses).reshape(-1, 3) for ep in demos]}
        if rounds:
            paths["corrective rounds"] = [np.asarray(ep.poses).reshape(-1, 3) for ep in rounds]
        paths["learner"] = [np.asarray(ep.poses).reshape(-1, 3) for ep in learned]
        picture = plot_paths(
            self.spec, paths, self.out / "paths.png",
            title=f"{self.name}: teacher, corrective rounds and the final tree")
        summary = {
            "scenario": self.name, "task": self.scenario.task, "world": self.spec.name,
            "behaviour": self.behaviour.name,
            "behaviour_file": None if self.behaviour.path is None else str(self.behaviour.path),
            "tree": {"nodes": int(clf.node_count_), "height": int(clf.height_),
                     "task": meta.get("task"), "vectors": prov.get("vectors"),
                     "labeled": prov.get("labeled"), "path": str(self.tree)},
            "teacher": tms, "rounds": per_round, "learned": lms,
            "success": self.success, "rule": rule_words(self.behaviour),
            "demonstration_labels": sum(len(ep.labels) for ep in demos),
            "wall_time": round(wall_time, 1), "teach_seconds": self.teach,
            "rounds_count": self.rounds, "round_seconds": self.round_seconds,
            "drive_seconds": self.drive, "style": self.args.style,
            "processes": self.process_counters(),
        }
        files.write_text(self.out / "summary.json", json.dumps(summary, indent=2, default=str))
        eps = [*demos, *rounds, *learned]
        with files.replace_file(self.out / "trajectories.npz") as tmp, open(tmp, "wb") as out:
            np.savez_compressed(
                out, **{f"{ep.kind}{k}_{f}": np.asarray(getattr(ep, f))
                      for k, ep in enumerate(eps) for f in ("ts", "poses", "side", "ids", "stalls")})
        return picture

    def process_counters(self) -> dict:
        """Each child's counters (its ``--stats``), of those that have written them."""
        out = {}
        for c in self.children:
            stats = self.out / "logs" / f"{c.name}.json"
            if stats.exists():
                out[c.name] = json.loads(stats.read_text())
        return out

    def print_tables(self, clf, meta, demos, tms, lms, per_round) -> None:
        """Table I, the corrective rounds and what the robots did."""
        from lab.metrics import BAND

        band = self.behaviour.rules.get("wall-band") or {}
        side = band.get("side", "right")
        near, far = band.get("near", BAND[0]), band.get("far", BAND[1])
        from lab.report import episode_table, table

        prov = meta.get("provenance") or {}
        demo_labels = sum(len(ep.labels) for ep in demos)
        print()
        print(table(["scenario", "nodes", "tree height", "demonstration vectors"],
                    [[self.name, clf.node_count_, clf.height_, prov.get("vectors")]],
                    title=f"Table I (paper) -- {self.name}, learned over zenoh by "
                          "separate processes",
                    notes=[f"(labeled vectors: {demo_labels} demonstrated from {len(demos)} start "
                           f"poses + {prov.get('vectors', 0) - demo_labels} labeled in "
                           f"{self.rounds} corrective rounds)"]))
        if per_round:
            print()
            rows = [[pr["round"], f"{pr['seconds']:.0f}", pr["scans"], pr["labels"],
                     f"{pr['teacher_ticks']} ticks", pr["collisions"],
                     "-" if pr["goals"] is None else f"{pr['goals']}/{pr['episodes']}"]
                    for pr in per_round]
            print(table(["round", "sim seconds", "scans", "labels", "teacher drove", "collisions",
                         "goal"], rows,
                        title="Corrective rounds (the controller drives the latest tree; the "
                              "teacher labels every scan and takes over while a beam is closer "
                              f"than {self.scenario.recipe.takeover:g} m)"))
        print()
        print(episode_table([("teacher", m) for m in tms] + [("learned", m) for m in lms],
                            title="What the robots did (sim seconds per episode; band = time "
                                  f"with the {side}-hand wall within {near:g}-{far:g} m)"))

    def cleanup(self) -> None:
        for c in reversed(self.children):
            if c.poll() is None:
                c.stop(timeout=5)
