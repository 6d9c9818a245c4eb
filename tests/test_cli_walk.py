"""Every option of every ``rhbl`` command, walked with hostile values made from its parser.

For each option that takes a value, the values come from its argparse ``type`` (a
``process.arguments.Checked``: its ``kind`` and, for numbers, its range) or its ``choices``
(``campaigns.fuzz.cli_hostile``): negative, zero, NaN, infinities, huge, empty, not a number;
a FIFO, a character device, a folder, a missing file, a path under a regular file; wildcards
and separators in a name; bad endpoints, addresses and origins. Each must be refused by the
parser (before ``main`` runs, so before any work or connection) with one line naming the
option, exit 2, no traceback. A new option is walked as soon as it exists; one without a
checked type (or choices) fails the first test. A subprocess per command then checks the same
end to end, with a bounded timeout (no hang).
"""

from __future__ import annotations

import os
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
from process.arguments import Checked, Number

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict[str, str]:
    return cli_places(tmp_path_factory.mktemp("walk"))


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_has_a_checked_type_or_choices(command):
    loose = [option_name(a) for a in value_actions(build_parser(command))
             if not isinstance(a.type, Checked) and not a.choices]
    assert loose == [], (f"rhbl {command}: give these a type from process.arguments (or "
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


ISSUE_CASES = [  # issue 21's list: each was a traceback, silence or the wrong code
    ("demo --console nonsense", "--console"),
    ("experiment wall-following --trials 0", "--trials"),
    ("evaluate --world room --tree {tree} --spheres 99999,0 --plot {tmp}/x.png", "--spheres"),
    ("learner --out /proc/nope/t.rhbl --features wall", "--out"),
    ("train --world room --out /proc/nope/t.rhbl", "--out"),  # its folder cannot be made
    ("learner --out {tmp}/l.rhbl --stride 0", "--stride"),
    ("teacher --perturb 2", "--perturb"),
    ("controller --tree {tree} --query-timeout -1", "--query-timeout"),
    ("server --duration -1", "--duration"),
    ("foxglove --duration -1", "--duration"),
    ("teacher --seconds -1", "--seconds"),
    ("controller --tree {tree} --seconds -1", "--seconds"),
    ("record --out {tmp}/r.mcap --chunk-seconds 0", "--chunk-seconds"),
    ("record --out {tmp}/r.mcap --chunk-seconds nan", "--chunk-seconds"),
    ("learner --out {tmp}/l.rhbl --max-nodes -1", "--max-nodes"),
    ("learner --out {tmp}/l.rhbl --scan-buffer 0", "--scan-buffer"),
    ("learner --out {tmp}/l.rhbl --snapshot-every 0", "--snapshot-every"),
    ("learner --out {tmp}/l.rhbl --match-timeout nan", "--match-timeout"),
    ("evaluate --world room --tree {tree} --episodes -1", "--episodes"),
    ("demo --starts -1", "--starts"),
    ("train --from-recording {rec} --out {tmp}/t.rhbl --world room", "--world"),
    ("train --from-recording {rec} --out {tmp}/t.rhbl --resume {tree}", "--resume"),
    ("server --listen tcp/127.0.0.1:99999", "--listen"),
    ("demo --speedup -1", "--speedup"),
    ("server --zenoh-config {tmp}/bad.json5", "bad.json5"),
    ("learner --out {tmp}/l.rhbl --resume /nonexistent", "--resume"),
    ("train --world room --out /dev/null", "--out"),
    ("inspect {tmp}/fifo", "fifo"),
    ("replay {tmp}/fifo", "fifo"),
    ("train --from-recording {tmp}/fifo --out {tmp}/t.rhbl", "fifo"),
    ("compact --tree {tree} --out {tmp}/c.rhbl --data {tmp}/fifo", "fifo"),
]


@pytest.fixture(scope="module")
def issue_files(tmp_path_factory):
    import numpy as np

    from client.recording.mcap_file import RecordingWriter
    from protocol import keys
    from protocol import messages as m
    from rhbl import HypersphereClassifier

    d = tmp_path_factory.mktemp("issue")
    tree = d / "tree.rhbl"
    HypersphereClassifier().fit(np.array([[0.0, 0.0], [1.0, 1.0]]), ["a", "b"]).save(tree)
    rec = d / "run.mcap"
    with RecordingWriter(rec, viewer=False) as w:
        w.write(keys.scan_key("r0"), m.Scan(ts=0.0, id=0, ranges=np.ones(36, np.float32))
                .encode(), 10**9)
    (d / "bad.json5").write_text('{ mode: "peer", ')
    os.mkfifo(d / "fifo")
    return {"tmp": str(d), "tree": str(tree), "rec": str(rec)}


@pytest.mark.parametrize("line, named", ISSUE_CASES)
def test_the_issues_cases_are_one_line_and_exit_2(line, named, issue_files):
    argv = line.format(**issue_files).split()
    r = subprocess.run([sys.executable, "-m", "lab.cli", *argv, "--connect", "tcp/127.0.0.1:9"]
                       if argv[0] not in ("train", "evaluate", "experiment", "demo", "inspect",
                                          "compact")
                       else [sys.executable, "-m", "lab.cli", *argv],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert len(lines) == 1 and named in lines[0] and "Traceback" not in r.stderr, r.stderr
