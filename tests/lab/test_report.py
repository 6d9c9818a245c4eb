"""lab.episode.Episode (one record for every driver) and lab.report (the one table formatter)."""

from __future__ import annotations

import pytest

from client.behaviour.learning import TreePolicy
from lab.episode import DT, Episode
from lab.evaluate import evaluate, format_table
from lab.harness import drive, make_learner, resolve_world
from lab.recipe import RECIPES
from lab.report import EPISODE_HEADERS, episode_table, table
from lab.train import train


def test_table_is_markdown_and_rejects_ragged_rows():
    text = table(["a", "b"], [[1, "x"], [2.5, None]], title="T", notes=["n"])
    assert text.splitlines() == ["T", "| a | b |", "|---|---|", "| 1 | x |", "| 2.5 | None |", "n"]
    with pytest.raises(ValueError, match="1 cells for 2 columns"):
        table(["a", "b"], [[1]])


def test_episode_of_a_run_and_its_metrics():
    spec = resolve_world("corridor")
    ep = drive(spec, _Straight(), spec.pose, seconds=3.0, kind="teacher")
    assert isinstance(ep, Episode) and ep.kind == "teacher" and ep.dt == DT
    assert len(ep.poses) == len(ep.stalls) == len(ep.actions) == len(ep.side) == 30
    assert ep.sim_time == pytest.approx(3.0) and ep.teacher_ticks == 0
    m = ep.metrics(spec.goal)
    assert m["seconds"] == pytest.approx(3.0) and m["distance"] > 0.5
    assert m["start"] == [round(v, 4) for v in spec.pose]
    # a recording: sim time from the step times; drivers counted
    rec = Episode(start=(0.0, 0.0, 0.0), ts=[1.0, 1.1, 1.2], drivers=["teacher", None, "teacher"])
    assert rec.sim_time == pytest.approx(0.2) and rec.teacher_ticks == 2


def test_evaluate_prints_one_markdown_row_per_driver_and_episode():
    spec = resolve_world("corridor")
    learner = make_learner("wall-following")
    train(spec, learner, RECIPES["wall-following"].replace(seconds=10, rounds=0), seed=0)
    rep = evaluate(spec, TreePolicy.from_learner(learner), episodes=2, seconds=3.0)
    lines = format_table(rep).splitlines()
    assert lines[1] == "| " + " | ".join([*EPISODE_HEADERS, "success"]) + " |"
    rows = [ln for ln in lines if ln.startswith("| 0: ") or ln.startswith("| 1: ")]
    assert [r.split(" | ")[0] for r in rows] == ["| 0: learner", "| 0: teacher", "| 1: learner",
                                                 "| 1: teacher"]
    assert any(ln.startswith("success rate: learner") for ln in lines)
    assert episode_table([("x", rep["learner"][0])]).count("\n") == 2


class _Straight:
    """A driver that always goes straight on (the default action set)."""

    def reset(self):
        pass

    def act(self, ranges, pose):
        return "fwd"
