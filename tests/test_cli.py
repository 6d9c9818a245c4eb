"""The ``rhbl`` front end: every command is reachable and has a truthful --help."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from lab.cli import COMMANDS, build_parser, main
from lab.recipe import DEMO, EVAL_SECONDS, RECIPES


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


@pytest.mark.parametrize(
    ("argv", "option", "given"),
    [
        (["refine", "--behaviour", "wall-following", "--tree", "{t}", "--out", "{t}"], "--out",
         "--tree"),
        (["compact", "--tree", "{t}", "--out", "{link}"], "--out", "--tree"),
        (["evaluate", "--world", "room", "--tree", "{t}", "--json", "{t}"], "--json", "--tree"),
        (["train", "--world", "room", "--resume", "{t}", "--out", "{link}"], "--out", "--resume"),
        (["learner", "--resume", "{t}", "--out", "{t}"], "--out", "--resume"),
    ],
)
def test_no_command_writes_over_a_file_it_reads(tmp_path, capsys, argv, option, given):
    """``--tree t --out t`` (or a link to it) would replace the taught tree with what was made
    from it: refused before any work, the file untouched."""
    tree = tmp_path / "t.rhbl"
    tree.write_bytes(b"a taught tree")
    (tmp_path / "link.rhbl").symlink_to(tree)
    argv = [a.format(t=tree, link=tmp_path / "link.rhbl") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rhbl {argv[0]}: error: {option} ") and f"is the file {given} reads" in err
    assert tree.read_bytes() == b"a taught tree"


def test_a_closed_stdout_pipe_ends_quietly(tmp_path):
    """`rhbl train ... | head -c 10`: the reader goes away; the snapshot is written, no error
    line or traceback, the SIGPIPE status."""
    out = tmp_path / "c.rhbl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "lab.cli", "train", "--world", "room", "--seconds", "5",
         "--rounds", "0", "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        env={k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"})  # block-buffered
    proc.stdout.close()  # nobody reads: the first print meets a broken pipe
    err = proc.stderr.read().decode()
    assert proc.wait(60) == 141, err
    assert err == "" and out.exists()


# ---- help defaults come from the training recipe (lab.recipe), so they cannot drift ----


def _helps(command: str) -> dict[str, str]:
    """option -> its help text, whitespace normalised."""
    parser = build_parser(command)
    return {a.option_strings[0]: " ".join((a.help or "").split())
            for a in parser._actions if a.option_strings}


def _number(text: str) -> float | tuple[float, ...] | str:
    if text == "none":
        return ()
    if "," in text:
        return tuple(float(v) for v in text.split(","))
    try:
        return float(text)
    except ValueError:
        return {"no": False, "yes": True}.get(text, text)


def test_train_help_defaults_are_the_recipes():
    helps = _helps("train")
    flags = {"--seconds": "seconds", "--perturb": "perturb", "--features": "features",
             "--spawn": "spawn", "--stride": "stride", "--starts": "starts",
             "--segment": "segment", "--random-segment": "random_segment",
             "--consistent": "consistent", "--rounds": "rounds",
             "--round-seconds": "round_seconds", "--round-free": "round_free",
             "--takeover": "takeover", "--augment": "augment",
             "--augment-scale": "augment_scale", "--round-scales": "round_scales"}
    for flag, name in flags.items():
        m = re.search(r"default: the recipe's \(wall following (\S+?), maze (\S+?)\)", helps[flag])
        assert m, (flag, helps[flag])
        for task, shown in zip(("wall-following", "maze"), m.groups(), strict=True):
            assert _number(shown) == getattr(RECIPES[task], name), (flag, task, shown)
    # the drift found before the recipe was typed: 300 s and perturb 0.2 in the help
    assert RECIPES["wall-following"].seconds == 600.0 and RECIPES["maze"].perturb == 0.05
    for flag in ("--distance", "--min-radius", "--max-nodes"):
        assert "default: the classifier's" in helps[flag]


def _demo_defaults(helps: dict[str, str], flag: str) -> tuple[float, float, float]:
    m = re.search(r"default: wall following (\S+?), maze (\S+?), goals (\S+?)[;)]", helps[flag])
    assert m, (flag, helps[flag])
    return float(m.group(1)), float(m.group(2)), float(m.group(3))


def test_demo_help_says_the_values_the_demo_uses(tmp_path):
    from lab.demo_run import Demo

    helps = _helps("demo")
    shown = {flag: _demo_defaults(helps, flag) for flag in
             ("--teach-seconds", "--rounds", "--round-seconds", "--drive-seconds")}
    assert shown["--rounds"] == (3, 4, 4)  # the maze demo: 4 rounds, not the recipe's 6
    parser = build_parser("demo")
    goals = Demo(parser.parse_args(["--scenario", "goals", "--out", str(tmp_path / "g"),
                                    "--quiet"]))
    assert (goals.teach, goals.rounds, goals.round_seconds, goals.drive) == \
        tuple(shown[f][2] for f in ("--teach-seconds", "--rounds", "--round-seconds",
                                    "--drive-seconds"))
    assert goals.behaviour.name == "red-green" and goals.targets and goals.again
    for k, task in enumerate(("wall-following", "maze")):
        demo = Demo(parser.parse_args(["--scenario", task, "--out", str(tmp_path / task),
                                       "--quiet"]))
        used = {"--teach-seconds": demo.teach, "--rounds": demo.rounds,
                "--round-seconds": demo.round_seconds, "--drive-seconds": demo.drive}
        for flag, value in used.items():
            assert shown[flag][k] == value, (task, flag)
        assert demo.scenario.recipe == RECIPES[task].for_demo()
        assert demo.scenario.recipe.rounds == DEMO.get(task, {}).get("rounds", RECIPES[task].rounds)
        assert demo.scenario.recipe.round_scales == () == demo.scenario.recipe.round_worlds
        assert demo.drive == EVAL_SECONDS[task] and demo.spec.name == RECIPES[task].world
