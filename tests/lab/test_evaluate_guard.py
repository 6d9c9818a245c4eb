"""``rhbl evaluate`` judges the tree alone and, beside it, drives it through the guard its
learning rule says (as ``rhbl controller`` does), counting what the guard did; ``--no-guard``:
the tree alone only."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from client.behaviour.rule import PERSON
from lab.cli import main
from rhbl import snapshot

WALL_TREE = Path(__file__).resolve().parents[1] / "rhbl" / "data" / "room-1200.rhbl"


def _as_taught_by_hand(tmp_path) -> Path:
    """The committed wall tree with a person's learning rule in its metadata (what
    ``rhbl learner --teacher person`` writes there)."""
    snap = snapshot.decode(snapshot.read(WALL_TREE), source=str(WALL_TREE))
    meta = dict(snap.metadata, learning={"rule": "person", "lag": 3})
    out = tmp_path / "by-hand.rhbl"
    snapshot.write(out, snapshot.encode(dataclasses.replace(snap, metadata=meta)))
    return out


def _evaluate(tmp_path, tree, *options) -> dict:
    out = tmp_path / "report.json"
    assert main(["evaluate", "--world", "room", "--tree", str(tree), "--episodes", "1",
                 "--seconds", "10", "--json", str(out), *options]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize(("options", "expected"), [
    (("--no-guard",), None), ((), 0.0), (("--guard", "--guard-clearance", "0.2"), 0.2)])
def test_a_scripted_tree_is_judged_alone_and_driven_through_its_rules_guard(tmp_path, options,
                                                                            expected):
    report = _evaluate(tmp_path, WALL_TREE, *options)
    assert report["judged"] == "the tree alone"
    if expected is None:
        assert report["guard"] is None and report["guarded"] is None
    else:
        assert report["guard"]["clearance"] == expected and report["guard"]["hold"] == 30
        assert set(report["guarded"]) >= {"success_rate", "collisions", "loops"}
        assert report["guard"]["overruled"] >= 0 and report["guard"]["avoided"] >= 0


def test_a_tree_taught_by_hand_is_evaluated_as_the_controller_drives_it(tmp_path, capsys):
    tree = _as_taught_by_hand(tmp_path)
    report = _evaluate(tmp_path, tree)
    assert report["guard"]["clearance"] == PERSON.guard.clearance > 0
    out = capsys.readouterr().out
    assert "judged by the tree alone" in out and "driven through the controller's guard" in out
    assert _evaluate(tmp_path, tree, "--no-guard")["guard"] is None
    assert _evaluate(tmp_path, tree, "--guard-hold", "7")["guard"]["hold"] == 7
    assert report["guard"]["straight"] is True
    assert _evaluate(tmp_path, tree, "--no-guard-straight")["guard"]["straight"] is False
