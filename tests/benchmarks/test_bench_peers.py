"""``benchmarks/bench_peers.py``: RHBL beside scikit-learn's learners on the same demonstrations,
each driven in closed loop."""

from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.fixture(scope="module")
def bench(request):
    return request.getfixturevalue("load_benchmark")("bench_peers")


def test_a_quick_run_drives_every_learner_and_prints_one_row_each(bench, tmp_path, capsys):
    out = tmp_path / "peers.json"
    assert bench.main(["--behaviour", "wall-following", "--seeds", "0", "--quick",
                       "--json", str(out)]) == 0
    text = capsys.readouterr().out
    rows = [line for line in text.splitlines() if line.startswith("| wall-following |")]
    peer = [r for r in rows if r.count("|") == len(bench.HEADER) + 1
            and not r.split("|")[2].strip().endswith(")")]
    assert [r.split("|")[2].strip() for r in peer] == bench.DEFAULT
    # the world table: the teaching world and the first held-out one, a column per learner
    worlds = [r for r in rows if r.count("|") == len(bench.DEFAULT) + 4
              and r.split("|")[2].strip().endswith(")")]
    assert [r.split("|")[2].strip() for r in worlds] == ["room (taught)",
                                                        "eval-room-jagged (held out)"]
    assert "rhbl refitted on the vectors = the tree rhbl train grew: yes" in text
    data = json.loads(out.read_text())
    run = data["results"]["wall-following"][0]
    assert run["vectors"] > 100
    for name, r in run["learners"].items():
        assert r["size"] > 0 and r["fit_s"] > 0 and r["single_us"] > 0 and r["batch_us"] > 0
        assert {w: v["episodes"] for w, v in r["worlds"].items()} == {
            "room": 1, "eval-room-jagged": 1}, name
        if name != "rhbl":  # a scikit-learn model answered every step it drove (20 s at 10 Hz)
            assert r["queries"] >= 2 * 200, name
    assert run["learners"]["1-nn"]["size"] == run["vectors"]  # kNN keeps every vector
    # the tables print again from the file, measuring nothing
    assert bench.main(["--from-json", str(out)]) == 0
    again = capsys.readouterr().out
    assert [r for r in again.splitlines() if r.startswith("| wall-following |")] == rows
    # seeds of a behaviour from several files go together; the same seed twice is refused
    assert bench.main(["--from-json", str(out), str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "wall-following seed 0 measured twice" in err[0]


def test_eval_world_drives_in_the_worlds_given_instead_of_the_held_out_ones(bench, capsys):
    assert bench.main(["--behaviour", "wall-following", "--seeds", "0", "--quick",
                       "--learners", "rhbl-vote", "--eval-world", "eval-room-l"]) == 0
    rows = [line.split("|")[2].strip() for line in capsys.readouterr().out.splitlines()
            if line.startswith("| wall-following |") and line.count("|") == 5]
    assert rows == ["room (taught)", "eval-room-l (held out)"]


def test_a_peer_drives_with_the_features_and_actions_of_the_tree(bench):
    from sklearn.tree import DecisionTreeClassifier

    from client.behaviour.actions import DEFAULT_ACTIONS
    from client.behaviour.features import FEATURES

    spec = FEATURES["wall"]
    ranges = np.full(360, 2.0, dtype=np.float32)
    x = spec.extract(ranges, 0.0)
    model = DecisionTreeClassifier().fit(np.stack([x, 1 - x]), ["rot-left", "fwd"])
    policy = bench.PeerPolicy(model, spec, DEFAULT_ACTIONS, size=3, depth=1)
    assert policy.act(ranges, (0.0, 0.0, 0.0)) == "rot-left" and policy.queries == 1
    assert policy.classifier.node_count_ == 3


@pytest.mark.parametrize("argv, says", [
    (["--behaviour", "no-such"], "unknown 'no-such'"),
    (["--learners", "svm"], "unknown 'svm'"),
    (["--seeds", "a,b"], "--seeds must be integers"),
    (["--people", "nobody"], "unknown 'nobody'"),
    (["--people", "steady", "--people-behaviour", "wandering"], "right-hand wall only"),
    (["--behaviour", ""], "nothing to measure"),
    (["--eval-world", "no-such-world"], "--eval-world no-such-world"),
    (["--eval-world", "room", "--people", "steady"], "not with --people"),
])
def test_bad_input_is_one_line_naming_it(bench, capsys, argv, says):
    with pytest.raises(SystemExit) as exc:
        bench.main(argv)
    assert exc.value.code == 2
    assert says in capsys.readouterr().err


def test_a_missing_json_file_is_one_line(bench, tmp_path, capsys):
    assert bench.main(["--from-json", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.json" in err[0]


def test_several_person_models_are_pooled_in_rows_of_their_own(bench):
    """``--people all`` names every model; with more than one model's sessions the table gains
    rows pooling them (the success over all their episodes), each model keeping its own."""
    ap_people = bench._names(bench.PEOPLE_MODELS, "people", every=True)
    assert ap_people("all") == bench.PEOPLE_MODELS and ap_people("steady,bang") == ["steady",
                                                                                     "bang"]

    def run(ok: int, size: int) -> dict:
        world = {"kind": "held_out", "episodes": 4, "successes": ok, "collisions": 0,
                 "teacher_success_rate": 1.0}
        return {"seed": 0, "vectors": 10, "trained_nodes": size, "learners": {"rhbl": {
            "size": size, "fit_s": 1.0, "single_us": 2.0, "batch_us": 1.0,
            "worlds": {"eval-room-l": world}}}}

    one = {"wall-following": [run(4, 9)], "wall-following by steady": [run(4, 5)]}
    assert bench.pooled(one) == one  # one model: nothing to pool
    two = {**one, "wall-following by bang": [run(1, 7)]}
    pooled = bench.pooled(two)
    assert list(pooled) == [*two, "wall-following by 2 people"]
    rows = {r[0]: r for r in bench.summary_rows(pooled, ["rhbl"])}
    assert rows["wall-following by 2 people"][3] == "62% (5/8)"
    assert rows["wall-following by bang"][3] == "25% (1/4)"


def test_the_order_vote_is_its_trees_majority_each_fitted_in_an_order_of_its_own(bench):
    from lab.behaviours import get, recipe_of

    recipe = recipe_of(get("wall-following"))
    rng = np.random.default_rng(0)
    X = rng.random((400, 5))
    y = np.where(X[:, 0] + 0.2 * rng.standard_normal(400) > 0.5, "fwd", "rot-left")
    vote = bench.OrderVote(X, y, recipe, seed=3)
    assert len(vote.members) == bench.VOTERS
    assert vote.node_count_ == sum(m.node_count_ for m in vote.members)
    # the trees differ (the order is each one's own), and a seed gives the same trees again
    sizes = [m.node_count_ for m in vote.members]
    assert len(set(sizes)) > 1 or any(
        (a.predict(X) != b.predict(X)).any() for a, b in zip(vote.members, vote.members[1:], strict=False))
    again = bench.OrderVote(X, y, recipe, seed=3)
    assert [m.node_count_ for m in again.members] == sizes
    assert (again.predict(X) == vote.predict(X)).all()
    # every answer is the majority of the members' answers (a tie: the first tree's side)
    for x in X[:50]:
        answers = [m.predict_one(x) for m in vote.members]
        top = max(answers.count(a) for a in answers)
        assert answers.count(vote.predict_one(x)) == top
        assert vote.predict_one(x) == next(a for a in answers if answers.count(a) == top)
