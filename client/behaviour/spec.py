"""Behaviour files: what a robot is taught, as data (TOML), and their one parser.

    b = behaviour("wall-following")        # a shipped behaviour's name, or a behaviour file's path
    b.name, b.summary, b.instructions       # what it is, in one line and for a person teaching it
    b.features                              # its perception (a client.behaviour.features.FeatureSpec)
    b.expert("reactive", actions)           # its scripted expert, with the file's parameters
    b.teach, b.held_out                     # the worlds it is taught in and evaluated in (names or paths)
    b.starts                                # its own start poses per world (name -> poses), if any
    b.rules                                 # its success rule: {"no-collision": {}, "wall-band": {...}}
    shipped()                               # every shipped behaviour, by name
    for_world("room")                       # the shipped behaviour of a world (worlds name none)

A behaviour file (docs/behaviours.md is the format with an example):

    name = "wall-following"
    summary = "follow the wall on the robot's right"
    perception = "wall"                     # a shipped feature spec, or a [perception] table
    instructions = "hold the arrow keys ..."
    [expert]
    name = "wall-follower"                  # as ``rhbl teacher --policy`` names it
    side = "right"                          # and any other parameter of its constructor
    [worlds]
    teach = ["room"]
    held_out = ["eval-room-jagged", "eval-room-l"]
    [starts]                                # optional: start poses of a world, instead of its own
    room = [[3.0, 0.7, 0.0]]
    guard = false                           # optional: no controller's guard (default true)
    [success]                               # every rule given must hold
    time-limit = { seconds = 120 }
    no-collision = {}
    wall-band = { side = "right" }

The parser is pure (no zenoh, no simulator): it checks every field and names, in one line, the
file, the field and what was allowed (``BehaviourError``, a ValueError). World names are kept as
written (a path relative to the behaviour file's folder is made absolute); ``lab`` resolves them.
The shipped behaviours are the ``*.toml`` files of the folder ``shipped/`` beside this module.
"""

from __future__ import annotations

import functools
import inspect
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .actions import DEFAULT_ACTIONS, ActionSet
from .features import BEACON_GOAL, FEATURES, FeatureError, FeatureSpec
from .goals import Goals, parse_goals
from .policies import STYLES, Policy
from .tasks import TASKS

__all__ = [
    "RULES",
    "Behaviour",
    "BehaviourError",
    "behaviour",
    "behaviour_names",
    "for_world",
    "load_behaviour",
    "parse_behaviour",
    "shipped",
    "shipped_dir",
]


class BehaviourError(ValueError):
    """A malformed behaviour file, or a behaviour that is not there."""


# The success vocabulary: rule -> {parameter: default} (None: required). Every rule a file gives
# must hold for an episode to succeed (lab.metrics.judge evaluates them); the parameters a rule
# leaves out take these defaults.
RULES: dict[str, dict[str, Any]] = {
    # the episode's length in sim seconds (how long the robot is driven from each start)
    "time-limit": {"seconds": 120.0},
    # no stall onset (before the goal, when the world has one and it was reached)
    "no-collision": {},
    # metres travelled: at least ``metres``, and at least ``of_teacher`` times the scripted
    # expert's from the same start (0: not compared)
    "distance": {"metres": 0.0, "of_teacher": 0.0},
    # never less than ``metres`` of progress from where any ``window`` seconds began
    "progress": {"window": 30.0, "metres": 0.5},
    # the nearest wall on ``side`` within [near, far] metres for at least ``fraction`` of the time
    "wall-band": {"side": "right", "near": 0.3, "far": 1.2, "fraction": 0.8},
    # the nearest walls on the left and on the right within ``tolerance`` metres of each other
    # for at least ``fraction`` of the time
    "centred": {"tolerance": 0.3, "fraction": 0.8},
    # the world's goal region ([goal] of the world file) reached within the time limit
    "goal": {},
    # at least ``area`` square metres covered: the cells of ``cell`` metres the robot entered
    "coverage": {"cell": 0.5, "area": 10.0},
    # the behaviour's [goals] reached in their order (each within its distance of its beacon,
    # plus ``slack`` metres), judged from the robot's true path
    "goals": {"slack": 0.1},
}
SIDES = ("right", "left")
INPUTS = {"heading": "lr"}  # extra perception inputs -> FeatureSpec.heading
_TOP = {"name", "summary", "perception", "instructions", "expert", "worlds", "starts", "success",
        "recipe", "goals", "guard"}
_PERCEPTION = {"beams", "sectors", "window", "clamp", "scale", "fov", "inputs", "beacon",
               "beacon_range", "beacon_bearing"}
_WORLDS = {"teach", "held_out"}


def _where(src: str, key: str) -> str:
    return f"{src}: field '{key}'"


def _err(src: str, key: str, expected: str, got: Any) -> BehaviourError:
    return BehaviourError(f"{_where(src, key)}: expected {expected}, got {got!r}")


def _unknown(src: str, table: str, got: Mapping, allowed) -> None:
    extra = sorted(set(got) - set(allowed))
    if extra:
        key = f"{table}.{extra[0]}" if table else extra[0]
        raise BehaviourError(f"{_where(src, key)}: unknown; allowed: {', '.join(sorted(allowed))}")


def _str(src: str, key: str, v: Any) -> str:
    if not isinstance(v, str) or not v.strip():
        raise _err(src, key, "a non-empty string", v)
    return v


def _number(src: str, key: str, v: Any, low: float = -math.inf, what: str = "a finite number"
            ) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < low:
        raise _err(src, key, what, v)
    return float(v)


def _table(src: str, key: str, v: Any) -> dict:
    if not isinstance(v, dict):
        raise _err(src, key, "a table", v)
    return v


@dataclass(frozen=True)
class Behaviour:
    """One behaviour, as its file says (see the module's doc). ``expert_params`` are the
    keyword arguments of its scripted expert, ``recipe`` the training recipe's fields it
    changes (``lab.recipe``), ``path`` its file (None: made in code)."""

    name: str
    summary: str
    features: FeatureSpec
    expert_name: str
    teach: tuple[str, ...]
    held_out: tuple[str, ...] = ()
    rules: dict[str, dict[str, Any]] = field(default_factory=dict, compare=False)
    expert_params: dict[str, Any] = field(default_factory=dict, compare=False)
    starts: dict[str, tuple[tuple[float, float, float], ...]] = field(default_factory=dict,
                                                                       compare=False)
    instructions: str = ""
    perception: str | None = None  # the shipped feature spec's name, None when inline
    recipe: dict[str, Any] = field(default_factory=dict, compare=False)
    path: Path | None = None
    goals: Goals | None = None  # its goals in order ([goals]; client.behaviour.goals), if any
    guard: bool = True  # the controller's guard (a safety layer) on for its trees; false: off

    @property
    def seconds(self) -> float:
        """Sim seconds of one evaluation episode (the ``time-limit`` rule)."""
        return float(self.rules.get("time-limit", RULES["time-limit"])["seconds"])

    @property
    def band_side(self) -> str | None:
        """The side whose wall distance is measured (the ``wall-band`` rule's), or None."""
        band = self.rules.get("wall-band")
        return None if band is None else band["side"]

    @property
    def worlds(self) -> tuple[str, ...]:
        """Every world it names: the teaching worlds, then the held-out ones."""
        return (*self.teach, *self.held_out)

    def expert(self, style: str = "reactive", actions: ActionSet = DEFAULT_ACTIONS,
               **kw) -> Policy:
        """Its scripted expert of ``style`` ("reactive" or "smooth") with the file's parameters
        (``kw`` added on top)."""
        if style not in STYLES:
            raise ValueError(f"teacher style must be one of {STYLES}, got {style!r}")
        params = {**self.expert_params, **kw}
        cls = _expert_task(self.expert_name).expert(style)
        extra = sorted(set(self.expert_params) - _parameters(cls))
        if extra:
            raise ValueError(f"behaviour {self.name!r}: the {style} {self.expert_name} expert "
                             f"takes no {', '.join(extra)} (the file's [expert] parameters are "
                             "the reactive expert's)")
        return cls(actions=actions, **params)


def _expert_task(name: str):
    return next(t for t in TASKS.values() if t.teacher == name)


def _parameters(cls: type) -> set[str]:
    """The keyword parameters an expert's constructor takes (a maze expert's and its base's:
    it passes ``**kw`` on), but ``actions`` and ``features``, which are not the file's."""
    out: set[str] = set()
    for c in cls.__mro__[:2]:
        if c is not Policy and c is not object:
            out |= {p for p in inspect.signature(c.__init__).parameters
                    if p not in ("self", "actions", "features", "kw")}
    return out


def _perception(src: str, v: Any) -> tuple[FeatureSpec, str | None]:
    """A shipped spec's name, or an inline table (beams or sectors, window, clamp, scale, fov,
    inputs, beacon, beacon_range) made into a FeatureSpec by its own checks."""
    if isinstance(v, str):
        if v not in FEATURES:
            raise _err(src, "perception", f"a shipped feature spec ({', '.join(FEATURES)}) or a "
                                          "[perception] table", v)
        return FEATURES[v], v
    t = _table(src, "perception", v)
    _unknown(src, "perception", t, _PERCEPTION)
    fov = _number(src, "perception.fov", t.get("fov", 180.0), 1e-9, "a number > 0 (degrees)")
    if ("beams" in t) == ("sectors" in t):
        raise BehaviourError(f"{_where(src, 'perception')}: expected exactly one of 'beams' (a "
                             "list of degrees from the scan's right edge) or 'sectors' (a count)"
                             f", got {sorted(k for k in ('beams', 'sectors') if k in t) or 'none'}")
    window = _number(src, "perception.window", t.get("window", 0.0), 0.0, "a number >= 0 "
                     "(degrees)")
    if "sectors" in t:
        n = t["sectors"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 360:
            raise _err(src, "perception.sectors", "an integer from 1 to 360", n)
        width = fov / n  # each sector's minimum: a beam at its centre, a window of half its width
        beams = tuple(width * (i + 0.5) for i in range(n))
        if "window" in t:
            raise BehaviourError(f"{_where(src, 'perception.window')}: not with 'sectors' (each "
                                 "sector's window is half its width)")
        window = width / 2.0
    else:
        raw = t["beams"]
        if not isinstance(raw, list) or not raw:
            raise _err(src, "perception.beams", "a non-empty list of degrees", raw)
        beams = tuple(_number(src, f"perception.beams[{i}]", b) for i, b in enumerate(raw))
    inputs = t.get("inputs", [])
    if not isinstance(inputs, list) or any(i not in INPUTS for i in inputs) \
            or len(set(inputs)) != len(inputs):
        raise _err(src, "perception.inputs", f"a list of distinct extra inputs from "
                                             f"{list(INPUTS)}", inputs)
    # the fiducial finder's view of one beacon: its id, or "goal" (the current goal's beacon)
    beacon = t.get("beacon")
    if beacon is not None and beacon != BEACON_GOAL and (
            isinstance(beacon, bool) or not isinstance(beacon, int) or beacon < 1):
        raise _err(src, "perception.beacon", f"a beacon id (an integer >= 1) or "
                                             f"{BEACON_GOAL!r}", beacon)
    for key in ("beacon_range", "beacon_bearing"):
        if key in t and beacon is None:
            raise BehaviourError(f"{_where(src, f'perception.{key}')}: only with 'beacon'")
    try:
        spec = FeatureSpec(beams=beams, window=window, fov=fov,
                           clamp=_number(src, "perception.clamp", t.get("clamp", 2.0)),
                           scale=_number(src, "perception.scale", t.get("scale", 2.0)),
                           heading=INPUTS[inputs[0]] if inputs else None, beacon=beacon,
                           beacon_range=_number(src, "perception.beacon_range",
                                                t.get("beacon_range", 8.0), 1e-9,
                                                "a number > 0 (m)"),
                           beacon_bearing=_number(src, "perception.beacon_bearing",
                                                  t.get("beacon_bearing", 180.0), 1e-9,
                                                  "a number of degrees in (0, 180]"))
    except FeatureError as exc:
        raise BehaviourError(f"{_where(src, 'perception')}: {exc}") from None
    return spec, None


def _expert(src: str, v: Any) -> tuple[str, dict]:
    """The expert's name and parameters, checked against its classes' constructors (an
    unknown parameter or a value the expert refuses is named)."""
    t = _table(src, "expert", v)
    names = [task.teacher for task in TASKS.values()]
    name = t.get("name")
    if name not in names:
        raise _err(src, "expert.name", f"one of {', '.join(names)}", name)
    params = {k: p for k, p in t.items() if k != "name"}
    task = _expert_task(name)
    _unknown(src, "expert", params, _parameters(task.reactive) | {"name"})
    for k, p in params.items():
        if k == "side":
            if p not in SIDES:
                raise _err(src, "expert.side", f"one of {', '.join(SIDES)}", p)
        elif isinstance(p, bool) or not isinstance(p, int | float) or not math.isfinite(p):
            raise _err(src, f"expert.{k}", "a finite number", p)
    try:  # the expert itself checks what it is given (as it will be built)
        task.reactive(actions=DEFAULT_ACTIONS, **params)
    except (TypeError, ValueError) as exc:
        raise BehaviourError(f"{_where(src, 'expert')}: {' '.join(str(exc).split())}") from None
    return name, params


def _worlds(src: str, v: Any, folder: Path | None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    t = _table(src, "worlds", v)
    _unknown(src, "worlds", t, _WORLDS)
    out = []
    for key in ("teach", "held_out"):
        raw = t.get(key, [])
        if key == "teach" and not raw:
            raise _err(src, "worlds.teach", "a non-empty list of world names or paths", raw)
        if not isinstance(raw, list):
            raise _err(src, f"worlds.{key}", "a list of world names or paths", raw)
        out.append(tuple(_world(_str(src, f"worlds.{key}[{i}]", w), folder)
                         for i, w in enumerate(raw)))
    return out[0], out[1]


def _world(text: str, folder: Path | None) -> str:
    """A world as written: a name stays a name; a path is made absolute from the file's folder."""
    if "/" not in text and not text.endswith(".toml"):
        return text
    p = Path(text).expanduser()
    if not p.is_absolute() and folder is not None:
        p = folder / p
    return str(p)


def _starts(src: str, v: Any, folder: Path | None) -> dict:
    t = _table(src, "starts", v)
    out = {}
    for world, poses in t.items():
        key = f"starts.{world}"
        if not isinstance(poses, list) or not poses:
            raise _err(src, key, "a non-empty list of [x, y, yaw] poses", poses)
        got = []
        for i, p in enumerate(poses):
            if not isinstance(p, list) or len(p) != 3:
                raise _err(src, f"{key}[{i}]", "[x, y, yaw] (m, m, rad)", p)
            got.append(tuple(_number(src, f"{key}[{i}][{j}]", x) for j, x in enumerate(p)))
        out[_world(world, folder)] = tuple(got)
    return out


def _rules(src: str, v: Any) -> dict[str, dict[str, Any]]:
    t = _table(src, "success", v)
    if not t:
        raise _err(src, "success", f"at least one rule of {', '.join(RULES)}", t)
    rules = {}
    for rule, params in t.items():
        if rule not in RULES:
            raise BehaviourError(f"{_where(src, f'success.{rule}')}: unknown rule; allowed: "
                                 f"{', '.join(RULES)}")
        params = _table(src, f"success.{rule}", params)
        _unknown(src, f"success.{rule}", params, RULES[rule])
        out = dict(RULES[rule])
        for k, p in params.items():
            key = f"success.{rule}.{k}"
            if k == "side":
                if p not in SIDES:
                    raise _err(src, key, f"one of {', '.join(SIDES)}", p)
                out[k] = p
            elif k == "fraction":
                out[k] = _number(src, key, p, 0.0, "a fraction in [0, 1]")
                if out[k] > 1:
                    raise _err(src, key, "a fraction in [0, 1]", p)
            elif k in ("seconds", "window", "cell"):
                out[k] = _number(src, key, p, 0.0, "a number > 0")
                if out[k] == 0:
                    raise _err(src, key, "a number > 0", p)
            else:
                out[k] = _number(src, key, p, 0.0, "a number >= 0")
        if rule == "wall-band" and out["near"] > out["far"]:
            raise _err(src, "success.wall-band", "near <= far", params)
        rules[rule] = out
    return rules


def parse_behaviour(data: Any, source: str = "<behaviour>", path: Path | None = None
                    ) -> Behaviour:
    """Check a behaviour mapping (as read from TOML) into a :class:`Behaviour`;
    ``BehaviourError`` naming ``source``, the field and what was allowed."""
    src = source
    if not isinstance(data, dict):
        raise _err(src, "<top>", "a table", data)
    _unknown(src, "", data, _TOP)
    for key in ("name", "summary", "perception", "expert", "worlds", "success"):
        if key not in data:
            raise BehaviourError(f"{_where(src, key)}: missing (a behaviour needs name, "
                                 "summary, perception, expert, worlds and success)")
    name = _str(src, "name", data["name"])
    if any(c.isspace() or c == "/" for c in name):
        raise _err(src, "name", "a name without spaces or '/'", name)
    summary = _str(src, "summary", data["summary"])
    if "\n" in summary.strip():
        raise _err(src, "summary", "one line", summary)
    instructions = data.get("instructions", "")
    if not isinstance(instructions, str):
        raise _err(src, "instructions", "a string", instructions)
    folder = path.parent if path is not None else None
    features, perception = _perception(src, data["perception"])
    expert, params = _expert(src, data["expert"])
    teach, held_out = _worlds(src, data["worlds"], folder)
    starts = _starts(src, data.get("starts", {}), folder)
    named = set(teach) | set(held_out)
    for world in starts:
        if world not in named:
            raise _err(src, f"starts.{world}", f"a world the behaviour names "
                                               f"({', '.join(sorted(named))})", world)
    recipe = _table(src, "recipe", data.get("recipe", {}))
    guard = data.get("guard", True)
    if not isinstance(guard, bool):
        raise _err(src, "guard", "true or false", guard)
    goals = None
    if "goals" in data:
        try:
            goals = parse_goals(data["goals"])
        except ValueError as exc:
            raise BehaviourError(f"{src}: {exc}") from None
    if goals is not None and features.beacon != BEACON_GOAL:
        raise _err(src, "perception.beacon", f"{BEACON_GOAL!r} (a behaviour with [goals] sees "
                                             "the current goal's beacon)", features.beacon)
    if goals is not None and expert != "beacon-seeker":
        raise _err(src, "expert.name", "beacon-seeker (the scripted teacher of goals in order)",
                   expert)
    rules = _rules(src, data["success"])
    if ("goals" in rules) != (goals is not None):
        raise BehaviourError(f"{_where(src, 'success.goals')}: a behaviour with [goals] is "
                             "judged by the 'goals' rule, and only such a one")
    return Behaviour(name=name, summary=summary.strip(), features=features, expert_name=expert,
                     teach=teach, held_out=held_out, rules=rules,
                     expert_params=params, starts=starts, instructions=instructions.strip(),
                     perception=perception, recipe=dict(recipe), path=path, goals=goals,
                     guard=guard)


def load_behaviour(path: str | Path) -> Behaviour:
    """Read and check a behaviour file; ``BehaviourError`` (or OSError) naming the file."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise BehaviourError(f"{p}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise BehaviourError(f"{p}: not valid TOML: {exc}") from None
    return parse_behaviour(data, str(p), p.resolve())


def shipped_dir() -> Path:
    """The folder of the shipped behaviours."""
    return Path(__file__).resolve().parent / "shipped"


@functools.cache
def shipped() -> dict[str, Behaviour]:
    """Every shipped behaviour by name, in the order of their names."""
    out = {}
    for p in sorted(shipped_dir().glob("*.toml")):
        b = load_behaviour(p)
        if b.name != p.stem:
            raise BehaviourError(f"{p}: field 'name': expected {p.stem!r} (a shipped behaviour "
                                 f"is named as its file), got {b.name!r}")
        out[b.name] = b
    return out


def behaviour_names() -> list[str]:
    """The shipped behaviours' names."""
    return list(shipped())


def behaviour(name_or_path: str | Path) -> Behaviour:
    """A shipped behaviour by name, or the behaviour file at a path (any ``.toml``, or any
    existing file); ``BehaviourError`` naming the shipped ones when it is neither."""
    text = str(name_or_path)
    known = shipped()
    if text in known:
        return known[text]
    p = Path(text)
    try:
        is_file = bool(text) and "\x00" not in text and p.is_file()
    except OSError:  # a name too long for a path, ...: not a file
        is_file = False
    if is_file:
        return load_behaviour(p)
    raise BehaviourError(f"behaviour {text!r} is neither a shipped behaviour ({', '.join(known)}) "
                         "nor a behaviour file")


def _names_world(named: str, name: str, path: Path | None) -> bool:
    """Whether a world as a behaviour names it (a name, or a path) is the world ``name`` (its
    file at ``path``, when known)."""
    if named == name:
        return True
    return path is not None and "/" in named and Path(named).resolve() == Path(path).resolve()


def for_world(name: str, path: str | Path | None = None, task: str | None = None,
              behaviours: Mapping[str, Behaviour] | None = None) -> Behaviour:
    """The shipped behaviour a world is taught or evaluated for. Worlds name no task: a
    behaviour names its worlds. The behaviours (default: the shipped ones) that name the world
    ``name`` (its file at ``path``) among their teaching or held-out worlds; when several do,
    those that drive from the world's own start poses (give no ``[starts]`` of their own for
    it: the world's poses were drawn for them; ``room``'s for ``wall-following``, not for
    ``left-wall``); when still several, or none, the one an old world file's ``task`` names (a
    hint only, so that such files keep working). BehaviourError when none or several remain
    (then ``--behaviour`` says which)."""
    known = shipped() if behaviours is None else behaviours
    naming = [b for b in known.values() if any(_names_world(w, name, path) for w in b.worlds)]
    if len(naming) > 1:
        own = [b for b in naming if not any(_names_world(w, name, path) for w in b.starts)]
        naming = own or naming
    if len(naming) != 1 and task is not None and task in known \
            and (not naming or known[task] in naming):
        return known[task]
    if len(naming) == 1:
        return naming[0]
    if naming:
        raise BehaviourError(f"world {name!r}: the behaviours {', '.join(b.name for b in naming)}"
                             " name it: say which with --behaviour NAME|FILE")
    raise BehaviourError(f"world {name!r}: no shipped behaviour names it: say which behaviour "
                         "with --behaviour NAME|FILE")
