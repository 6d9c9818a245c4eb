"""The discrete action set: the paper's five primitive behaviours, each a (vx, va) pair.

The robot never stands still (paper, section 6.1): every action moves or turns it.

    actions = DEFAULT_ACTIONS
    actions.names                 -> ("fwd", "fwd-left", "rot-left", "fwd-right", "rot-right")
    actions["fwd-left"]           -> (vx m/s, va rad/s)
    actions.mirror("fwd-left")    -> "fwd-right"   (left/right swapped; used by mirrored policies)
    ActionSet.from_dict(actions.to_dict()) == actions   (stored in every snapshot's metadata)
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

__all__ = ["ActionSet", "ActionError", "DEFAULT_ACTIONS", "MIRROR"]


class ActionError(ValueError):
    """An unknown action name or a malformed action set."""


# left <-> right pairs of the default names
MIRROR = {
    "fwd": "fwd",
    "fwd-left": "fwd-right",
    "fwd-right": "fwd-left",
    "rot-left": "rot-right",
    "rot-right": "rot-left",
}


@dataclass(frozen=True)
class ActionSet(Mapping[str, tuple[float, float]]):
    """An ordered, immutable map ``name -> (vx, va)`` (m/s, rad/s; va > 0 turns left)."""

    items_: tuple[tuple[str, tuple[float, float]], ...]

    def __init__(self, actions: Mapping[str, tuple[float, float]] | None = None, **kw):
        pairs = dict(actions or {}, **kw)
        if not pairs:
            raise ActionError("an action set needs at least one action")
        clean: list[tuple[str, tuple[float, float]]] = []
        for name, vel in pairs.items():
            if not isinstance(name, str) or not name:
                raise ActionError(f"action names must be non-empty strings, got {name!r}")
            try:
                vx, va = (float(v) for v in vel)
            except (TypeError, ValueError) as exc:
                raise ActionError(f"action {name!r} must be a (vx, va) pair, got {vel!r}") from exc
            if vx == 0.0 and va == 0.0:
                raise ActionError(f"action {name!r} stands still; the robot must never stand still")
            clean.append((name, (vx, va)))
        object.__setattr__(self, "items_", tuple(clean))

    # Mapping protocol
    def __getitem__(self, name: str) -> tuple[float, float]:
        for n, v in self.items_:
            if n == name:
                return v
        raise ActionError(f"unknown action {name!r}; known: {', '.join(self.names)}")

    def __iter__(self) -> Iterator[str]:
        return (n for n, _ in self.items_)

    def __len__(self) -> int:
        return len(self.items_)

    def __contains__(self, name: object) -> bool:
        return any(n == name for n, _ in self.items_)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.items_)

    def velocity(self, name: str) -> tuple[float, float]:
        """(vx, va) of an action; ActionError names the unknown action."""
        return self[name]

    def mirror(self, name: str) -> str:
        """The left/right mirror image of an action (itself when it has none in this set)."""
        other = MIRROR.get(name, name)
        return other if other in self else name

    def to_dict(self) -> dict:
        return {"names": list(self.names), "velocities": [list(v) for _, v in self.items_]}

    @classmethod
    def from_dict(cls, data: Mapping) -> ActionSet:
        try:
            names, vels = data["names"], data["velocities"]
        except (KeyError, TypeError) as exc:
            raise ActionError(f"an action set dict needs 'names' and 'velocities', got {data!r}") from exc
        if len(names) != len(vels):
            raise ActionError("action set dict: 'names' and 'velocities' differ in length")
        return cls(dict(zip(names, (tuple(v) for v in vels), strict=True)))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ActionSet) and self.items_ == other.items_

    def __hash__(self) -> int:
        return hash(self.items_)

    def __repr__(self) -> str:
        inner = ", ".join(f"{n!r}: ({vx:g}, {va:g})" for n, (vx, va) in self.items_)
        return f"ActionSet({{{inner}}})"


# Speeds well inside the Pioneer limits (0.5 m/s, 100 deg/s). The first action is the
# classifier's default label (the paper's root hypersphere is labelled "forward").
DEFAULT_ACTIONS = ActionSet(
    {
        "fwd": (0.4, 0.0),
        "fwd-left": (0.25, 0.6),
        "rot-left": (0.0, 0.8),
        "fwd-right": (0.25, -0.6),
        "rot-right": (0.0, -0.8),
    }
)
