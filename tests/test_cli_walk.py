"""Every option of every ``rhbl`` command, walked with hostile values made from its parser.

For each option that takes a value, the values come from its argparse ``type`` (a
``protocol.arguments.Checked``: its ``kind`` and, for numbers, its range) or its ``choices``
(``campaigns.fuzz.cli_hostile``): negative, zero, NaN, infinities, huge, empty, not a number;
a FIFO, a character device, a folder, a missing file, a path under a regular file; wildcards
and separators in a name; bad endpoints, addresses and origins. Each must be refused by the
parser (before ``main`` runs, so before any work or connection) with one line naming the
option, exit 2, no traceback. A new option is walked as soon as it exists; one without a
checked type (or choices) fails the first test. A subprocess per command then checks the same
end to end, with a bounded timeout (no hang).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from campaigns.fuzz import (
    cli_base_argv,
    cli_hostile,
    cli_parse,
    cli_places,
    cli_refusal,
    option_name,
    value_actions,
)
from lab.cli import COMMANDS, build_parser
from protocol.arguments import Checked, Number

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict[str, str]:
    return cli_places(tmp_path_factory.mktemp("walk"))


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_has_a_checked_type_or_choices(command):
    loose = [option_name(a) for a in value_actions(build_parser(command))
             if not isinstance(a.type, Checked) and not a.choices]
    assert loose == [], (f"rhbl {command}: give these a type from protocol.arguments (or "
                         f"choices): {loose}")


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_refuses_hostile_values_in_one_line(command, places):
    parser = build_parser(command)
    code, err = cli_parse(parser, cli_base_argv(parser, None, places))
    assert code is None, f"rhbl {command}: its valid example arguments are refused: {err}"
    walked = 0
    for action in value_actions(parser):
        values = cli_hostile(action, places)
        assert values, f"rhbl {command} {option_name(action)}: no hostile value"
        for value in values:
            wrong = cli_refusal(command, action, value, parser, places)
            assert wrong is None, wrong
            walked += 1
    assert walked >= len(value_actions(parser))


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_hostile_value_exits_2_in_one_line_end_to_end(command, places):
    """The real ``rhbl``: a NaN in the command's first number option, or a FIFO as its first
    path, is one line and exit 2 in a bounded time, nothing connected (no router runs)."""
    parser = build_parser(command)
    action = next((a for a in value_actions(parser) if isinstance(a.type, Number)), None)
    value = "nan"
    if action is None:
        action = next(a for a in value_actions(parser)
                      if getattr(a.type, "kind", "") in ("input", "output"))
        value = places["fifo"]
    argv = cli_base_argv(parser, action, places)
    argv += [f"{action.option_strings[-1]}={value}"] if action.option_strings else ["--", value]
    connect = any("--connect" in a.option_strings for a in parser._actions)
    r = subprocess.run([sys.executable, "-m", "lab.cli", command, *argv,
                        *(["--connect", "tcp/127.0.0.1:9"] if connect else [])],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and option_name(action) in lines[0], r.stderr
    assert "Traceback" not in r.stderr
