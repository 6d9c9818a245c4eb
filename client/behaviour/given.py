"""A behaviour as the processes are given one: ``--behaviour NAME|FILE`` (a shipped behaviour's
name or a behaviour file's path) and its success rule in words, for a person.

    parser.add_argument("--behaviour", type=behaviour_arg)   # checked: one line if it is bad
    b = behaviour(args.behaviour)                            # client.behaviour.spec.Behaviour
    rule_words(b)                                            # "no collision; the wall on ..."
    as_argument(b)                                           # what to pass a child process
    behaviour_of_world("room", task)                         # a world's shipped behaviour
    to_page(b)                                               # what the console's page shows

The roles (``rhbl teacher``, ``rhbl learner``, ``rhbl console``) and ``lab`` use the same
argument type, so a behaviour is named the same way everywhere.
"""

from __future__ import annotations

from process.arguments import Checked, files_checked

from .spec import RULES, Behaviour, BehaviourError, behaviour, for_world, shipped

__all__ = ["as_argument", "behaviour_arg", "behaviour_of_world", "rule_words", "to_page"]


def _check(text: str) -> str:
    if not files_checked() and text not in shipped() and ("/" in text or text.endswith(".toml")):
        return text  # a path on another machine (a compose file's): checked there
    behaviour(text)  # BehaviourError (a ValueError): one line naming the file, field, allowed
    return text


# ``--behaviour NAME|FILE`` (argparse type: a shipped behaviour's name or a behaviour file)
behaviour_arg = Checked("behaviour", _check)
# (a shipped name or a regular file, as a world is: the CLI walk tries the same hostile values)
behaviour_arg.kind, behaviour_arg.example = "world", "wall-following"


def as_argument(b: Behaviour) -> str:
    """What names ``b`` to a child process's ``--behaviour``: a shipped behaviour's name, else
    its file's path (a behaviour made in code has none: its name)."""
    known = shipped().get(b.name)
    if b.path is None or (known is not None and known.path == b.path):
        return b.name
    return str(b.path)


def _num(v) -> str:
    return f"{v:g}"


def _rule(rule: str, p: dict) -> str:
    if rule == "time-limit":
        return f"each start is driven {_num(p['seconds'])} s"
    if rule == "no-collision":
        return "no collision"
    if rule == "distance":
        parts = []
        if p["metres"] > 0:
            parts.append(f"at least {_num(p['metres'])} m")
        if p["of_teacher"] > 0:
            parts.append(f"at least {p['of_teacher'] * 100:.0f}% of the teacher's distance "
                         "from the same start")
        return "driven " + (" and ".join(parts) if parts else "any distance")
    if rule == "progress":
        return (f"at least {_num(p['metres'])} m of progress in every {_num(p['window'])} s "
                "(never stuck)")
    if rule == "wall-band":
        return (f"the wall on the {p['side']} within {_num(p['near'])}-{_num(p['far'])} m "
                f"for {p['fraction'] * 100:.0f}% of the time")
    if rule == "centred":
        return (f"the walls left and right within {_num(p['tolerance'])} m of each other for "
                f"{p['fraction'] * 100:.0f}% of the time")
    if rule == "goal":
        return "the goal reached"
    if rule == "coverage":
        return f"at least {_num(p['area'])} m\u00b2 covered (cells of {_num(p['cell'])} m)"
    if rule == "goals":
        return (f"the goals reached in their order (each within its distance + "
                f"{_num(p['slack'])} m of its beacon)")
    raise ValueError(f"no success rule {rule!r}; known: {', '.join(RULES)}")


def rule_words(b: Behaviour) -> str:
    """The behaviour's success rule in words, every part of which must hold ("; " between)."""
    return "; ".join(_rule(rule, p) for rule, p in b.rules.items())


def behaviour_of_world(world: str, task: str | None = None) -> Behaviour | None:
    """The shipped behaviour of a world as a server tells it (``get_world``: its name, and the
    task an old world file may still name, a hint): ``client.behaviour.spec.for_world``; None
    when no shipped behaviour names it, or several do (then the process is told which)."""
    try:
        return for_world(world, task=task or None)
    except BehaviourError:
        return None


def to_page(b: Behaviour) -> dict:
    """What a person is shown of a behaviour: its name, summary, instructions and success rule
    in words (the console's page)."""
    return {"name": b.name, "summary": b.summary, "instructions": b.instructions,
            "rule": rule_words(b), "file": None if b.path is None else str(b.path)}
