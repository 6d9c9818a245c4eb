"""rhbl train / evaluate / experiment end to end on a small world (quick)."""

import json

import pytest

from client.behaviour.learning import TreePolicy, load_snapshot
from lab.cli import main as cli
from lab.evaluate import evaluate
from lab.harness import make_learner, parse_pose, resolve_world
from lab.recipe import RECIPES
from lab.train import train, visited_states

CORRIDOR = "corridor"


def test_train_then_evaluate_cli(tmp_path, capsys):
    tree = tmp_path / "t.rhbl"
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--seconds", "40",
                "--round-generated", "1", "--out", str(tree), "--seed", "1"]) == 0
    assert tree.exists()
    out_json, png = tmp_path / "e.json", tmp_path / "e.png"
    assert cli(["evaluate", "--world", CORRIDOR, "--tree", str(tree), "--episodes", "2",
                "--seconds", "20", "--json", str(out_json), "--plot", str(png),
                "--spheres", "0,1"]) == 0
    rep = json.loads(out_json.read_text())
    assert png.stat().st_size > 1000
    assert len(rep["learner"]) == 2 and len(rep["teacher"]) == 2
    for ep in rep["learner"] + rep["teacher"]:
        for key in ("start", "seconds", "collisions", "distance", "wall_band_fraction",
                    "goal_reached", "time_to_goal", "oscillations", "teacher_agreement", "success"):
            assert key in ep
        assert ep["goal_reached"] is None  # no goal in a wall-following world
    assert rep["success_rate"] == sum(ep["success"] for ep in rep["learner"]) / 2
    assert rep["tree"]["nodes"] >= 1 and rep["tree"]["height"] >= 0
    assert "success rate" in capsys.readouterr().out


def test_resume_with_a_corrective_start(tmp_path):
    first = tmp_path / "a.rhbl"
    second = tmp_path / "b.rhbl"
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--seconds", "10", "--out", str(first),
                "--rounds", "0"]) == 0
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--seconds", "10", "--out", str(second),
                "--resume", str(first), "--start", "5,1,3.1416"]) == 0
    _, _, _, meta = load_snapshot(second)
    prov = meta["provenance"]
    assert prov["parent"] == str(first)
    assert prov["vectors"] == 200
    assert prov["sessions"][-1]["start"] == [5.0, 1.0, 3.1416]


def test_parse_pose():
    assert parse_pose("1,2,-0.5") == (1.0, 2.0, -0.5)
    with pytest.raises(Exception, match="x,y,yaw"):
        parse_pose("1,2")


def test_maze_episode_stops_at_goal_and_reports_time():
    spec = resolve_world("maze")
    learner = make_learner("maze")
    train(spec, learner, RECIPES["maze"].replace(seconds=20.0, rounds=0), seed=0)  # teacher checked
    rep = evaluate(spec, TreePolicy.from_learner(learner), episodes=1, seconds=5.0)
    ep = rep["teacher"][0]
    assert ep["goal_reached"] is False and ep["time_to_goal"] is None  # 5 s is too short
    assert ep["wall_band_fraction"] is None


def test_experiment_cli_small(capsys):
    assert cli(["experiment", "wall-following", "--paper", "--trials", "1", "--train-seconds", "20",
                "--seconds", "10", "--episodes", "1", "--eval-world", "none"]) == 0
    out = capsys.readouterr().out
    assert "Table I" in out and "53.4" in out


def test_train_compacts_on_the_vectors_it_learned(tmp_path, capsys):
    spec = resolve_world(CORRIDOR)
    short = RECIPES["wall-following"].replace(seconds=20.0, rounds=1, round_seconds=5.0)
    compacting = short.replace(compact="exact")
    learner = make_learner(compacting)
    assert learner.recording
    train(spec, learner, compacting, seed=0)
    rec = learner.session["compaction"]
    assert rec["method"] == "exact" and rec["nodes_after"] == learner.nodes
    assert rec["data"]["rows"] == learner.vectors
    X, _ = learner.recorded()
    full = make_learner(short)  # the same run without compaction: the same predictions
    assert not full.recording
    train(spec, full, short, seed=0)
    assert full.session["compaction"] is None and full.nodes >= learner.nodes
    assert list(full.classifier.predict(X)) == list(learner.classifier.predict(X))
    # the CLI: --compact prune --compact-max-nodes N, recorded in the snapshot
    tree = tmp_path / "c.rhbl"
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--seconds", "20", "--rounds", "0", "--out",
                str(tree), "--compact", "prune-balanced", "--compact-max-nodes", "5",
                "--radius", "parent"]) == 0
    assert "compacted (prune) from" in capsys.readouterr().out
    # the behaviour's own radius (the margin) is not compacted: named, nothing written
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--seconds", "20",
                "--rounds", "0", "--out", str(tmp_path / "m.rhbl"), "--compact", "exact"]) == 2
    assert "--radius parent" in capsys.readouterr().err
    assert not (tmp_path / "m.rhbl").exists()
    _, _, _, meta = load_snapshot(tree)
    assert meta["compaction"][-1]["nodes_after"] <= 5
    assert meta["compaction"][-1]["settings"]["class_weight"] == "balanced"
    assert meta["provenance"]["sessions"][-1]["compaction"]["method"] == "prune"


def test_experiment_reports_nodes_before_and_after_compaction(capsys):
    assert cli(["experiment", "wall-following", "--trials", "1", "--train-seconds", "20",
                "--seconds", "10", "--episodes", "1", "--eval-world", "none", "--rounds", "0",
                "--compact", "exact", "--radius", "parent"]) == 0
    out = capsys.readouterr().out
    assert "before compaction" in out and "s0 " in out and " -> " in out


def test_a_compacting_recipe_needs_a_recording_learner():
    spec = resolve_world(CORRIDOR)
    recipe = RECIPES["wall-following"].replace(seconds=5.0, rounds=0, compact="exact")
    with pytest.raises(ValueError, match="compact 'exact' needs a learner"):
        train(spec, make_learner(RECIPES["wall-following"]), recipe, seed=0)


def test_compact_rounds_compacts_between_rounds_and_keeps_learning(tmp_path):
    spec = resolve_world(CORRIDOR)
    recipe = RECIPES["wall-following"].replace(seconds=20.0, rounds=2, round_seconds=5.0,
                                        compact="prune-balanced", compact_max_nodes=4,
                                        compact_rounds=True)
    learner = make_learner(recipe)
    train(spec, learner, recipe, seed=0)
    # after the demonstrations, after round 1, the last step (after round 2)
    records = learner.classifier.metadata["compaction"]
    notes = [r["data"]["source"] for r in records]
    assert len(records) == 3 and "after the demonstrations" in notes[0]
    assert "after round 1" in notes[1] and "the last step" in notes[2]
    assert [r["data"]["rows"] for r in records] == sorted(r["data"]["rows"] for r in records)
    assert records[-1]["data"]["rows"] == learner.vectors
    assert all(r["nodes_after"] <= 4 for r in records) and learner.nodes <= 4
    assert learner.session["compaction"] == records[-1]
    assert learner.session["compact_rounds"] == records[:2]
    stats = learner.session["round_stats"]
    # round 1 drove the compacted tree and grew it where the teacher disagreed, round 2 too
    assert stats[0]["nodes"] > records[0]["nodes_after"]
    assert stats[0]["nodes_compacted"] == records[1]["nodes_after"]
    assert "nodes_compacted" not in stats[1]  # the last round's is the last step
    assert records[2]["nodes_before"] == stats[1]["nodes"]
    out = learner.save(tmp_path / "c.rhbl")  # the snapshot keeps every record
    clf, _, _, meta = load_snapshot(out)
    assert [r["data"]["source"] for r in meta["compaction"]] == notes
    assert clf.node_count_ == learner.nodes


def test_compact_rounds_in_scaled_copies_compacts_after_every_round_but_the_last():
    spec = resolve_world(CORRIDOR)
    recipe = RECIPES["wall-following"].replace(seconds=10.0, rounds=1, round_seconds=3.0,
                                        round_scales=(1.2,), compact="exact",
                                        compact_rounds=True)
    learner = make_learner(recipe)
    train(spec, learner, recipe, seed=0)
    notes = [r["data"]["source"] for r in learner.classifier.metadata["compaction"]]
    assert len(notes) == 3
    assert "after round 1 in the copy scaled 1.2" in notes[1] and "last step" in notes[2]


def test_visited_states_label_what_the_tree_reaches_and_learn_nothing():
    spec = resolve_world(CORRIDOR)
    recipe = RECIPES["wall-following"].replace(seconds=10.0, rounds=0, round_seconds=2.0,
                                        round_free=1)
    learner = make_learner(recipe)
    train(spec, learner, recipe, seed=0)
    before = learner.classifier.tree_arrays()
    vectors = learner.vectors
    X, y = visited_states(spec, learner, recipe, seed=3, scales=(0.9,))
    # one round of 2 s (20 steps) from every start pose and one free pose, in 2 worlds
    starts = len(spec.start_poses)
    assert X.shape == ((2 * (starts + 1)) * 20, learner.features.dim) and len(y) == len(X)
    assert set(y) <= set(learner.actions.names)
    assert learner.vectors == vectors
    after = learner.classifier.tree_arrays()
    assert all((before[k] == after[k]).all() for k in before)


def test_compact_rounds_bad_combinations_are_named_errors(tmp_path, capsys):
    out = str(tmp_path / "x.rhbl")
    assert cli(["train", "--behaviour", "wall-following", "--world", CORRIDOR, "--out", out, "--compact-rounds"]) == 2
    assert "compact_rounds needs a compaction step" in capsys.readouterr().err
    (tmp_path / "none.mcap").write_bytes(b"")  # the combination is refused before it is read
    assert cli(["train", "--from-recording", str(tmp_path / "none.mcap"), "--out", out,
                "--compact-rounds"]) == 2
    assert "--compact-rounds does not apply to --from-recording" in capsys.readouterr().err
    assert not (tmp_path / "x.rhbl").exists()


def test_compact_visits_redoes_the_last_compaction_with_held_out_states():
    spec = resolve_world(CORRIDOR)
    base = RECIPES["wall-following"].replace(seconds=10.0, rounds=1, round_seconds=2.0,
                                      compact="prune-balanced", compact_max_nodes=3,
                                      compact_rounds=True)
    plain = make_learner(base)
    train(spec, plain, base, seed=0)
    recipe = base.replace(compact_visits=2, visit_scales=(0.9,), visit_free=1)
    learner = make_learner(recipe)
    train(spec, learner, recipe, seed=0)
    rec = learner.session["compaction"]
    assert learner.session["compact_visits"] == {"visits": 2, "scales": [0.9], "free": 1}
    # each visit: one 2 s round (20 steps) from every start pose and one free pose, in 2 worlds
    visited = 2 * 2 * (len(spec.start_poses) + 1) * 20
    assert rec["data"]["rows"] == learner.vectors + visited
    assert "held-out states" in rec["data"]["source"] and "(2 of 2)" in rec["data"]["source"]
    assert rec["nodes_before"] == plain.session["compaction"]["nodes_before"]  # the same tree
    assert learner.nodes <= 3 and rec["nodes_after"] == learner.nodes
    assert learner.vectors == plain.vectors  # the visits learned nothing


def test_a_behaviours_tree_is_learned_again_bounded_by_the_margin(tmp_path, capsys):
    """rhbl train with a behaviour's own recipe (radius "margin") ends by learning the tree
    again from every vector it learned, in one fit: the tree is the margin tree of its vectors
    (what the peer benchmark refits, lab.harness.learned_from), not the one grown as they came;
    a resumed learner keeps the tree it extends; --radius parent grows the paper's."""
    from lab.behaviours import get, recipe_of
    from lab.harness import learned_from
    from rhbl import HypersphereClassifier

    recipe = recipe_of(get("wall-following")).replace(seconds=20.0, rounds=1, round_seconds=5.0,
                                                      round_generated=0, round_free=0)
    assert recipe.radius == "margin"
    learner = make_learner(recipe)
    assert learner.recording  # the step needs the vectors
    spec = resolve_world(CORRIDOR)
    train(spec, learner, recipe, seed=0, behaviour=get("wall-following"))
    assert learner.session["relearned"] is True and learner.classifier.radius == "margin"
    X, y = learner.recorded()
    params = learner.classifier.get_params()
    grown = HypersphereClassifier(**params).partial_fit(X, y)  # as the vectors came
    fitted = HypersphereClassifier(**params).fit(X, y)
    assert learner.classifier.tree_equal(fitted) and not learner.classifier.tree_equal(grown)
    assert learned_from(recipe, X, y).classifier.tree_equal(fitted)
    assert fitted.node_count_ < HypersphereClassifier(**{**params, "radius": "parent"}).fit(
        X, y).node_count_
    tree = tmp_path / "m.rhbl"
    learner.save(tree)
    again = tmp_path / "again.rhbl"
    assert cli(["train", "--world", CORRIDOR, "--behaviour", "wall-following", "--resume",
                str(tree), "--start", "1,1,0", "--seconds", "5", "--out", str(again)]) == 0
    resumed = load_snapshot(again)[0]
    assert resumed.radius == "margin" and resumed.node_count_ >= learner.nodes
    paper = tmp_path / "p.rhbl"
    assert cli(["train", "--world", CORRIDOR, "--behaviour", "wall-following", "--seconds", "20",
                "--rounds", "0", "--radius", "parent", "--out", str(paper)]) == 0
    assert load_snapshot(paper)[0].radius == "parent"
