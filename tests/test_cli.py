"""The ``rhbl`` front end: every command is reachable and has a truthful --help."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from lab.cli import COMMANDS, build_parser, main


def test_top_level_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_command_builds_its_parser(command):
    parser = build_parser(command)
    assert parser.prog == f"rhbl {command}"
    assert parser.format_help().strip()


def test_unknown_command_is_a_clear_usage_error():
    proc = subprocess.run(
        [sys.executable, "-m", "lab.cli", "fly"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    assert "invalid choice: 'fly'" in proc.stderr


def test_wrong_option_names_the_option():
    proc = subprocess.run(
        [sys.executable, "-m", "lab.cli", "example", "--no-such-flag"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert "--no-such-flag" in proc.stderr


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["train", "--world", "no-such-world", "--out", "{tmp}/t.rhbl"], "no-such-world"),
        (["evaluate", "--world", "corridor", "--tree", "{tmp}/garbage.rhbl"], "garbage.rhbl"),
        (["evaluate", "--world", "{tmp}/bad.toml", "--tree", "{tmp}/garbage.rhbl"], "robot.pose"),
    ],
)
def test_bad_input_is_one_clear_line_not_a_traceback(tmp_path, argv, needle):
    (tmp_path / "garbage.rhbl").write_bytes(b"not a snapshot")
    (tmp_path / "bad.toml").write_text('name = "x"\ntask = "wall-following"\n[robot]\npose = [1, 1]\n')
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    proc = subprocess.run(
        [sys.executable, "-m", "lab.cli", *argv], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"rhbl {argv[0]}: error: ")
    assert needle in proc.stderr


def test_a_closed_stdout_pipe_ends_quietly(tmp_path):
    """`rhbl train ... | head -c 10`: the reader goes away; the snapshot is written, no error
    line or traceback, the SIGPIPE status."""
    out = tmp_path / "c.rhbl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "lab.cli", "train", "--world", "corridor", "--seconds", "5",
         "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        env={k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"})  # block-buffered
    proc.stdout.close()  # nobody reads: the first print meets a broken pipe
    err = proc.stderr.read().decode()
    assert proc.wait(60) == 141, err
    assert err == "" and out.exists()
