"""The simulator server: world files, pymunk physics, laser, odometry (``server.world``), command
arbitration (``server.arbiter``) and the zenoh node (``server.node``, ``rhbl server``).

``import server`` stays light (no pymunk, no zenoh); see docs/architecture.md.
"""

from __future__ import annotations

from pathlib import Path

from process.arguments import Checked

__all__ = ["world_arg", "world_names", "world_path", "worlds_dir"]


def worlds_dir() -> Path:
    """The folder of the shipped worlds (``server/worlds``)."""
    return Path(__file__).resolve().parent / "worlds"


def world_names() -> list[str]:
    """Names of the shipped worlds (``room``, ``maze``, ...)."""
    return sorted(p.stem for p in worlds_dir().glob("*.toml"))


def world_path(name: str | Path) -> Path:
    """Resolve a world: an existing path, or a shipped world's name (``room``/``room.toml``)."""
    p = Path(name)
    if p.is_file():
        return p
    stem = p.name[:-5] if p.name.endswith(".toml") else p.name
    shipped = worlds_dir() / f"{stem}.toml"
    if p.parent == Path(".") and shipped.is_file():
        return shipped
    raise FileNotFoundError(
        f"world {str(name)!r} is neither a file nor a shipped world (one of {world_names()})"
    )


def _world(text: str) -> str:
    from process.arguments import files_checked

    if not files_checked() and "/" in text:  # a path on another machine (syntax_only)
        return text
    try:
        world_path(text)
    except FileNotFoundError as exc:
        raise ValueError(str(exc)) from None
    return text


# ``--world FILE|NAME`` (argparse type: a regular file or a shipped world's name)
world_arg = Checked("world", _world)
world_arg.kind, world_arg.example = "world", "room"
