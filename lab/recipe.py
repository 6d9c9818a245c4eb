"""The training recipe: one frozen :class:`Recipe` per task, the single home of every default of
``rhbl train``, ``rhbl experiment`` and ``rhbl demo`` (their ``--help`` texts are generated from
it). docs/experiments.md says how each value was chosen and what it measured.

    recipe = RECIPES["maze"]                          # the task's recipe
    recipe = recipe.replace(seconds=120, rounds=1)    # a variant (validated, still frozen)
    recipe = recipe_from_args("maze", args)           # the recipe plus the CLI flags given
    demo = recipe.for_demo()                          # what ``rhbl demo`` runs (DEMO overrides)

One training run (``lab.harness.train``): demonstrations from the ``starts`` poses, each
``segment`` seconds (or until the goal), then from sampled poses (``random_segment`` x
``segment`` each) until ``seconds`` of sim time are used; then ``rounds`` corrective (DAgger)
rounds of ``round_seconds`` per start pose, first in each of ``round_worlds`` (and its scaled copies),
then in ``round_generated`` randomised worlds (``lab.generated``), then in copies of the world
scaled by each of ``round_scales``, each round also from
``round_free`` random free-space poses; last, the
``compact`` step (also after the demonstrations and after every round with ``compact_rounds``;
redone against held-out visited states with ``compact_visits``).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass

from client.behaviour.features import FEATURES, FeatureSpec
from lab.generated import KINDS
from process import arguments
from process.arguments import checked_list

__all__ = [
    "DEMO",
    "EVAL_SECONDS",
    "OWN",
    "RECIPES",
    "Recipe",
    "add_recipe_arguments",
    "parse_floats",
    "parse_scales",
    "per_task",
    "recipe_default",
    "recipe_for",
    "recipe_from_args",
]

STARTS = ("default", "world", "free")
GENERATORS = KINDS  # the kinds of randomised world lab.generated draws
SPAWN = ("all", "winner")
DISTANCE = ("squared", "euclidean")
RADIUS = ("parent", "margin")
TREE_PARAMS = ("spawn", "distance", "radius", "min_radius", "max_nodes", "max_depth")
# the compaction step's choices and the ``rhbl.compaction`` settings each one means
COMPACT: dict[str, dict] = {
    "none": {}, "exact": {"method": "exact"}, "prune": {"method": "prune"},
    "prune-balanced": {"method": "prune", "class_weight": "balanced"}}


@dataclass(frozen=True)
class Recipe:
    """How a task's tree is trained. ``None`` tree parameters: the classifier's own default."""

    task: str
    world: str                      # the shipped world it is trained on (experiment, demo)
    features: str | FeatureSpec = "wall"
    perturb: float = 0.05           # fraction of steps a random action is executed
    seconds: float = 600.0          # sim seconds of demonstration in total
    # the tree (rhbl.HypersphereClassifier) and what the learner offers it
    spawn: str = "winner"
    distance: str | None = None
    # "margin": the tree learned again at the end from every vector, each sphere bounded by the
    # nearest vector of another label (rhbl's radius="margin"); None: the paper's radius
    radius: str | None = None
    min_radius: float | None = None
    max_nodes: int | None = None
    max_depth: int | None = None
    stride: int = 1                 # learn every n-th labelled step
    min_delta: float = 0.0
    # the demonstrations
    starts: str = "world"           # "default" | "world" | "free"
    segment: float = 60.0           # sim seconds per demonstration before the teacher restarts
    random_segment: float = 0.0     # sampled-pose demonstrations: this fraction of ``segment``
    turn: float = math.pi           # heading change of a sampled pose (rad)
    consistent: bool = False        # learn only labels that do not depend on the teacher's memory
    # the corrective (DAgger) rounds
    rounds: int = 0
    round_seconds: float = 60.0
    takeover: float = 0.0           # the teacher drives while a beam is closer than this (m)
    round_scales: tuple[float, ...] = ()
    round_free: int = 0
    # corrective rounds also in these worlds (names or paths: a behaviour's other teaching
    # worlds, ``lab.behaviours.recipe_of``), each from its own start poses and in its copies
    # scaled by ``round_scales``, before the training world's
    round_worlds: tuple[str, ...] = ()
    # corrective rounds also in this many randomised worlds of the kind ``generator`` names
    # (``lab.generated``: "rooms", "mazes", "clutter", "beacons"; domain randomisation), drawn
    # from the training seed, each from its own start poses, after ``round_worlds``
    round_generated: int = 0
    generator: str = "rooms"
    # scale augmentation: each labelled state offered again with the scan scaled
    augment: int = 0
    augment_scale: float = 1.3
    # the last step: compact the tree on every vector it learned (``rhbl.compaction``). None by
    # default: every compaction measured, also between the rounds, lost closed-loop success on
    # some world for some seed (docs/experiments.md, "Compact trees (issue)")
    compact: str = "none"           # "none" | "exact" | "prune" | "prune-balanced"
    compact_max_nodes: int | None = None    # prune: until at most this many spheres are left
    compact_max_error: float | None = None  # prune: fraction of the vectors it may make wrong
    # compact also after the demonstrations and after every corrective round, so that the next
    # round's teacher labels the states the compacted tree itself reaches (its errors there
    # grow new spheres); the last round's compaction is the last step
    compact_rounds: bool = False
    # then redo the last compaction this many times against every learned vector plus held-out
    # visited states: the compacted tree drives one corrective round without learning (the
    # start poses and ``visit_free`` free-space poses) in copies scaled by ``visit_scales`` and
    # in the world, the teacher labelling (``lab.harness.visited_states``); the tree as it was
    # before the last compaction is compacted against all of them
    compact_visits: int = 0
    visit_scales: tuple[float, ...] = (0.85, 1.2)
    visit_free: int = 4

    def __post_init__(self) -> None:
        def bad(name: str, expected: str) -> ValueError:
            return ValueError(f"recipe {name} must be {expected}, got {getattr(self, name)!r}")

        if not isinstance(self.task, str) or not self.task:
            raise bad("task", "a behaviour's name (client.behaviour.spec)")
        if not isinstance(self.features, FeatureSpec) and self.features not in FEATURES:
            raise bad("features", f"one of {', '.join(sorted(FEATURES))} or a FeatureSpec")
        if self.starts not in STARTS:
            raise bad("starts", f"one of {', '.join(STARTS)}")
        if self.spawn not in SPAWN:
            raise bad("spawn", f"one of {', '.join(SPAWN)}")
        if self.distance is not None and self.distance not in DISTANCE:
            raise bad("distance", f"one of {', '.join(DISTANCE)}")
        if self.radius is not None and self.radius not in RADIUS:
            raise bad("radius", f"one of {', '.join(RADIUS)}")
        for name in ("seconds", "segment", "round_seconds", "augment_scale"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise bad(name, "a finite number > 0")
        for name in ("perturb", "random_segment", "turn", "takeover", "min_delta"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise bad(name, "a finite number >= 0")
        if not self.perturb <= 1:
            raise bad("perturb", "a fraction in [0, 1]")
        for name in ("rounds", "round_free", "augment", "compact_visits", "visit_free",
                     "round_generated"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise bad(name, "an integer >= 0")
        if isinstance(self.stride, bool) or not isinstance(self.stride, int) or self.stride < 1:
            raise bad("stride", "an integer >= 1")
        if self.compact not in COMPACT:
            raise bad("compact", f"one of {', '.join(COMPACT)}")
        if self.compact != "none" and self.radius == "margin":
            raise ValueError(f"recipe compact {self.compact!r} keeps a tree's answers by the "
                             "paper's rule: not with radius 'margin' (to compact: radius "
                             "'parent', --radius parent)")
        n = self.compact_max_nodes
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise bad("compact_max_nodes", "None or an integer >= 1")
        e = self.compact_max_error
        if e is not None and not (isinstance(e, int | float) and math.isfinite(e) and 0 <= e <= 1):
            raise bad("compact_max_error", "None or a fraction in [0, 1]")
        if not isinstance(self.compact_rounds, bool):
            raise bad("compact_rounds", "True or False")
        for name in ("compact_rounds", "compact_visits"):
            if getattr(self, name) and self.compact == "none":
                raise ValueError(f"recipe {name} needs a compaction step (compact 'exact', "
                                 "'prune' or 'prune-balanced'), got compact 'none'")
        if (n is not None or e is not None) and not self.compact.startswith("prune"):
            raise ValueError(f"recipe compact_max_nodes/compact_max_error apply to compact "
                             f"'prune' or 'prune-balanced' only, got compact {self.compact!r}")
        if self.generator not in GENERATORS:
            raise bad("generator", f"one of {', '.join(GENERATORS)}")
        worlds = self.round_worlds
        if isinstance(worlds, str) or not all(isinstance(w, str) and w for w in worlds):
            raise bad("round_worlds", "a list of world names or paths")
        object.__setattr__(self, "round_worlds", tuple(worlds))
        for name in ("round_scales", "visit_scales"):
            scales = tuple(float(v) for v in getattr(self, name))
            if not all(math.isfinite(v) and v > 0 for v in scales):
                raise bad(name, "finite factors > 0")
            object.__setattr__(self, name, scales)

    def replace(self, **changes) -> Recipe:
        """A copy with ``changes`` (field names; an unknown name is a TypeError naming it)."""
        unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(self)})
        if unknown:
            raise TypeError(f"not a recipe field: {', '.join(unknown)}")
        return dataclasses.replace(self, **changes)

    def feature_spec(self) -> FeatureSpec:
        return self.features if isinstance(self.features, FeatureSpec) else FEATURES[self.features]

    def tree_params(self) -> dict:
        """The classifier's keyword arguments the recipe sets (``None``: its own default)."""
        return {k: getattr(self, k) for k in TREE_PARAMS if getattr(self, k) is not None}

    def compact_params(self) -> dict | None:
        """The keyword arguments of the compaction step (``DemonstrationLearner.compact``), or
        None when the recipe does not compact."""
        if self.compact == "none":
            return None
        out = dict(COMPACT[self.compact])
        if self.compact_max_nodes is not None:
            out["max_nodes"] = self.compact_max_nodes
        if self.compact_max_error is not None:
            out["max_error"] = self.compact_max_error
        return out

    def for_demo(self) -> Recipe:
        """The recipe ``rhbl demo`` runs over zenoh: this one with the task's ``DEMO`` changes,
        less what one server in one world cannot run (rounds in scaled copies, in other or
        randomised worlds, from free-space poses) and the margin radius (the learner process
        learns each label as it comes: the paper's radius)."""
        return self.replace(round_scales=(), round_free=0, round_worlds=(), round_generated=0,
                            radius=None, **DEMO.get(self.task, {}))


# The default recipe per task (docs/experiments.md "Current recipe" has the measurements
# behind each value). Wall following: demonstrations from the start poses, then 30 s ones
# from random free-space poses, three corrective rounds. Maze: long demonstrations from each
# start pose, six corrective rounds in copies scaled 0.85 and 1.2 and in the maze itself, each
# also from four random free-space poses; its randomised worlds are tiered mazes (none in its
# rounds: ``rhbl refine --generated`` draws them).
RECIPES: dict[str, Recipe] = {
    "wall-following": Recipe(
        task="wall-following", world="room", seconds=600.0, starts="free", segment=60.0,
        random_segment=0.5, rounds=3, round_seconds=60.0, takeover=0.3),
    "maze": Recipe(
        task="maze", world="maze", seconds=600.0, starts="world", segment=240.0,
        random_segment=0.0, rounds=6, round_seconds=240.0, takeover=0.3,
        round_scales=(0.85, 1.2), round_free=4, generator="mazes"),
}

# What ``rhbl demo`` changes for its time budget (about two minutes on a shared 2-core machine):
# the maze runs 4 corrective rounds instead of 6 (``--rounds 6`` for the recipe's). The demo
# also leaves out, by construction (one server serves one world, the demo teleports only to
# its start poses): rounds in scaled copies, in other teaching worlds and in randomised worlds,
# rounds from free-space poses and the wall following's demonstrations from free-space poses;
# each start pose demonstrates ``segment``. Goals in order (red-green, ``--scenario goals``)
# run the recipe's 4 rounds (with 2, the recipe's before, the final tree reached both beacons
# in order from 17 of 24 starts, seeds 0-3, against 23 of 24 with 4: ``rhbl demo --scenario
# goals --seed S --rounds 2|4``).
DEMO: dict[str, dict] = {"maze": {"rounds": 4}}

# What a behaviour's own recipe (``lab.behaviours.recipe_of``; not ``--paper``) changes from
# the paper's scenario: the spheres bounded by the margin, the tree learned again from every
# vector at the end (chosen on development rooms, mazes, left-hand rooms, cluttered rooms and
# rooms with beacons, and the dead end's teaching world: docs/studies/margin-radius.md; the
# behaviour file of remembered keeps the paper's radius).
OWN: dict = {"radius": "margin"}

# Sim seconds of one evaluation episode per task (``rhbl evaluate``, the demo's final drives).
EVAL_SECONDS: dict[str, float] = {"wall-following": 120.0, "maze": 240.0}


def recipe_for(task: str) -> Recipe:
    """The default recipe of ``task`` (ValueError naming the task when there is none)."""
    try:
        return RECIPES[task]
    except KeyError:
        raise ValueError(f"no training recipe for task {task!r} "
                         f"(known: {', '.join(RECIPES)})") from None


# ------------------------------------------------------------------------------------- CLI


def _show(value) -> str:
    if isinstance(value, tuple):
        return ",".join(f"{v:g}" for v in value) if value else "none"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    return "the classifier's" if value is None else str(value)


def per_task(values: dict[str, object]) -> str:
    """``"wall following 600, maze 600"``: one value per task, for help texts."""
    return ", ".join(f"{task.replace('-', ' ')} {_show(v)}" for task, v in values.items())


def recipe_default(name: str, recipes: dict[str, Recipe] | None = None) -> str:
    """The help text's default of recipe field ``name``, generated from ``recipes``:
    ``"default: the recipe's (wall following 600, maze 600)"``."""
    if name in OWN and recipes is None:
        return (f"default: {OWN[name]} in a behaviour's own recipe (its file may say "
                "otherwise: remembered's does), the paper's with --paper")
    values = {t: getattr(r, name) for t, r in (RECIPES if recipes is None else recipes).items()}
    if all(v is None for v in values.values()):
        return "default: the classifier's" if name in TREE_PARAMS else "default: none"
    return f"default: the recipe's ({per_task(values)})"


def parse_floats(text: str, what: str) -> tuple[float, ...]:
    """Comma-separated numbers of a CLI value; ArgumentTypeError saying ``what`` they must be."""
    try:
        return tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{what}, got {text!r}") from exc


def _parse_scales(text: str) -> tuple[float, ...]:
    if text.strip().lower() in ("", "none"):
        return ()
    vals = parse_floats(text, "scales must be numbers like 0.85,1.2 or 'none'")
    if not all(v > 0 and math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"scales must be positive, got {text!r}")
    return vals


# ``--round-scales``: comma-separated positive factors, or 'none'
parse_scales = checked_list("scales", _parse_scales, "1.2")


# flag -> (recipe field, argparse keywords, help); the help gets the recipe's defaults appended
_FLAGS: list[tuple[str, str, dict, str]] = [
    ("--perturb", "perturb", {"type": arguments.fraction},
     "fraction of time a random action is executed"),
    ("--features", "features", {"choices": sorted(FEATURES)}, "feature spec"),
    ("--spawn", "spawn", {"choices": list(SPAWN)},
     "spawn rule ('all' is the paper's literal rule)"),
    ("--distance", "distance", {"choices": list(DISTANCE)}, "the tree's distance"),
    ("--radius", "radius", {"choices": list(RADIUS)},
     "a new sphere's radius: 'parent' (the paper's: as large as its parent allows) or "
     "'margin' (also no farther than the nearest vector of another label: the tree learned "
     "again from every vector at the end of training, docs/rhbl.md)"),
    ("--min-radius", "min_radius", {"type": arguments.non_negative_float},
     "the smallest sphere radius"),
    ("--max-nodes", "max_nodes", {"type": arguments.positive_int}, "cap on the tree size"),
    ("--stride", "stride", {"type": arguments.positive_int}, "learn every n-th step"),
    ("--starts", "starts", {"choices": list(STARTS)},
     "demonstrate from the world's default pose only, or from each of its start poses in turn "
     "('free': then from poses anywhere in the free space, random heading)"),
    ("--segment", "segment", {"type": arguments.seconds},
     "sim seconds per demonstration before the teacher restarts"),
    ("--random-segment", "random_segment", {"type": arguments.non_negative_float},
     "after the start poses: demonstrations from sampled poses, each this fraction of "
     "--segment (0: cycle the start poses)"),
    ("--consistent", "consistent", {"action": "store_true"},
     "learn only labels that do not depend on the teacher's memory"),
    ("--rounds", "rounds", {"type": arguments.non_negative_int},
     "corrective (DAgger) rounds after the demonstration: the tree drives from every start "
     "pose, the teacher labels"),
    ("--round-seconds", "round_seconds", {"type": arguments.seconds},
     "sim seconds per start pose in each corrective round"),
    ("--round-free", "round_free", {"type": arguments.non_negative_int},
     "corrective rounds also drive from this many random free-space poses"),
    ("--round-generated", "round_generated", {"type": arguments.non_negative_int},
     "corrective rounds also in this many randomised worlds of --generator (domain "
     "randomisation, lab.generated), drawn from the seed"),
    ("--generator", "generator", {"choices": list(GENERATORS)},
     "the kind of randomised world of --round-generated"),
    ("--takeover", "takeover", {"type": arguments.non_negative_float},
     "in corrective rounds the teacher drives while a beam is closer than this (m; 0 = never)"),
    ("--augment", "augment", {"type": arguments.non_negative_int},
     "scale augmentation: offer every labelled state N more times with the scan scaled (a "
     "wider/narrower copy of the world)"),
    ("--augment-scale", "augment_scale",
     {"type": arguments.Number(float, 1, 10, name="scale factor")},
     "largest scale factor of --augment (and 1/it the smallest)"),
    ("--round-scales", "round_scales", {"type": parse_scales, "metavar": "F,F"},
     "repeat the corrective rounds in the training world scaled by these factors first "
     "('none': only the world itself)"),
    ("--compact", "compact", {"choices": list(COMPACT)},
     "last step: compact the tree on every vector it learned (rhbl.compaction; exact: no "
     "prediction on them changes; prune: also delete the weakest spheres; prune-balanced: "
     "errors weighted per label)"),
    ("--compact-max-nodes", "compact_max_nodes", {"type": arguments.positive_int},
     "prune: delete the weakest spheres until at most N are left"),
    ("--compact-max-error", "compact_max_error", {"type": arguments.fraction},
     "prune: fraction of the learned vectors whose errors it may add"),
    ("--compact-rounds", "compact_rounds", {"action": argparse.BooleanOptionalAction},
     "with --compact: compact also after the demonstrations and after every corrective round, "
     "so the next round corrects the states the compacted tree reaches"),
    ("--compact-visits", "compact_visits", {"type": arguments.non_negative_int},
     "with --compact: then redo the last compaction K times against the learned vectors plus "
     "the teacher's labels of the states the compacted tree reaches in one round without "
     "learning in scaled copies (--visit-scales) and the world"),
    ("--visit-scales", "visit_scales", {"type": parse_scales, "metavar": "F,F"},
     "--compact-visits: the scaled copies ('none': only the world itself)"),
    ("--visit-free", "visit_free", {"type": arguments.non_negative_int},
     "--compact-visits: the round also drives from this many random free-space poses"),
]


def add_recipe_arguments(parser: argparse.ArgumentParser, seconds: str = "--seconds") -> None:
    """The recipe's flags (default None: the task's recipe), ``seconds`` naming the flag of
    the demonstration time; every help text shows the recipe's values."""
    parser.add_argument(seconds, dest="recipe_seconds", type=arguments.seconds, default=None,
                        metavar="S",
                        help=f"sim seconds of demonstration ({recipe_default('seconds')})")
    for flag, name, kw, text in _FLAGS:
        parser.add_argument(flag, dest=name, default=None, **kw,
                            help=f"{text} ({recipe_default(name)})".replace("%", "%%"))


def recipe_from_args(task: str | Recipe, args: argparse.Namespace) -> Recipe:
    """The task's recipe (or the recipe ``task``) with the flags of ``add_recipe_arguments``
    that were given."""
    changes = {f.name: getattr(args, f.name) for f in dataclasses.fields(Recipe)
               if f.name not in ("task", "world", "seconds") and getattr(args, f.name, None)
               is not None}
    if getattr(args, "recipe_seconds", None) is not None:
        changes["seconds"] = args.recipe_seconds
    compact = changes.get("compact")
    if compact is not None:  # --compact replaces the recipe's step: its other settings not
        if not compact.startswith("prune"):  # given go with it
            changes.setdefault("compact_max_nodes", None)
            changes.setdefault("compact_max_error", None)
        if compact == "none":
            changes.setdefault("compact_rounds", False)
            changes.setdefault("compact_visits", 0)
    return (task if isinstance(task, Recipe) else recipe_for(task)).replace(**changes)
