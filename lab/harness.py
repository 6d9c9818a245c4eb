"""The in-process harness: no zenoh, ``server.world.World`` stepped directly at 10 Hz with the same
feature, action, policy and learning code the zenoh processes run. ``rhbl train`` (``lab.train``)
and ``rhbl evaluate`` (``lab.evaluate``) run on it.

One step (``step_world``): scan -> (teacher label | tree prediction) -> world.set_command ->
world.step(dt). ``on_step`` (optional: ``lab.sim_tap.SimTap.step`` for ``--record``) sees each
step before the world moves; it is passed explicitly, down to every step that should be seen.

    spec = resolve_world("room")
    b = behaviour_for_world(spec)                                    # lab.behaviours
    learner = make_learner(recipe_of(b))                             # lab.recipe: the defaults
    ep = drive(spec, TreePolicy.from_learner(learner), pose, seconds=b.seconds,
               teacher=b.expert(), behaviour=b)
    ep.poses, ep.stalls, ep.actions, ep.side, ep.teacher_actions, ep.dt   (a lab.episode.Episode)
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from client.behaviour.actions import DEFAULT_ACTIONS, ActionSet
from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.rule import rule_for
from client.behaviour.spec import Behaviour, BehaviourError, shipped
from lab import metrics
from lab.behaviours import behaviour_for_world
from lab.episode import DT, Episode
from lab.recipe import Recipe, parse_floats, recipe_for
from process.arguments import checked_list
from server.world import World, WorldSpec, load_world

__all__ = [
    "DT",
    "OnStep",
    "demonstration_starts",
    "drive",
    "make_learner",
    "parse_pose",
    "recorded",
    "resolve_world",
    "step_world",
]

# what sees each step before the world moves: (world, executed action, ranges, actions, label=,
# source=) (lab.sim_tap.SimTap.step)
OnStep = Callable[..., None]


def resolve_world(path_or_name: str) -> WorldSpec:
    p = Path(path_or_name)
    if not p.exists():
        import server

        if hasattr(server, "world_path"):
            p = Path(server.world_path(path_or_name))
        else:  # pragma: no cover
            p = Path(__file__).resolve().parent.parent / "server" / "worlds" / f"{path_or_name}.toml"
    return load_world(p)


def _parse_pose(text: str) -> tuple[float, float, float]:
    vals = parse_floats(text, "pose must be x,y,yaw numbers")
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"pose must be x,y,yaw (3 finite numbers), got {text!r}")
    return vals  # type: ignore[return-value]


# ``--start x,y,yaw`` (an argparse type: ``process.arguments.checked_list``)
parse_pose = checked_list("pose", _parse_pose, "1,1,0")


def make_learner(recipe: Recipe | str, actions: ActionSet = DEFAULT_ACTIONS, *,
                 record: bool | None = None) -> DemonstrationLearner:
    """A learner as ``recipe`` says (features, stride, tree parameters) by the scripted
    teacher's learning rule (``client.behaviour.rule.rule_for("script")``: the expert's labels
    learned as they arrive; recorded in the snapshot); a task name: its default recipe.
    ``record``: keep the vectors it learns (``learner.recorded()``); default: when the recipe
    compacts or bounds the spheres by the margin (those steps need them)."""
    recipe = recipe_for(recipe) if isinstance(recipe, str) else recipe
    return DemonstrationLearner(recipe.feature_spec(), actions, task=recipe.task,
                                stride=recipe.stride, min_delta=recipe.min_delta,
                                record=(recipe.compact != "none" or recipe.radius == "margin"
                                        if record is None else record),
                                rule=rule_for("script"), **recipe.tree_params())


def learned_from(recipe: Recipe, X: np.ndarray, y, actions: ActionSet = DEFAULT_ACTIONS
                 ) -> DemonstrationLearner:
    """A learner of ``recipe`` (``make_learner``) that has learned the vectors ``(X, y)`` in
    order as ``rhbl train``'s learner ends having learned them: offered as they came, then,
    with the recipe's radius "margin", learned again from all of them at once
    (``DemonstrationLearner.relearn``). The same tree as the trained one, from its recorded
    vectors (the peer benchmark fits RHBL so)."""
    learner = make_learner(recipe, actions)  # (it records what the margin's relearn needs)
    learner.observe_vectors(X, y)
    if recipe.radius == "margin":
        learner.relearn()
    return learner


def step_world(world: World, ep: Episode, actions: ActionSet, name: str, side: str | None,
               ranges, label: str | None = None, source: str = "teacher",
               on_step: OnStep | None = None, gaps: bool = False) -> None:
    """One step: ``on_step`` (if any) sees it first, then the action ``name`` drives the world
    ``ep.dt`` seconds and ``ep`` records the pose, the stall, the followed side's distance
    (``side`` not None) and the left wall's distance minus the right's (``gaps``)."""
    if on_step is not None:  # rhbl train/evaluate --record: lab.sim_tap.SimTap.step
        on_step(world, name, ranges, actions, label=label, source=source)
    vx, va = actions[name]
    world.set_command(0, vx, va)
    world.step(ep.dt)
    ep.actions.append(name)
    ep.poses.append(world.pose(0))
    ep.stalls.append(world.stall(0))
    if side is not None:
        ep.side.append(metrics.side_distance(ranges, side))
    if gaps:
        ep.gaps.append(metrics.side_distance(ranges, "left") - metrics.side_distance(ranges, "right"))


def recorded(behaviour: Behaviour) -> dict:
    """What ``step_world`` records for ``behaviour``'s success rule: ``side`` and ``gaps``."""
    return {"side": behaviour.band_side, "gaps": "centred" in behaviour.rules}


def demonstration_starts(spec: WorldSpec, starts: str = "world") -> list[tuple[float, float, float]]:
    """The fixed part of a training run's schedule: ``"default"`` = the world's pose only,
    ``"world"`` = every start pose of the world (default pose first)."""
    if starts == "default":
        return [tuple(spec.pose)]
    if starts in ("world", "free"):
        return [tuple(p) for p in spec.start_poses]
    raise ValueError(f"starts must be 'default', 'world' or 'free', got {starts!r}")


def drive(spec: WorldSpec, driver, start, seconds: float, seed: int = 0, teacher=None,
          range_noise: float = 0.0, odom_noise: float = 0.0, dt: float = DT,
          stop_at_goal: bool = True, kind: str = "", on_step: OnStep | None = None,
          behaviour: Behaviour | None = None) -> Episode:
    """Drive ``driver`` (anything with ``act(ranges, pose)``: a TreePolicy or a scripted policy)
    from ``start`` for ``seconds``; ``teacher`` (optional) is asked what it would do on each
    state (teacher agreement). Stops at the goal, when the world has one. The episode records
    what ``behaviour``'s success rule measures (default: the world's behaviour, else the one
    the driver was taught; in a world no behaviour names, the right-hand wall's distance)."""
    actions = getattr(driver, "actions", DEFAULT_ACTIONS)
    world = World(spec, robots=1, seed=seed, range_noise=range_noise, odom_noise=odom_noise)
    start = tuple(float(v) for v in start)
    world.reset(poses=[start])
    driver.reset()
    if teacher is not None:
        teacher.reset()
    ep = Episode(start=start, dt=dt, kind=kind)
    if behaviour is None:
        try:
            behaviour = behaviour_for_world(spec, (getattr(driver, "metadata", None) or {})
                                            .get("task"))
        except BehaviourError:  # a world no behaviour names: the paper's measure
            behaviour = shipped()["wall-following"]
    record = recorded(behaviour)
    t0 = time.perf_counter()
    for _ in range(int(round(seconds / dt))):
        ranges = world.scan(0)
        odom = world.odom(0)
        name = driver.act(ranges, odom)
        if teacher is not None:
            ep.teacher_actions.append(teacher.act(ranges, odom))
        step_world(world, ep, actions, name, record["side"], ranges,
                   source="controller" if isinstance(driver, TreePolicy) else "teacher",
                   on_step=on_step, gaps=record["gaps"])
        if stop_at_goal and spec.goal is not None and world.at_goal(0):
            break
    ep.wall_time = time.perf_counter() - t0
    return ep
