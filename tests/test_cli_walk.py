"""Every option of every ``rhbl`` command, walked with hostile values made from its parser.

For each option that takes a value, the values come from its argparse ``type`` (a
``protocol.arguments.Checked``: its ``kind`` and, for numbers, its range) or its ``choices``:
negative, zero, NaN, infinities, huge, empty, not a number; a FIFO, a character device, a
folder, a missing file, a path under a regular file; wildcards and separators in a name; bad
endpoints and addresses. Each must be refused by the parser (before ``main`` runs, so before
any work or connection) with one line naming the option, exit 2, no traceback. A new option
is walked as soon as it exists; one without a checked type (or choices) fails the first test.
A subprocess per command then checks the same end to end, with a bounded timeout (no hang).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from lab.cli import COMMANDS, build_parser
from protocol.arguments import Checked, Number

ROOT = Path(__file__).resolve().parents[1]


def value_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions
            if a.nargs != 0 and not isinstance(a, argparse._HelpAction)
            and a.dest != "_main"]


def name_of(action: argparse.Action) -> str:
    return action.option_strings[-1] if action.option_strings else action.dest


@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("walk")
    (d / "file.json5").write_text("{}\n")  # a regular file (a valid zenoh config too)
    os.mkfifo(d / "fifo")
    (d / "folder").mkdir()
    os.symlink("/dev/null", d / "to-dev-null")
    return {"file": str(d / "file.json5"), "fifo": str(d / "fifo"), "folder": str(d / "folder"),
            "device": "/dev/null", "link": str(d / "to-dev-null"),
            "missing": str(d / "missing" / "x"), "under_file": str(d / "file.json5" / "x"),
            "new": str(d / "new" / "out.x"), "new_folder": str(d / "new-folder")}


def example(action: argparse.Action, places: dict[str, str]) -> str:
    """A valid value of ``action`` (for the options that must be given while another is
    walked)."""
    t = action.type
    if action.choices:
        return str(next(iter(action.choices)))
    kind = getattr(t, "kind", "text")
    return {"input": places["file"], "output": places["new"],
            "folder": places["new_folder"]}.get(kind, getattr(t, "example", "x"))


def _number_values(t: Number) -> list[str]:
    out = ["nan", "inf", "-inf", "1e999", "", "x", "1x"]
    for v in (-1, 0, 1e12):
        low_bad = t.low is not None and (v < t.low or (t.low_open and v == t.low))
        if low_bad or (t.high is not None and v > t.high):
            out.append(f"{v:g}" if t.cast is not int else str(int(v)))
    if t.cast is int:
        out.append("1.5")
    return out


def hostile(action: argparse.Action, places: dict[str, str]) -> list[str]:
    """The values ``action`` must refuse ("" is a value of a type whose ``empty_ok``)."""
    values = _hostile(action, places)
    return [v for v in values if v or not getattr(action.type, "empty_ok", False)]


def _hostile(action: argparse.Action, places: dict[str, str]) -> list[str]:
    t = action.type
    if action.choices and not isinstance(t, Checked):
        return ["not-a-choice", ""]
    kind = t.kind
    if isinstance(t, Number):
        return _number_values(t)
    if kind == "input":
        return ["", places["fifo"], places["device"], places["folder"], places["missing"],
                places["link"]]
    if kind == "output":
        return ["", places["fifo"], places["device"], places["folder"], places["link"],
                places["under_file"]]
    if kind == "folder":
        return ["", places["file"], places["fifo"], places["device"], places["under_file"]]
    if kind == "world":
        return ["", "no-such-world", places["fifo"], places["device"], places["folder"]]
    if kind == "chunk":
        return ["", "*", "**", "a/*", "r$*0", "r#0", "r?0", "a b", "a//b", "/a", "a/"]
    if kind == "host":
        return ["", "-x", "a b", "a/b"]
    if kind == "address":
        return ["", "nonsense", "127.0.0.1:99999", ":80", "127.0.0.1:-1", "a b:80"]
    if kind == "endpoint":
        return ["", "nonsense", "tcp/", "tcp/127.0.0.1:99999", "tcp/127.0.0.1", "/x"]
    if kind == "list":
        return ["x", "nan", "inf,1,0", "nan,nan,nan", "1e999"]
    return ["", "\x00", "a\nb", "x" * 1001]  # text, token


def base_argv(parser: argparse.ArgumentParser, skip: argparse.Action | None,
              places: dict[str, str]) -> list[str]:
    """The required options and positionals, with valid values (but ``skip``)."""
    argv, positionals = [], []
    required_groups = [g for g in parser._mutually_exclusive_groups if g.required]
    for a in value_actions(parser):
        if a is skip:
            continue
        if not a.option_strings:
            positionals.append(example(a, places))
        elif a.required:
            argv += [a.option_strings[-1], example(a, places)]
    for g in required_groups:
        if skip in g._group_actions:
            continue
        first = g._group_actions[0]
        argv += [first.option_strings[-1]] + ([] if first.nargs == 0 else
                                              [example(first, places)])
    return argv + positionals


def parse(parser, argv) -> tuple[int | None, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            return exc.code, err.getvalue()
    return None, err.getvalue()


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_has_a_checked_type_or_choices(command):
    loose = [name_of(a) for a in value_actions(build_parser(command))
             if not isinstance(a.type, Checked) and not a.choices]
    assert loose == [], (f"rhbl {command}: give these a type from protocol.arguments (or "
                         f"choices): {loose}")


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_refuses_hostile_values_in_one_line(command, places):
    parser = build_parser(command)
    code, err = parse(parser, base_argv(parser, None, places))
    assert code is None, f"rhbl {command}: its valid example arguments are refused: {err}"
    walked = 0
    for action in value_actions(parser):
        for value in hostile(action, places):
            argv = base_argv(parser, action, places)
            if action.option_strings:
                argv = [*argv, f"{action.option_strings[-1]}={value}"]
            else:
                argv = [*argv, "--", value]
            code, err = parse(parser, argv)
            what = f"rhbl {command} {name_of(action)} {value!r}"
            assert code == 2, f"{what}: accepted (exit {code})"
            lines = err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(f"rhbl {command}: error:"), \
                f"{what}: {err!r}"
            assert "Traceback" not in err
            named = action.option_strings or [action.dest, action.metavar or action.dest]
            assert any(n in lines[0] for n in named), f"{what}: the option is not named: {err}"
            walked += 1
    assert walked >= len(value_actions(parser))


def _first_number(parser) -> argparse.Action | None:
    return next((a for a in value_actions(parser) if isinstance(a.type, Number)), None)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_hostile_value_exits_2_in_one_line_end_to_end(command, places):
    """The real ``rhbl``: a NaN in the command's first number option, or a FIFO as its first
    path, is one line and exit 2 in a bounded time, nothing connected (no router runs)."""
    parser = build_parser(command)
    action = _first_number(parser)
    value = "nan"
    if action is None:
        action = next(a for a in value_actions(parser)
                      if getattr(a.type, "kind", "") in ("input", "output"))
        value = places["fifo"]
    argv = base_argv(parser, action, places)
    argv += [f"{action.option_strings[-1]}={value}"] if action.option_strings else ["--", value]
    r = subprocess.run([sys.executable, "-m", "lab.cli", command, *argv,
                        *(["--connect", "tcp/127.0.0.1:9"] if any(
                            "--connect" in a.option_strings for a in parser._actions) else [])],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and name_of(action) in lines[0], r.stderr
    assert "Traceback" not in r.stderr
