"""Closed-loop episodes at scale: one picklable task per episode, run in this process, on every
core of this machine (a process pool) or on a Dask cluster (``distributed``, the optional
``cluster`` extra). ``rhbl evaluate`` and ``rhbl refine`` run their episodes here.

    task = EpisodeTask("wall-following", "room", tree_bytes, start=(3, 0.7, 0), seed=0)
    result = run_episode(task)     # {"success", "metrics", "teacher", ...}: evaluate's judge
    with Runner(workers=None, cluster=None) as runner:   # None: a process per core
        results = runner.map(tasks)                      # in the order of the tasks
    results = run_episodes(tasks, cluster="tcp://10.0.0.5:8786")  # an existing Dask scheduler

An episode is a function of its task alone: the world is made from the task's seed, the tree
from its bytes, and nothing of the process it runs in is read (the scripted expert's episode,
which the success rule compares with, is the same wherever it is computed). So the results are
the same run serially, on the pool or on a cluster, in any order. A worker that dies loses no
result: the pool is made again and the tasks that had not come back run again (at most
``retries`` times); a Dask scheduler reruns the tasks of a lost worker on another one (its
``allowed-failures``, 3 by default).

Dask (not Ray) because it is pure Python, a pip install of a few small packages, and its
``LocalCluster`` starts in a test in about a second; ``dask scheduler`` / ``dask worker
ADDRESS`` on other machines make the cluster a user gives with ``--cluster`` (each worker needs
rhbl installed, the same version).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import functools
import hashlib
import logging
import multiprocessing
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from client.behaviour.goals import GoalPolicy
from client.behaviour.learning import TreePolicy, check_compatible
from client.behaviour.spec import Behaviour
from lab import metrics
from lab.harness import DT, OnStep, drive, recorded
from process import arguments
from server.world import WorldSpec

__all__ = ["PRACTICE_SEED", "EpisodeTask", "Runner", "add_arguments", "cluster_address", "cores",
           "judged_episode", "practice_tasks", "teacher_episode", "run_episode", "run_episodes",
           "runner_from_args", "tree_bytes"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EpisodeTask:
    """One closed-loop episode: ``behaviour`` (a shipped behaviour's name or a behaviour file)
    judges it in ``world`` (a name or a file, with the behaviour's start poses), the tree
    (snapshot bytes, its features and actions in its metadata) drives from ``start`` for
    ``seconds`` (None: the behaviour's time limit) with ``seed``; ``guard``: the controller's
    guard's settings (``client.behaviour.guard.RotationGuard`` keywords), None: the tree alone.
    ``trace``: also return the winning sphere, the features, the action and the followed
    wall's distance of every step (refinement's credit assignment)."""

    behaviour: str
    world: str
    tree: bytes = field(repr=False)
    start: tuple[float, float, float]
    seed: int = 0
    seconds: float | None = None
    range_noise: float = 0.0
    odom_noise: float = 0.0
    guard: tuple | None = None  # ((keyword, value), ...): hashable
    trace: bool = False
    scale: float = 1.0  # the world scaled by this (``WorldSpec.scaled``; the start as given)

    @property
    def tree_hash(self) -> str:
        return hashlib.sha256(self.tree).hexdigest()


def tree_bytes(policy) -> bytes:
    """A TreePolicy's tree as snapshot bytes, with its features and actions (what a task
    carries)."""
    clf = policy.classifier
    meta = {**(clf.metadata or {}), **(policy.metadata or {})}
    meta["features"], meta["actions"] = policy.features.to_dict(), policy.actions.to_dict()
    saved = clf.metadata
    clf.metadata = dict(saved or {})
    try:
        return clf.to_bytes(meta)
    finally:
        clf.metadata = saved


# -------------------------------------------------------------------------- one episode

_POLICIES: OrderedDict = OrderedDict()  # tree hash -> TreePolicy (this process's last few)


def _policy(task: EpisodeTask):
    from client.behaviour.actions import ActionSet
    from client.behaviour.features import FeatureSpec
    from rhbl import loads

    key = task.tree_hash
    hit = _POLICIES.get(key)
    if hit is None:
        clf = loads(task.tree, source="<episode task's tree>")
        meta = dict(clf.metadata or {})
        check_compatible(meta)
        if isinstance(meta.get("goals"), dict):  # a tree with goals in order (lab.goals)
            hit = _TracedGoals.from_classifier(clf, "<episode task's tree>")
        else:
            hit = _Traced(clf, FeatureSpec.from_dict(meta["features"]),
                          ActionSet.from_dict(meta["actions"]), meta)
        _POLICIES[key] = hit
        while len(_POLICIES) > 8:
            _POLICIES.popitem(last=False)
    _POLICIES.move_to_end(key)
    return hit


@functools.cache
def _behaviour(name: str):
    from lab.behaviours import get

    return get(name)


DRAWN = "drawn"  # a task's world drawn at random: ``drawn:<kind>:<seed>:<i>:<side>``
PRACTICE_SEED = 500  # the drawn practice worlds' (training runs draw with their own seeds)


def drawn_name(kind: str, seed: int, i: int, side: str = "right") -> str:
    """The name a task gives the ``i``-th world ``lab.generated.generated(kind, ., seed,
    side)`` draws: each worker draws it again (the same world for the same name)."""
    return f"{DRAWN}:{kind}:{int(seed)}:{int(i)}:{side}"


@functools.cache
def task_world(behaviour: str, world: str, scale: float = 1.0):
    """The world a task names (a behaviour's world, a file, or ``drawn_name``'s), scaled by
    ``scale``; made once per process."""
    from lab.behaviours import world_of

    if world.startswith(DRAWN + ":"):
        from lab.generated import generated

        _, kind, seed, i, side = world.split(":")
        spec = generated(kind, int(i) + 1, int(seed), side)[int(i)]
    else:
        spec = world_of(_behaviour(behaviour), world)
    return spec if scale == 1.0 else spec.scaled(scale)


def practice_tasks(b, seeds, scales, seconds=None, free: int = 0, noise=(0.0, 0.0),
                   drawn: tuple[str, int] | None = None, drawn_seed: int = PRACTICE_SEED,
                   teach: bool = True, first: int = 0) -> list[EpisodeTask]:
    """``rhbl refine``'s practice set, the tree left out (``b``: a ``Behaviour``): every start
    pose of each teaching world (``teach``), as it is and scaled by each of ``scales``, and
    ``free`` poses in its free space (``server.world.free_pose``, drawn with
    seed 100 + the scale's place: not the poses the tree was taught from), each with every
    seed; ``drawn`` = (kind, count): also every start pose of ``count`` worlds
    ``lab.generated`` draws of that kind (with ``drawn_seed``: ``PRACTICE_SEED``, not a
    training run's seed), as they are, from the ``first``-th."""
    from server.world import free_pose

    name = str(b.path) if b.path else b.name
    worlds = [(w, scale) for w in (b.teach if teach else ()) for scale in (1.0, *scales)]
    if drawn is not None and drawn[1] > 0:
        worlds += [(drawn_name(drawn[0], drawn_seed, i, b.band_side or "right"), 1.0)
                   for i in range(first, first + drawn[1])]
    out = []
    for j, (w, scale) in enumerate(worlds):
        spec = task_world(name, w, float(scale))
        rng = np.random.default_rng(100 + (j % (1 + len(scales))))  # 100 + the scale's place
        poses = list(spec.start_poses)
        poses += [tuple(p) for p in (free_pose(spec, rng) for _ in range(free)) if p]
        for k, start in enumerate(poses):
            for seed in seeds:
                out.append(EpisodeTask(name, w, b"", tuple(float(v) for v in start),
                                       seed=seed * 1000 + k, seconds=seconds,
                                       range_noise=noise[0], odom_noise=noise[1],
                                       trace=True, scale=float(scale)))
    return out


class _Tracing:
    """Notes the winning sphere of the action tree and the features of every answer
    (``tracing`` on), the same answers as the policy's own (``TreePolicy``, ``GoalPolicy``)."""

    tracing = False
    winners: list = []
    states: list = []

    def reset(self) -> None:
        super().reset()
        self.winners, self.states = [], []
        self.names = [str(v) for v in self.classifier.classes_]

    def act(self, ranges, pose) -> str:
        if not self.tracing:
            return super().act(ranges, pose)
        yaw = float(pose[2]) if pose is not None else 0.0
        x = np.asarray(self.vector(ranges, yaw), dtype=np.float64)
        clf = self.classifier
        node = clf.tree_.apply_one(np.array(x))
        self.winners.append(node)  # -1: outside the unit cube (no sphere decided)
        self.states.append(x)
        if node < 0:  # the classifier's checks say why
            return str(clf.predict_one(x))
        return self.names[int(clf.tree_.label[node])]


class _Traced(_Tracing, TreePolicy):
    pass


class _TracedGoals(_Tracing, GoalPolicy):
    pass


_TEACHER_CACHE: dict = {}


def teacher_episode(spec: WorldSpec, b: Behaviour, actions, start, seconds: float, seed: int,
                     range_noise: float, odom_noise: float, dt: float,
                     on_step: OnStep | None = None):
    """The behaviour's scripted expert's episode from ``start``. Without noise it does not
    depend on the seed (and not on the tree), so it is computed once per world, expert, start
    and length."""
    key = None
    if range_noise == 0.0 and odom_noise == 0.0:
        key = (spec.name, str(spec.path), spec.walls, spec.goal, tuple(start), seconds, dt,
               tuple(actions.names), b.expert_name, repr(sorted(b.expert_params.items())),
               tuple(recorded(b).items()))
        hit = _TEACHER_CACHE.get(key)
        if hit is not None:
            return hit
    tt = drive(spec, b.expert(actions=actions), start, seconds, seed=seed,
               range_noise=range_noise, odom_noise=odom_noise, dt=dt, kind="teacher",
               on_step=on_step, behaviour=b)
    if key is not None:
        if len(_TEACHER_CACHE) > 256:
            _TEACHER_CACHE.clear()
        _TEACHER_CACHE[key] = tt
    return tt


def judged_episode(spec: WorldSpec, b: Behaviour, policy, start, seconds: float, seed: int,
                   range_noise: float = 0.0, odom_noise: float = 0.0, dt: float = DT,
                   on_step: OnStep | None = None, both: bool = False):
    """One start judged: the behaviour's scripted expert and ``policy`` drive from ``start``
    with ``seed``, each judged by the behaviour's success rule (the policy's distance compared
    with the expert's): ``(learner metrics, expert metrics, learner episode)``, with ``both``
    the expert's episode too. The one place an episode is judged (``rhbl evaluate``, and here
    ``run_episode`` on a pool or a cluster). A behaviour with goals in order is judged by
    ``lab.goals.judged_goal_episode`` (no noise, the default step)."""
    if b.goals is not None:
        if range_noise or odom_noise or dt != DT or on_step is not None:
            raise ValueError(f"behaviour {b.name!r} has goals in order: its episodes are "
                             "driven without noise, at the default step, here")
        from lab.goals import judged_goal_episode

        lm, tm, lt, tt = judged_goal_episode(spec, b, policy, start, seconds, seed)
        return (lm, tm, lt, tt) if both else (lm, tm, lt)
    tt = teacher_episode(spec, b, policy.actions, start, seconds, seed, range_noise,
                          odom_noise, dt, on_step)
    tm = tt.metrics(spec.goal, b.rules)
    tm["success"] = metrics.judge(b.rules, tm, None)
    lt = drive(spec, policy, start, seconds, seed=seed, teacher=b.expert(actions=policy.actions),
               range_noise=range_noise, odom_noise=odom_noise, dt=dt, kind="learner",
               on_step=on_step, behaviour=b)
    lm = lt.metrics(spec.goal, b.rules)
    lm["success"] = metrics.judge(b.rules, lm, tm)
    return (lm, tm, lt, tt) if both else (lm, tm, lt)


def run_episode(task: EpisodeTask) -> dict:
    """One episode judged as ``rhbl evaluate`` judges it (``judged_episode``):
    ``{"success", "metrics", "teacher", "steps", "stalls"}`` (``stalls``: the steps a collision
    began), with ``trace``: ``"winners"`` (the sphere that decided each step), ``"states"``
    (its features, float32), ``"actions"``, ``"side"`` (the followed wall's distance) and
    ``"poses"`` (the true pose after each step, float32)."""
    from client.behaviour.guard import RotationGuard

    b = _behaviour(task.behaviour)
    spec = task_world(task.behaviour, task.world, float(task.scale))
    policy = _policy(task)
    policy.tracing = task.trace
    driver = policy if task.guard is None else RotationGuard(policy, **dict(task.guard))
    seconds = b.seconds if task.seconds is None else float(task.seconds)
    lm, tm, ep = judged_episode(spec, b, driver, tuple(task.start), seconds, task.seed,
                                task.range_noise, task.odom_noise)
    out = {"success": bool(lm["success"]), "metrics": lm, "teacher": tm, "steps": len(ep.poses),
           "stalls": [i for i, s in enumerate(ep.stalls) if s and (i == 0 or not ep.stalls[i - 1])]}
    if task.trace:
        out["winners"] = np.asarray(policy.winners, dtype=np.int32)
        out["states"] = np.asarray(policy.states, dtype=np.float32)
        out["actions"] = list(ep.actions)
        out["side"] = np.asarray(ep.side, dtype=np.float32) if ep.side else None
        out["poses"] = np.asarray([tuple(q)[:3] for q in ep.poses], dtype=np.float32)
    if task.guard is not None:
        out["guard"] = {k: getattr(driver, k) for k in ("overruled", "avoided", "straight_on")}
    policy.tracing = False
    return out


# -------------------------------------------------------------------------- many episodes


def judged_on(runner, b: Behaviour, spec: WorldSpec, policy, starts, seed: int,
              seconds: float | None, range_noise: float = 0.0, odom_noise: float = 0.0
              ) -> tuple[list, list]:
    """``policy`` (a tree, a tree with goals, either through the controller's guard) judged
    from each of ``starts`` (episode ``k`` with seed ``seed * 1000 + k``) on ``runner``, as
    ``judged_episode`` judges it here: (the learner's metrics, the expert's), in order. What the
    guard overruled is added to its counters."""
    inner = getattr(policy, "policy", None) or policy  # a guard drives ``.policy``
    held = None if inner is policy else tuple(
        (k, getattr(policy, k)) for k in ("hold", "memory", "clearance", "lookahead",
                                          "straight"))
    data, where = tree_bytes(inner), str(spec.path) if spec.path is not None else spec.name
    tasks = [EpisodeTask(str(b.path) if b.path else b.name, where, data, tuple(start),
                         seed * 1000 + k, seconds, range_noise, odom_noise, held)
             for k, start in enumerate(starts)]
    learner, teacher = [], []
    for r in runner.map(tasks):
        learner.append(r["metrics"])
        teacher.append(r["teacher"])
        for k, v in (r.get("guard") or {}).items():  # what the guard overruled, summed
            setattr(policy, k, getattr(policy, k) + v)
    return learner, teacher


def cores() -> int:
    """The cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity else (os.cpu_count() or 1)


def _orphan_watch(owner: int, every: float = 0.5) -> None:
    """A pool worker's initializer: it ends itself once ``owner`` (the process whose Runner
    made the pool) is gone, so a command killed (even by SIGKILL) leaves no workers running
    episodes for nobody (the pool's forkserver then ends with them)."""
    from lab.children import running

    def watch() -> None:
        while running(owner):
            time.sleep(every)
        os._exit(0)

    threading.Thread(target=watch, name="orphan-watch", daemon=True).start()


class Runner:
    """Runs episode tasks: ``cluster`` (a Dask scheduler's address) on that cluster; else on
    ``workers`` processes of this machine (None: one per core; 1: in this process). Keep one
    for many ``map`` calls (the pool's processes or the cluster's connection stay)."""

    def __init__(self, workers: int | None = None, cluster: str | None = None,
                 retries: int = 3):
        if workers is not None and workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.cluster = cluster
        self.workers = cores() if workers is None else int(workers)
        self.retries = retries
        self.episodes = 0  # tasks run so far
        self.rerun = 0  # tasks run again after their worker died (the pool)
        self._pool: cf.ProcessPoolExecutor | None = None
        self._client = None
        if cluster is not None:
            try:
                from distributed import Client
            except ImportError:
                raise ValueError("--cluster needs Dask's distributed (pip install "
                                 "'rhbl[cluster]')") from None
            try:
                self._client = Client(cluster, timeout="10s", set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise ValueError(f"--cluster {cluster}: cannot reach a Dask scheduler "
                                 f"there ({exc})") from None

    def describe(self) -> str:
        if self._client is not None:
            n = len(self._client.scheduler_info(n_workers=-1).get("workers", {}))
            return f"the Dask cluster at {self.cluster} ({n} workers)"
        return "this process" if self.workers == 1 else f"{self.workers} processes"

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        ctx = multiprocessing.get_context("forkserver")
        return cf.ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_orphan_watch,
                                      initargs=(os.getpid(),))

    def worker_pids(self) -> list[int]:
        """The process ids of the pool's workers (none before the first ``map``)."""
        pool = self._pool
        return [] if pool is None else sorted(pool._processes or {})

    def map(self, tasks: list[EpisodeTask]) -> list[dict]:
        """Every task's result, in the order of ``tasks``."""
        tasks = list(tasks)
        self.episodes += len(tasks)
        if not tasks:
            return []
        if self._client is not None:
            futures = self._client.map(run_episode, tasks, pure=False)
            return self._client.gather(futures)
        if self.workers == 1 or len(tasks) == 1:
            return [run_episode(t) for t in tasks]
        return self._on_pool(tasks)

    def _on_pool(self, tasks: list[EpisodeTask]) -> list[dict]:
        results: list = [None] * len(tasks)
        todo = list(range(len(tasks)))
        for attempt in range(self.retries + 1):
            futures = self._submit(tasks, todo)
            lost = []
            for fut in cf.as_completed(futures):
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except cf.process.BrokenProcessPool:
                    lost.append(i)
            if not lost:
                return results
            log.warning("a worker process died: %d episodes run again", len(lost))
            self.rerun += len(lost)
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
            todo = sorted(lost)
            if attempt == self.retries:
                break
        raise RuntimeError(f"{len(todo)} episodes lost their worker {self.retries + 1} times")

    def _submit(self, tasks: list[EpisodeTask], todo: list[int]) -> dict:
        """The futures of ``tasks[i]`` for ``i`` in ``todo`` on the pool; a pool a worker left
        while it was idle (between maps: nothing of it was lost) is replaced first."""
        for _ in range(2):
            if self._pool is None:
                self._pool = self._new_pool()
            try:
                return {self._pool.submit(run_episode, tasks[i]): i for i in todo}
            except cf.process.BrokenProcessPool:
                log.warning("a worker process died between runs: a new pool")
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = None
        raise RuntimeError("the pool's workers died as they started, twice")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None:
            self._client.close()
            self._client = None

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def run_episodes(tasks: list[EpisodeTask], cluster: str | None = None,
                 workers: int | None = None) -> list[dict]:
    """Every task's result in order: on the Dask cluster at ``cluster``, else on ``workers``
    processes (None: one per core)."""
    with Runner(workers=workers, cluster=cluster) as runner:
        return runner.map(tasks)


# -------------------------------------------------------------------------- the options


def _cluster(text: str) -> str:
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    if scheme not in ("tcp", "tls"):
        raise ValueError(f"must be a Dask scheduler's address tcp://HOST:PORT, got {text!r}")
    arguments.address.parse(rest)
    return f"{scheme}://{rest}"


cluster_address = arguments.Checked("cluster address", _cluster)
cluster_address.kind, cluster_address.example = "address", "tcp://127.0.0.1:8786"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers N`` and ``--cluster ADDRESS``: where the episodes run."""
    parser.add_argument("--workers", type=arguments.positive_int, default=None,
                        help="run the episodes on this many processes of this machine "
                             "(default: one per core; 1: in this process)")
    parser.add_argument("--cluster", type=cluster_address, default=None, metavar="ADDRESS",
                        help="run the episodes on the Dask cluster whose scheduler is at "
                             "tcp://HOST:PORT (needs the 'cluster' extra: pip install "
                             "'rhbl[cluster]'; every worker with rhbl installed)")


def runner_from_args(args: argparse.Namespace) -> Runner:
    if args.cluster is not None and args.workers is not None:
        raise ValueError("give --workers N or --cluster ADDRESS, not both (a cluster's "
                         "workers are its own)")
    return Runner(workers=args.workers, cluster=args.cluster)
