"""Behaviour files (client.behaviour.spec): the shipped ones, the format's checks, one line
naming the file, the field and what was allowed for every malformed file."""

from __future__ import annotations

import pytest

from client.behaviour.features import FEATURES
from client.behaviour.policies import ReactiveFollower, ReactiveMazeTeacher, WallFollower
from client.behaviour.spec import (
    RULES,
    BehaviourError,
    behaviour,
    load_behaviour,
    parse_behaviour,
    shipped,
)

GOOD = """
name = "mine"
summary = "a behaviour of my own"
perception = "wall"
instructions = "drive about"
[expert]
name = "wall-follower"
side = "left"
target = 0.7
[worlds]
teach = ["room"]
held_out = ["eval-room-l", "my/world.toml"]
[starts]
room = [[1.9, 2.5, 1.5708]]
[success]
time-limit = { seconds = 60 }
no-collision = {}
wall-band = { side = "left", fraction = 0.5 }
"""


def write(tmp_path, text: str, name: str = "mine.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_the_shipped_behaviours_are_todays_two_tasks():
    known = shipped()
    assert {"wall-following", "maze"} <= set(known)
    wall, maze = known["wall-following"], known["maze"]
    assert wall.features == FEATURES["wall"] and wall.perception == "wall"
    assert wall.teach == ("room",) and wall.held_out == (
        "eval-room-jagged", "eval-room-l", "eval-room-ring")
    assert wall.rules["wall-band"] == {"side": "right", "near": 0.3, "far": 1.2, "fraction": 0.8}
    assert wall.rules["distance"]["of_teacher"] == 0.7 and wall.seconds == 120.0
    assert wall.band_side == "right" and maze.band_side is None
    assert maze.seconds == 240.0 and set(maze.rules) == {"time-limit", "no-collision", "goal"}
    assert maze.teach == ("maze",) and maze.held_out == (
        "eval-maze-3tier", "eval-maze-5tier", "eval-maze-narrow")
    assert type(wall.expert()) is ReactiveFollower and type(maze.expert()) is ReactiveMazeTeacher
    assert type(wall.expert("smooth")) is WallFollower
    for b in known.values():
        assert b.summary and "\n" not in b.summary and b.instructions
    assert behaviour("maze") is maze


def test_a_users_file_anywhere(tmp_path):
    p = write(tmp_path, GOOD)
    b = behaviour(str(p))
    assert b == load_behaviour(p) and b.path == p.resolve() and b.name == "mine"
    expert = b.expert()
    assert expert.side == "left" and expert.target == 0.7
    assert b.held_out == ("eval-room-l", str(tmp_path / "my" / "world.toml"))  # from its folder
    assert b.starts == {"room": ((1.9, 2.5, 1.5708),)}
    assert b.rules["wall-band"] == dict(RULES["wall-band"], side="left", fraction=0.5)
    assert b.seconds == 60.0 and b.instructions == "drive about"
    assert b.expert("smooth").side == "left"  # both styles take side and target
    band = behaviour(write(tmp_path, GOOD.replace("target = 0.7", "band = 0.1"), "band.toml"))
    assert band.expert().band == 0.1
    with pytest.raises(ValueError, match="the smooth wall-follower expert takes no band"):
        band.expert("smooth")


def test_inline_perception_beams_or_sectors_reuses_the_feature_spec(tmp_path):
    text = GOOD.replace('perception = "wall"\n', "")
    b = behaviour(write(tmp_path, text + '[perception]\nbeams = [0, 45, 90, 135, 180]\n'
                                          'window = 5\ninputs = ["heading"]\n'))
    assert b.features.beams == (0.0, 45.0, 90.0, 135.0, 180.0) and b.features.window == 5.0
    assert b.features.heading == "lr" and b.features.dim == 6 and b.perception is None
    b = behaviour(write(tmp_path, text + "[perception]\nsectors = 6\nclamp = 1.5\n", "s.toml"))
    assert b.features.beams == (15.0, 45.0, 75.0, 105.0, 135.0, 165.0)
    assert b.features.window == 15.0 and b.features.clamp == 1.5


@pytest.mark.parametrize(("change", "field", "allowed"), [
    (('instructions = "drive about"', 'colour = "red"'), "colour",
     "allowed: expert, goals, guard, instructions"),
    (('name = "mine"', "name = 3"), "name", "a non-empty string"),
    (('perception = "wall"', 'perception = "sonar"'), "perception", "a shipped feature spec"),
    (('side = "left"', 'side = "up"'), "expert.side", "one of right, left"),
    (('target = 0.7', 'wings = 2'), "expert.wings", "allowed:"),
    (('target = 0.7', 'target = "far"'), "expert.target", "a finite number"),
    (('name = "wall-follower"', 'name = "dancer"'), "expert.name", "one of wall-follower, maze"),
    (('teach = ["room"]', "teach = []"), "worlds.teach", "a non-empty list"),
    (('held_out = ["eval-room-l", "my/world.toml"]', 'held_out = "eval-room-l"'),
     "worlds.held_out", "a list of world names"),
    (("room = [[1.9, 2.5, 1.5708]]", "room = [[1.9, 2.5]]"), "starts.room[0]", "[x, y, yaw]"),
    (("room = [[1.9, 2.5, 1.5708]]", "maze = [[1, 1, 0]]"), "starts.maze", "a world the behaviour"),
    (("no-collision = {}", "dance = {}"), "success.dance", "unknown rule; allowed: time-limit"),
    (('side = "left", fraction = 0.5', 'side = "left", fraction = 1.5'),
     "success.wall-band.fraction", "a fraction in [0, 1]"),
    (('side = "left", fraction = 0.5', 'side = "left", width = 1'), "success.wall-band.width",
     "allowed: far, fraction, near, side"),
    (("seconds = 60", "seconds = -1"), "success.time-limit.seconds", "a number > 0"),
    (("no-collision = {}", "no-collision = true"), "success.no-collision", "a table"),
    (("[success]", "[succes]"), "succes", "allowed:"),
])
def test_a_malformed_file_is_one_line_naming_file_field_and_what_was_allowed(
        tmp_path, change, field, allowed):
    old, new = change
    assert old in GOOD
    p = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(BehaviourError) as exc:
        load_behaviour(p)
    message = str(exc.value)
    assert "\n" not in message
    assert message.startswith(f"{p}: field '{field}'"), message
    assert allowed in message, message


def test_missing_fields_bad_toml_and_unknown_names(tmp_path):
    with pytest.raises(BehaviourError, match="field 'success': missing"):
        parse_behaviour({k: v for k, v in _good().items() if k != "success"}, "x.toml")
    with pytest.raises(BehaviourError, match="inline.toml: field 'perception': expected exactly "
                                             "one of 'beams'"):
        parse_behaviour(dict(_good(), perception={"window": 3}), "inline.toml")
    with pytest.raises(BehaviourError, match="beam 200.0 deg outside"):
        parse_behaviour(dict(_good(), perception={"beams": [0, 200]}), "inline.toml")
    with pytest.raises(BehaviourError, match="not valid TOML"):
        load_behaviour(write(tmp_path, "name = = 1"))
    with pytest.raises(BehaviourError, match="neither a shipped behaviour .*wall-following"):
        behaviour("no-such-behaviour")


def _good() -> dict:
    import tomllib

    return tomllib.loads(GOOD)


def test_a_behaviour_can_turn_the_controllers_guard_off(tmp_path):
    """``guard = false``: its trees' learning rule records the guard off (``rhbl learner
    --behaviour``), so the controller drives the tree's answers as they are."""
    import argparse

    from client.roles.learner import guard_of

    assert behaviour(str(write(tmp_path, GOOD))).guard is True
    off = write(tmp_path, 'guard = false\n' + GOOD, "off.toml")
    assert behaviour(str(off)).guard is False
    assert guard_of(argparse.Namespace(behaviour=str(off))) is False
    assert guard_of(argparse.Namespace(behaviour=None)) is None
    with pytest.raises(BehaviourError, match="guard"):
        behaviour(str(write(tmp_path, 'guard = "no"\n' + GOOD, "bad.toml")))
