"""The tasks a robot learns, one table: what each task is made of, for everyone who needs it.

    task = TASKS["maze"]              # or task_named("maze"): ValueError naming the known ones
    task.features                     # "maze": its feature spec (client.behaviour.features.FEATURES)
    task.teacher                      # "maze": its scripted expert in ``rhbl teacher --policy``
    task.side                         # the wall it keeps beside the robot ("right"), or None
    make_policy("wall-following")     # the task's scripted expert (style "reactive" or "smooth")

What a robot is taught is a behaviour file (``client.behaviour.spec``, docs/behaviours.md): it
names its scripted expert by ``teacher`` ("wall-follower", "maze") and gives its parameters (the
side, ...); this table is where the experts' classes are found. A world file may still name its
task (``server.world.TASKS``, the world format's list, holds the same names: the server cannot
import this package; a test keeps the two equal); a task's name is its shipped behaviour's.
"""

from __future__ import annotations

from dataclasses import dataclass

from .actions import DEFAULT_ACTIONS, ActionSet
from .goals import BeaconSeeker
from .policies import (
    STYLES,
    CorridorCentrer,
    DeadEndEscaper,
    DoorwayTeacher,
    MazeTeacher,
    Policy,
    ReactiveDoorwayFollower,
    ReactiveFollower,
    ReactiveMazeTeacher,
    WallFollower,
    Wanderer,
)

__all__ = ["TASKS", "Task", "make_policy", "task_named", "task_of_features", "task_of_teacher"]


@dataclass(frozen=True)
class Task:
    """One task: ``name`` (as world files name it), ``features`` (the feature spec a new tree of
    it learns by default), ``teacher`` (its scripted expert's name for ``rhbl teacher
    --policy``), ``side`` (the wall the robot keeps beside it, measured as the wall band; None
    when none), ``reactive`` and ``smooth`` (the expert's classes of each style) and
    ``eval_worlds`` (the glob of the shipped worlds that evaluate it)."""

    name: str
    features: str
    teacher: str
    side: str | None
    reactive: type[Policy]
    smooth: type[Policy]
    eval_worlds: str

    def expert(self, style: str = "reactive") -> type[Policy]:
        if style not in STYLES:
            raise ValueError(f"teacher style must be one of {STYLES}, got {style!r}")
        return self.reactive if style == "reactive" else self.smooth


TASKS: dict[str, Task] = {t.name: t for t in (
    Task("wall-following", features="wall", teacher="wall-follower", side="right",
         reactive=ReactiveFollower, smooth=WallFollower, eval_worlds="eval-room*.toml"),
    Task("maze", features="maze", teacher="maze", side=None,
         reactive=ReactiveMazeTeacher, smooth=MazeTeacher, eval_worlds="eval-maze*.toml"),
    # room to room through doorways: the right-hand rule in a suite of rooms (shipped behaviour
    # "doorways"); its own worlds are the behaviour file's
    Task("doorways", features="wall", teacher="doorway", side=None,
         reactive=ReactiveDoorwayFollower, smooth=DoorwayTeacher,
         eval_worlds="eval-doorways*.toml"),
    # out of a dead end: straight on, a U-turn on the spot where the way is blocked (shipped
    # behaviour "dead-end"); a reactive expert only, so both styles are the same one
    Task("dead-end", features="around", teacher="dead-end", side=None,
         reactive=DeadEndEscaper, smooth=DeadEndEscaper, eval_worlds="eval-dead-end*.toml"),
)}


def task_named(name: str) -> Task:
    """The task ``name``; ValueError naming the known tasks."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"no task {name!r}; known: {', '.join(TASKS)}") from None


def task_of_features(features: str | None) -> str | None:
    """The paper's task whose spec is ``features`` (``wall`` -> wall-following, ``maze`` ->
    maze: what a tree of one that names no task meant); None for any other spec (``around``,
    say, is the perception of several behaviours: a tree of it names its task itself, or none)."""
    return next((t.name for t in list(TASKS.values())[:2] if t.features == features), None)


def task_of_teacher(teacher: str) -> str:
    """The task of a scripted expert named as ``rhbl teacher --policy`` names it."""
    for t in TASKS.values():
        if t.teacher == teacher:
            return t.name
    raise ValueError(f"no scripted teacher {teacher!r}; known: "
                     f"{', '.join(t.teacher for t in TASKS.values())}")


def make_policy(task: str, actions: ActionSet = DEFAULT_ACTIONS, style: str = "reactive",
                **kw) -> Policy:
    """The scripted expert of a world's task: "wall-following" or "maze".

    ``style="reactive"`` (default): ``ReactiveFollower`` / ``ReactiveMazeTeacher``, labels a pure
    function of the scan's sectors (docs/experiments.md: the learnable teacher).
    ``style="smooth"``: the earlier history-dependent ``WallFollower`` / ``MazeTeacher``
    (hysteresis, dwell, committed rotations, lost-wall memory)."""
    if style not in STYLES:
        raise ValueError(f"teacher style must be one of {STYLES}, got {style!r}")
    if task not in TASKS:
        raise ValueError(f"no scripted teacher for task {task!r}; known: {', '.join(TASKS)}")
    return TASKS[task].expert(style)(actions=actions, **kw)


# centring along a winding corridor (the shipped behaviour corridor-centring)
TASKS["corridor-centring"] = Task("corridor-centring", features="around",
                                  teacher="corridor-centrer", side=None,
                                  reactive=CorridorCentrer, smooth=CorridorCentrer,
                                  eval_worlds="eval-corridor*.toml")

# wandering a cluttered room without touching anything, covering ground (the shipped behaviour
# wandering)
TASKS["wandering"] = Task("wandering", features="around", teacher="wanderer", side=None,
                          reactive=Wanderer, smooth=Wanderer, eval_worlds="eval-clutter*.toml")

# goals in order: to each beacon the behaviour's [goals] name in turn, keeping off the walls
# (the shipped behaviours red-green, patrol and remembered; client.behaviour.goals)
TASKS["red-green"] = Task("red-green", features="around", teacher="beacon-seeker", side=None,
                          reactive=BeaconSeeker, smooth=BeaconSeeker,
                          eval_worlds="eval-goals*.toml")
