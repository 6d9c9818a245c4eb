"""``rhbl behaviours``: the shipped behaviours, one line each; and the lab's side of behaviour
files (``client.behaviour.spec``): their worlds, their recipe, a world's behaviour.

    b = get("wall-following")              # a shipped behaviour's name or a behaviour file's path
    spec = world_of(b, "room")             # the world, with the behaviour's own start poses
    spec = teaching_world(b)               # its first teaching world
    recipe = recipe_of(b)                  # its training recipe (lab.recipe)
    b = behaviour_for_world(spec)          # the behaviour a world is taught or evaluated for
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from client.behaviour.given import behaviour_arg  # --behaviour NAME|FILE: the processes' too
from client.behaviour.spec import Behaviour, BehaviourError, behaviour, for_world, shipped
from lab.recipe import OWN, RECIPES, Recipe
from process import arguments, files
from server import world_path
from server.world import WorldSpec, load_world

__all__ = ["add_arguments", "add_paper_argument", "behaviour_arg", "behaviour_for_world",
           "check", "describe", "get", "main", "recipe_of", "teaching_world", "to_dict", "world_of"]


def get(name_or_path: str | Path | Behaviour) -> Behaviour:
    """A shipped behaviour by name, a behaviour file by path (a Behaviour: itself)."""
    return name_or_path if isinstance(name_or_path, Behaviour) else behaviour(name_or_path)


def world_of(b: Behaviour, world: str) -> WorldSpec:
    """The world ``world`` (a name or path, as the behaviour names it or not) with the
    behaviour's own start poses for it, when it gives some (the first is the default pose)."""
    try:
        spec = load_world(world_path(world))
    except FileNotFoundError as exc:
        where = b.path or b.name
        raise BehaviourError(f"{where}: field 'worlds': {exc}") from None
    starts = b.starts.get(world) or b.starts.get(spec.name)
    if starts:
        spec = dataclasses.replace(spec, pose=starts[0], starts=tuple(starts[1:]))
    return spec


def teaching_world(b: Behaviour) -> WorldSpec:
    """The first world the behaviour is taught in."""
    return world_of(b, b.teach[0])


def recipe_of(b: Behaviour, paper: bool = False) -> Recipe:
    """The behaviour's training recipe: the recipe of the same name (``lab.recipe.RECIPES``, the
    paper's Table I scenarios'), else wall following's; with the behaviour's perception, its
    first teaching world (its demonstrations), its other teaching worlds (corrective rounds
    there too: ``round_worlds``) and the fields its ``[recipe]`` table changes.

    ``paper``: the paper's scenario of that name as Table I was reproduced (``rhbl experiment
    --paper``): the recipe of ``RECIPES`` alone, in its one world; BehaviourError for a
    behaviour that is not one of the paper's two."""
    if paper:
        if b.name not in RECIPES:
            raise BehaviourError(f"{b.path or b.name}: not one of the paper's scenarios (--paper "
                                 f"goes with {' or '.join(RECIPES)})")
        return RECIPES[b.name]
    base = RECIPES.get(b.name) or RECIPES["wall-following"]
    changes = {"round_worlds": b.teach[1:], **OWN, **b.recipe}
    fields = {f.name for f in dataclasses.fields(Recipe)} - {"task", "world", "features"}
    for key, value in changes.items():
        if key not in fields:
            raise BehaviourError(f"{b.path or b.name}: field 'recipe.{key}': unknown; allowed: "
                                 f"{', '.join(sorted(fields))}")
        if isinstance(value, list):
            changes[key] = tuple(value)
    try:
        return base.replace(task=b.name, world=b.teach[0],
                            features=b.perception or b.features, **changes)
    except (TypeError, ValueError) as exc:
        raise BehaviourError(f"{b.path or b.name}: field 'recipe': {exc}") from None


def add_paper_argument(parser: argparse.ArgumentParser) -> None:
    """``--paper``: the paper's scenario instead of the behaviour's own recipe (``recipe_of``)."""
    parser.add_argument("--paper", action="store_true",
                        help="the paper's scenario as its Table I was reproduced (wall-following "
                             "and maze): the recipe and the one teaching world of lab.recipe."
                             "RECIPES, without the behaviour file's other teaching worlds and "
                             "[recipe] changes (randomised rooms, free-space poses)")


def behaviour_for_world(spec: WorldSpec, hint: str | None = None) -> Behaviour:
    """The behaviour of a world: the shipped behaviour that names it among its teaching or
    held-out worlds (``client.behaviour.spec.for_world``: when several do, the one that drives
    from the world's own start poses); when none does (or several), the one an older world
    file's ``task`` names, else the shipped behaviour ``hint`` names (``lab.evaluate``: the
    tree's own task); BehaviourError when none is left, or more than one (then
    ``--behaviour`` says which)."""
    return for_world(spec.name, spec.path, spec.task or hint)


# ------------------------------------------------------------------------------ the command


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("behaviour", nargs="?", default=None, type=behaviour_arg,
                        help="show this behaviour in full (a shipped behaviour's name or a "
                             "behaviour file); default: list the shipped ones")
    parser.add_argument("--json", default=None, type=arguments.output_file,
                        help="also write them (or it) in full as JSON: name, summary, "
                             "perception (the feature spec), expert, worlds, starts, success "
                             "rule, instructions, goals")


def to_dict(b: Behaviour) -> dict:
    """A behaviour as plain data (``--json``): what its file says, its perception as the
    feature spec it makes."""
    return {"name": b.name, "summary": b.summary, "file": str(b.path) if b.path else None,
            "perception": b.perception, "features": b.features.to_dict(),
            "expert": {"name": b.expert_name, **b.expert_params},
            "worlds": {"teach": list(b.teach), "held_out": list(b.held_out)},
            "starts": {w: [list(p) for p in poses] for w, poses in b.starts.items()},
            "success": b.rules, "instructions": b.instructions,
            "goals": None if b.goals is None else b.goals.to_dict()}


def _drawn(b: Behaviour) -> str:
    """", and N randomised rooms" when its recipe also teaches it in drawn worlds."""
    n = b.recipe.get("round_generated", 0)
    kind = {"clutter": "cluttered rooms"}.get(b.recipe.get("generator", "rooms"),
                                              b.recipe.get("generator", "rooms"))
    return f", and {n} randomised {kind} (lab.generated)" if n else ""


def describe(b: Behaviour) -> str:
    """A behaviour in full: its line, perception, expert, worlds, success rule, instructions."""
    rules = "; ".join(rule + (" " + ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                                               for k, v in p.items()) if p else "")
                      for rule, p in b.rules.items())
    expert = ", ".join(f"{k} {v}" for k, v in b.expert_params.items())
    lines = [f"{b.name}: {b.summary}",
             f"  file: {b.path}" if b.path else "",
             f"  perception: {b.perception or 'inline'} ({b.features.dim} inputs)",
             f"  expert: {b.expert_name}" + (f" ({expert})" if expert else ""),
             f"  taught in: {', '.join(b.teach)}" + _drawn(b),
             f"  held out: {', '.join(b.held_out) or 'none'}",
             f"  success: {rules}"]
    if b.goals is not None:
        g = b.goals
        order = " -> ".join(str(g.beacons[k]) for k in g.visits)
        lines.insert(4, f"  goals: beacons {order}" + (" (a cycle)" if g.cycle else "")
                     + f", each reached within {', '.join(f'{w:g}' for w in g.within)} m")
    if b.instructions:
        lines += ["  instructions:", *("    " + line for line in b.instructions.splitlines())]
    return "\n".join(line for line in lines if line)


def check(b: Behaviour) -> None:
    """What the file says beyond its own fields, checked as a command that uses it would: its
    recipe (``recipe_of``) and every world it names, loaded (BehaviourError or the world's
    ValueError, naming what was wrong)."""
    recipe_of(b)
    for field, worlds in (("teach", b.teach), ("held_out", b.held_out)):
        for w in worlds:
            try:
                spec = world_of(b, w)
                if "goal" in b.rules and spec.goal is None:
                    raise ValueError("it has no [goal], and the success rule asks for one")
                if b.goals is not None:  # every beacon the goals name stands in it
                    from lab.goals import targets

                    targets(spec, b)
            except BehaviourError:
                raise
            except ValueError as exc:
                raise BehaviourError(f"{b.path or b.name}: field 'worlds.{field}': world {w!r}: "
                                     f"{exc}") from None


def main(args) -> int:
    if args.behaviour is not None:
        chosen = [get(args.behaviour)]
        check(chosen[0])  # a file you wrote: its recipe and worlds too, before it is used
        print(describe(chosen[0]))
    else:
        chosen = list(shipped().values())
        width = max((len(b.name) for b in chosen), default=0)
        for b in chosen:
            print(f"{b.name:<{width}}  {b.summary}")
    if args.json:
        files.write_text(args.json, json.dumps([to_dict(b) for b in chosen], indent=1), "--json")
    return 0
