"""``benchmarks/ablate_person_rule.py``: the person rule's variants taught by person models and
judged by the tree alone."""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="module")
def ablate(request):
    return request.getfixturevalue("load_benchmark")("ablate_person_rule")


def test_a_session_teaches_with_the_variant_and_judges_every_world_of_the_behaviour(ablate):
    rows = [ablate.session("left-wall", "calm", m, seed=0, demo=20.0, correct=10.0, episodes=1)
            for m in ("person:copies=0", "person:copies=2")]
    assert all(len(r) == 1 for r in rows)  # no refinement: the session's row alone
    rows = [r[0] for r in rows]
    assert [r["method"] for r in rows] == ["person:copies=0 20+10 s", "person:copies=2 20+10 s"]
    for r in rows:
        assert r["behaviour"] == "left-wall" and r["person"] == "calm" and r["labels"] > 0
        kinds = {w: v["kind"] for w, v in r["worlds"].items()}
        assert kinds == {"room": "taught", "eval-room-jagged": "held_out",
                         "eval-room-l": "held_out", "eval-room-ring": "held_out"}
        assert all(v["episodes"] == 1 and 0 <= v["successes"] <= 1 for v in r["worlds"].values())
    # the copies are learned too: the same labels make a bigger tree with two copies each
    assert rows[1]["nodes"] > rows[0]["nodes"]


@pytest.mark.slow
def test_a_session_refined_by_practice_is_judged_again_beside_it(ablate):
    from lab.practice import Runner

    with Runner(workers=1) as runner:
        rows = ablate.session("wall-following", "calm", "person", seed=0, demo=30.0,
                              correct=0.0, episodes=1, refine=0.05, runner=runner,
                              practice={"scales": (), "seconds": 10.0})
    assert [r["method"] for r in rows] == ["person 30+0 s", "person 30+0 s refined 0.05 min"]
    assert set(rows[1]["worlds"]) == set(rows[0]["worlds"])
    ref = rows[1]["refinement"]
    assert ref["episodes"] >= 6 and ref["after"]["fitness"] >= ref["before"]["fitness"]
    assert rows[1]["nodes"] == ref["after"]["nodes"]


def _row(method, behaviour, taught, held):
    return {"behaviour": behaviour, "person": "calm", "method": method, "seed": 0,
            "worlds": {"a": {"kind": "taught", "successes": taught[0], "episodes": taught[1],
                             "collisions": 1},
                       "b": {"kind": "held_out", "successes": held[0], "episodes": held[1],
                             "collisions": 0}}}


def test_the_table_pools_every_episode_and_counts_the_sessions_on_target(ablate, tmp_path):
    rows = [_row("person", "maze", (9, 10), (8, 10)), _row("person", "dead-end", (8, 10), (10, 10)),
            _row("person:k=50", "maze", (0, 10), (0, 10))]
    text = ablate.tables(rows)
    line = next(x for x in text.splitlines() if x.startswith("| person |"))
    # dead-end, maze, all (85% of 20 taught, 90% held out), collisions, on target
    assert line == "| person | 80% / 100% | 90% / 80% | 85% / 90% | 2 | 1 of 2 |"
    assert "| person:k=50 | - | 0% / 0% | 0% / 0% | 1 | 0 of 1 |" in text
    path = tmp_path / "rows.json"
    path.write_text(json.dumps(rows))
    assert ablate.main(["--table", str(path)]) == 0


@pytest.mark.parametrize("argv, says", [
    (["--behaviour", "red-green"], "--behaviour: unknown 'red-green'"),
    (["--people", "nobody"], "--people: unknown 'nobody'"),
    (["--methods", "nonsense"], "--methods:"),
    (["--seeds", "a"], "--seeds: integers"),
])
def test_wrong_arguments_are_named_and_exit_2(ablate, capsys, argv, says):
    with pytest.raises(SystemExit) as exc:
        ablate.main(argv)
    assert exc.value.code == 2 and says in capsys.readouterr().err


def test_the_practice_flags_reach_refine_and_name_the_variant(ablate):
    import argparse

    args = argparse.Namespace(refine_generated=4, refine_validation=0, refine_more=6)
    practice = ablate._practice_of(args, "wall-following")
    assert practice == {"drawn": ("rooms", 4), "more": 6}
    assert ablate._refined_tag(practice) == " +4 drawn +6 more"
    args = argparse.Namespace(refine_generated=0, refine_validation=0, refine_more=0)
    assert ablate._practice_of(args, "wall-following") == {}
