"""Learning from a person: the reaction lag, the neighbours' vote, the PersonLearner."""

import copy
import dataclasses
import types

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.learning import DemonstrationLearner, TreePolicy
from client.behaviour.rule import PERSON, LearningRule
from client.behaviour.teaching import (
    PersonLearner,
    answered_scan,
    estimate_lag,
    nearest_votes,
    parse_lag,
    sided_actions,
)
from rhbl import load

NAMES = DEFAULT_ACTIONS.names
LAG, MAX_LAG = PERSON.alignment.default, PERSON.alignment.max_lag


def _scans(ids, jump_at=None):
    """id -> a scan-like object with a pose; the robot moves 5 cm per scan, or 3 m at
    ``jump_at`` (it was put elsewhere)."""
    out, x = {}, 0.0
    for i in ids:
        x += 3.0 if i == jump_at else 0.05
        out[i] = types.SimpleNamespace(pose=(x, 0.0, 0.0))
    return out


def test_answered_scan_is_lag_scans_before_the_one_shown():
    scans = _scans(range(100, 120))
    assert answered_scan(115, scans, lag=3) == 112
    assert answered_scan(115, scans, lag=0) == 115
    assert answered_scan(115, scans) == 115 - LAG


def test_answered_scan_falls_back_to_the_scan_shown():
    scans = _scans(range(100, 120))
    assert answered_scan(101, scans, lag=3) == 101  # the console never saw scan 98
    jumped = _scans(range(100, 120), jump_at=114)
    assert answered_scan(115, jumped, lag=3) == 115  # put elsewhere in between: not that view
    assert answered_scan(118, jumped, lag=3) == 115  # three scans after the jump: paired again
    poses = {i: (0.05 * i, 0.0) for i in range(10)}
    assert answered_scan(9, poses, lag=2, pose=lambda p: p) == 7


def test_nearest_votes_counts_the_labels_of_the_k_nearest():
    X = np.array([[0.0], [0.1], [0.2], [0.9], [1.0]])
    y = np.array([0, 0, 1, 2, 2])
    votes = nearest_votes(np.array([[0.05], [0.95]]), X, y, 3, 3)
    assert votes.tolist() == [[2.0, 1.0, 0.0], [0.0, 1.0, 2.0]]
    assert nearest_votes(np.array([[0.5]]), X, y, 99, 3).tolist() == [[2.0, 1.0, 2.0]]


def test_the_sided_vote_keeps_a_tapped_turn_and_drops_a_confused_side():
    votes = np.zeros((5, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, i["fwd-right"]], votes[0, i["fwd-left"]] = 55, 45    # over-steering: forward
    votes[1, i["fwd-right"]], votes[1, i["rot-left"]] = 7, 3      # left and right confused
    votes[2, i["fwd"]], votes[2, i["rot-right"]] = 65, 35         # a turn tapped between
    votes[2, i["rot-left"]] = 5                                   # forward presses, one wrong
    votes[3, i["rot-right"]] = 3                                  # all agree
    votes[4, i["fwd"]], votes[4, i["rot-left"]], votes[4, i["rot-right"]] = 80, 8, 7
    assert [NAMES[a] for a in sided_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd", "fwd-right", "fwd-right", "rot-right", "fwd"]
    # two thirds: a side at least that heavy is kept (a zig-zag), a lighter one dropped
    edge = np.zeros((2, 5))
    edge[0, i["fwd-left"]], edge[0, i["fwd-right"]] = 3, 2
    edge[1, i["fwd-left"]], edge[1, i["fwd-right"]] = 30, 19
    assert [NAMES[a] for a in sided_actions(edge, DEFAULT_ACTIONS)] == ["fwd", "fwd-left"]
    # a learner takes the side share it is given (the study's ablation)
    for share, want in ((0.0, ["fwd", "fwd"]), (1.0, ["fwd-left", "fwd-left"])):
        learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, side_share=share)
        assert learner.rule.editing.side_share == share
        assert [NAMES[a] for a in learner._edit(edge)] == want


def _walk(n=200, seed=0):
    """A run along a wall: the right-hand distance grows slowly; the person steers right
    once it is beyond 1 m; one key in twenty is wrong."""
    rng = np.random.default_rng(seed)
    ranges, labels, truth = [], [], []
    for k in range(n):
        r = np.full(360, 3.0, dtype=np.float32)
        r[:60] = 0.5 + 1.0 * k / n
        right = "fwd-right" if r[0] > 1.0 else "fwd"
        truth.append(right)
        labels.append("rot-left" if rng.random() < 0.05 else right)
        ranges.append(r)
    return ranges, labels, truth


def test_person_learner_outvotes_wrong_keys():
    ranges, labels, truth = _walk()
    person = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following")
    stream = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, spawn="winner")
    for r, lab in zip(ranges, labels, strict=True):
        assert person.observe(r, 0.0, lab)
        stream.observe(r, 0.0, lab)
    wrong = [k for k, (lab, t) in enumerate(zip(labels, truth, strict=True)) if lab != t]
    assert wrong  # the walk has wrong keys
    assert all(person.predict(ranges[k]) == truth[k] for k in wrong)  # outvoted
    right = sum(person.predict(r) == t for r, t in zip(ranges, truth, strict=True))
    assert right >= 195
    # the label-by-label tree carves a sphere for each wrong key and loses the rest around it
    assert sum(stream.predict(r) == t for r, t in zip(ranges, truth, strict=True)) < right - 50
    assert person.vectors == person.seen == len(labels)


def test_person_learner_rebuilds_only_when_labels_came():
    ranges, labels, _ = _walk(60)
    person = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS)
    assert person.nodes == 1 and person.predict(ranges[0]) == "fwd"  # nothing learned yet
    person.observe_vectors([FEATURES["wall"].extract(r) for r in ranges[:30]], labels[:30])
    first = person.classifier
    assert person.classifier is first  # no new label: the same tree
    published = TreePolicy(first, person.features, person.actions)  # a snapshot: it stays
    follows = TreePolicy.from_learner(person)  # a corrective round's: the tree as it is now
    person.observe(ranges[30], 0.0, labels[30])
    second = person.classifier
    assert second is not first and published.classifier is first
    assert follows.classifier is second and person.classifier is second  # built once
    assert person.vectors == 31


def test_person_learner_copies_are_seeded_and_the_tree_saves(tmp_path):
    ranges, labels, _ = _walk(80)
    a = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, copies=2, seed=4)
    b = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, copies=2, seed=4)
    for r, lab in zip(ranges, labels, strict=True):
        a.observe(r, 0.0, lab)
        b.observe(r, 0.0, lab)
    X, y = a.training_set()
    assert len(y) == 3 * 80 and X.shape == (240, 5)
    assert a.classifier.tree_.equal(b.classifier.tree_)
    path = a.save(tmp_path / "person.rhbl")
    meta = load(path).metadata
    learning = meta["learning"]
    assert {k: learning[k] for k in ("rule", "lag", "estimated_lag", "k", "copies", "sigma",
                                     "vote", "seed")} == {
        "rule": "person", "lag": None, "estimated_lag": LAG, "k": PERSON.editing.k,
        "copies": 2, "sigma": PERSON.editing.sigma, "vote": "sided", "seed": 4}
    assert meta["tree_params"]["spawn"] == "winner"
    # the whole rule is in the metadata: read back, it is the rule the learner learned by
    assert LearningRule.of(meta) == a.rule and a.rule.editing.copies == 2
    assert learning["editing"]["method"] == "wilson-edited-knn"
    assert learning["guard"]["clearance"] == PERSON.guard.clearance > 0
    assert meta["provenance"]["vectors"] == 80


def test_the_tree_learns_its_training_set_in_the_rules_passes():
    """Each pass learns every edited vector again in another seeded order: after the rule's
    passes the tree answers more of its own training set as labelled than after one (a vector
    learned early is covered by a sphere spawned later), and the passes are stored."""
    ranges, labels, _ = _walk(300, seed=3)
    trees = {}
    for passes in (1, PERSON.passes):
        learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, passes=passes)
        for r, lab in zip(ranges, labels, strict=True):
            learner.observe(r, 0.0, lab)
        X, y = learner.training_set()
        names = np.array(learner.actions.names)
        trees[passes] = (learner.classifier.predict(X) == names[y]).mean()
        assert learner.metadata()["learning"]["passes"] == passes
        assert LearningRule.of(learner.metadata()).passes == passes
    assert PERSON.passes > 1
    assert trees[PERSON.passes] > trees[1]
    assert trees[PERSON.passes] >= 0.99
    with pytest.raises(ValueError, match="passes must be an integer >= 1"):
        PersonLearner(FEATURES["wall"], passes=0)


def test_a_margin_trees_passes_are_learned_in_one_fit():
    """``radius="margin"`` (a study's variant, docs/studies/people-for-every-behaviour.md): the
    rule's passes are one ``fit`` of the orders one after another, so every sphere is bounded
    by its margin among all the edited vectors (``partial_fit`` would bound by the parent
    only)."""
    from rhbl import HypersphereClassifier

    ranges, labels, _ = _walk(200, seed=5)
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, radius="margin")
    for r, lab in zip(ranges, labels, strict=True):
        learner.observe(r, 0.0, lab)
    tree = learner.classifier
    rows, y = learner._update()
    names = np.array(learner.actions.names)
    every = np.concatenate(learner._orders(len(y)))
    expect = HypersphereClassifier(default_label=names[0], spawn="winner", radius="margin").fit(
        rows[every], names[y[every]])
    parent = HypersphereClassifier(default_label=names[0], spawn="winner", radius="margin")
    for order in learner._orders(len(y)):
        parent.partial_fit(rows[order], names[y[order]])
    assert tree.get_params()["radius"] == "margin"
    assert tree.node_count_ == expect.node_count_
    assert (tree.predict(rows) == expect.predict(rows)).all()
    assert tree.node_count_ != parent.node_count_


def test_person_learner_rejects_bad_settings_and_labels():
    with pytest.raises(ValueError, match="k must be an integer >= 1"):
        PersonLearner(FEATURES["wall"], k=0)
    with pytest.raises(ValueError, match="copies must be"):
        PersonLearner(FEATURES["wall"], copies=-1)
    with pytest.raises(TypeError, match="vote"):  # one vote: the rule's (studies: benchmarks)
        PersonLearner(FEATURES["wall"], vote="mode")
    person = PersonLearner(FEATURES["wall"])
    with pytest.raises(ValueError, match="'jump' is not an action"):
        person.observe(np.full(360, 1.0), 0.0, "jump")
    with pytest.raises(ValueError, match="rebuilt from its labels"):
        person.compact()


def test_observe_vectors_learns_as_one_by_one():
    ranges, labels, _ = _walk(50)
    X = [FEATURES["wall"].extract(r) for r in ranges]
    batch = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, spawn="winner")
    single = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, spawn="winner")
    assert batch.observe_vectors(X, labels) == 50
    for x, lab in zip(X, labels, strict=True):
        single.observe_vector(x, lab)
    assert batch.classifier.tree_.equal(single.classifier.tree_)
    assert batch.vectors == batch.seen == 50
    with pytest.raises(ValueError, match="2 vectors but 1 labels"):
        batch.observe_vectors(X[:2], labels[:1])
    with pytest.raises(ValueError, match="'jump' is not an action"):
        batch.observe_vectors(X[:1], ["jump"])


def _delayed_labels(lag: int, n: int = 1500, seed: int = 0):
    """A robot's features drifting smoothly (5 slow sinusoids per feature), the label the
    nearest of 5 prototypes to the features ``lag`` steps earlier (a person answering what they
    saw a reaction time ago): (W, y), W[t, l] the features l steps before t."""
    rng = np.random.default_rng(seed)
    t = np.arange(n + 8)[:, None, None]
    f = rng.uniform(0.05, 0.2, (1, 5, 5))
    ph = rng.uniform(0, 2 * np.pi, (1, 5, 5))
    x = 0.5 + 0.1 * np.sin(f * t + ph).sum(axis=2)  # (n + 8, 5)
    protos = rng.uniform(0.3, 0.7, (5, 5))
    lab = ((x[:, None, :] - protos[None]) ** 2).sum(axis=2).argmin(axis=1)
    idx = np.arange(8, n + 8)
    W = np.stack([x[idx - lag_] for lag_ in range(MAX_LAG + 1)], axis=1)
    return W, lab[idx - lag]


@pytest.mark.parametrize("lag", [3, 4, 5])
def test_estimate_lag_finds_the_lag_the_labels_answer(lag):
    W, y = _delayed_labels(lag)
    found, agreement = estimate_lag(W, y, k=5, n_labels=5)
    assert found == lag, agreement
    assert len(agreement) == MAX_LAG + 1 and agreement[lag] > agreement[0]


def test_a_long_sessions_lag_is_estimated_from_an_even_spread_of_its_decisions():
    """Past ``decisions`` changes of key the estimate answers that many, evenly spread (its cost
    grows with the labels, not their square); below it nothing changes."""
    W, y = _delayed_labels(4, n=3000)
    change = y[1:] != y[:-1]
    n_decisions = int((np.r_[True, change] | np.r_[change, False]).sum())
    assert n_decisions > 300
    full = estimate_lag(W, y, k=5, n_labels=5)
    assert estimate_lag(W, y, k=5, n_labels=5, decisions=n_decisions) == full  # the cap unused
    assert estimate_lag(W, y, k=5, n_labels=5, decisions=10**6) == full
    found, agreement = estimate_lag(W, y, k=5, n_labels=5, decisions=300)
    assert found == 4 and agreement != full[1]  # fewer decisions answered, the same lag
    assert estimate_lag(W, y, k=5, n_labels=5, decisions=300) == (found, agreement)


def test_person_learner_estimates_its_lag_from_the_earlier_scans():
    W, y = _delayed_labels(4)
    a = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, k=5, lag=None)
    fixed = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, k=5, lag=4)
    assert a.lag is None and a.estimated_lag == LAG  # no labels yet: the fixed default
    for w, label in zip(W, y, strict=True):
        a.observe_vector(w[0], NAMES[label], earlier=w[1:])
        fixed.observe_vector(w[4], NAMES[label])  # paired 4 scans back, as Pairing(lag=4) does
    assert a.estimated_lag == 4 and fixed.estimated_lag == 4 and fixed.lag_agreement == []
    assert len(a.lag_agreement) == MAX_LAG + 1
    # built at the estimated lag: the same training set as the learner with that lag fixed
    assert a.classifier.tree_.equal(fixed.classifier.tree_)
    assert a.metadata()["learning"]["estimated_lag"] == 4
    with pytest.raises(ValueError, match="lag"):
        PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, lag=MAX_LAG + 1)
    assert parse_lag("auto") is None and parse_lag(" 4") == 4
    for bad in ("7", "-1", "x", ""):
        with pytest.raises(ValueError, match="'auto' or an integer 0..6"):
            parse_lag(bad)


def test_labelled_gives_the_labels_as_given_with_their_earlier_scans():
    person = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following")
    x = np.linspace(0.1, 0.5, FEATURES["wall"].dim)
    person.observe_vector(x, "fwd", earlier=[x + 0.1, x + 0.2])
    person.observe_vector(x + 0.3, "rot-left")
    W, labels = person.labelled()
    assert labels == ["fwd", "rot-left"] and W.shape == (2, MAX_LAG + 1, len(x))
    assert np.allclose(W[0, 0], x) and np.allclose(W[0, 1], x + 0.1)
    assert np.allclose(W[0, 3:], x)  # lags not held: the label's own scan
    fixed = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, lag=2)
    fixed.observe_vector(x, "fwd")
    assert fixed.labelled()[0].shape == (1, 1, len(x))


@pytest.mark.parametrize("lag", [2, None])
def test_the_tree_kept_up_to_date_label_by_label_is_the_tree_built_at_once(lag):
    """Live (the tree asked for after every few labels: only the votes a new label enters are
    taken again) and at once (every vote): the same training set and the same tree."""
    W, y = _delayed_labels(4, n=700)
    rule = PERSON if lag is not None else PERSON.replace(
        alignment=dataclasses.replace(PERSON.alignment, regrow=0.0))  # the lag: every build
    live = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, lag=lag, k=10)
    once = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, lag=lag, k=10)
    for t, (w, label) in enumerate(zip(W, y, strict=True)):
        for learner in (live, once):
            if lag is None:
                learner.observe_vector(w[0], NAMES[label], earlier=w[1:])
            else:
                learner.observe_vector(w[lag], NAMES[label])
        if t % 7 == 0 or t in (9, 10, 11, 12):
            _ = live.classifier
    a, b = live.training_set(), once.training_set()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert live.classifier.tree_.equal(once.classifier.tree_)


def test_past_extend_above_the_tree_is_extended_and_learned_again_at_each_growth():
    """A long session (``extend_above``: here from the first vector): the tree so far is
    extended with what is new or voted otherwise (a tree handed out stays as it was), and it is
    learned again at once when the vectors grew by the alignment's ``regrow``."""
    rng = np.random.default_rng(2)
    rule = PERSON.replace(extend_above=0, lag=0)
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, k=5, copies=0)
    learner.observe_vectors(rng.uniform(0.1, 0.4, (400, 5)), ["fwd"] * 400)
    first = learner.classifier
    assert learner._whole == 400  # the first tree: learned at once
    corner = rng.uniform(0.8, 0.9, (20, 5))  # a place nobody showed before, one key
    learner.observe_vectors(corner, ["rot-left"] * 20)
    second = learner.classifier
    assert second is not first and learner._whole == 400  # extended, not learned again
    assert set(map(str, second.predict(corner))) == {"rot-left"}
    assert set(map(str, first.predict(corner))) == {"fwd"}  # handed out before: as it was
    learner.observe_vectors(rng.uniform(0.1, 0.4, (40, 5)), ["fwd"] * 40)  # 460 >= 400 * 1.125
    _ = learner.classifier
    assert learner._whole == 460  # grown by an eighth: learned again at once


def test_in_the_background_a_growth_points_label_is_in_the_tree_before_the_relearn_ends():
    """``background`` (the live learner's): at a growth point the build extends the tree so far
    at once (the new labels are in it) and the tree is learned again beside; the next build
    after that ends takes it, extended with what came meanwhile: then the same tree as a
    learner that relearned at once. A copy has no relearn under way."""
    rng = np.random.default_rng(2)
    rule = PERSON.replace(extend_above=0, lag=0)
    live, once = (PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, k=5, copies=2,
                                background=b) for b in (True, False))
    base = rng.uniform(0.1, 0.4, (400, 5))
    for learner in (live, once):
        learner.observe_vectors(base, ["fwd"] * 400)
    assert live.classifier.tree_.equal(once.classifier.tree_)  # the first tree: at once
    assert not live.relearning
    corner = rng.uniform(0.8, 0.9, (60, 5))  # grown by an eighth, a place nobody showed
    for learner in (live, once):
        learner.observe_vectors(corner, ["rot-left"] * 60)
    grown = live.classifier
    assert live.relearning and live._whole == 1200  # (vectors: a label and its 2 copies)
    assert set(map(str, grown.predict(corner))) == {"rot-left"}  # extended: the labels are in
    assert copy.deepcopy(live)._job is None
    assert live.wait_relearned(60)
    last = rng.uniform(0.1, 0.4, (3, 5))
    for learner in (live, once):
        _ = learner.classifier  # (once: learned again at once here)
        learner.observe_vectors(last, ["fwd-left"] * 3)
    taken = live.classifier
    assert not live.relearning and live._whole == once._whole == 1380
    assert taken.tree_.equal(once.classifier.tree_)


def test_in_the_background_a_new_lags_votes_are_taken_beside_and_the_old_lag_builds_meanwhile():
    """``background``: when the lag estimated again differs, every vote at it is taken in a
    thread of its own while the builds go on at the lag the tree was built with (the
    snapshot's ``estimated_lag`` says so); once taken, the same edited training set as a
    learner that voted at once, and the tree is learned again beside."""
    W2, y2 = _delayed_labels(2, n=400)
    W5, y5 = _delayed_labels(5, n=2000, seed=1)
    rule = PERSON.replace(extend_above=0)
    live, once = (PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, k=5, copies=1,
                                background=b) for b in (True, False))

    def give(W, y) -> None:
        for learner in (live, once):
            for w, label in zip(W, y, strict=True):
                learner.observe_vector(w[0], NAMES[label], earlier=w[1:])

    give(W2, y2)
    _ = live.classifier
    assert live._edited.lag == 2 and not live.relearning
    give(W5[:1000], y5[:1000])
    for t in range(1000, 2000):  # a label a build, until the lag estimated is another
        give(W5[t:t + 1], y5[t:t + 1])
        _ = live.classifier
        if live._revote is not None:
            break
    new = live.estimated_lag
    assert new > 2 and live._edited.lag == 2  # voted beside: lag 2 meanwhile
    assert live.metadata()["learning"]["estimated_lag"] == 2
    give(W5[t + 1:t + 3], y5[t + 1:t + 3])
    _ = live.classifier  # (a build while it votes, maybe)
    assert live.wait_relearned(60)
    give(W5[t + 3:t + 4], y5[t + 3:t + 4])
    _ = live.classifier  # the votes taken: a relearn begun beside
    assert live._edited.lag == new and live._job is not None
    assert live.metadata()["learning"]["estimated_lag"] == new
    a, b = live.training_set(), once.training_set()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_a_long_sessions_lag_is_estimated_again_one_lag_a_build():
    """Past ``extend_above`` no build waits for a whole estimate: each computes one lag's
    agreement of the estimate begun when the labels had grown by ``regrow``; the lag so far
    meanwhile, the estimate's lag once every lag is done (the same as at once)."""
    W, y = _delayed_labels(4, n=1200)
    rule = PERSON.replace(extend_above=0)
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, rule=rule, k=5)
    for w, label in zip(W[:1000], y[:1000], strict=True):
        learner.observe_vector(w[0], NAMES[label], earlier=w[1:])
    assert learner.estimated_lag == 4  # the first estimate: at once
    for w, label in zip(W[1000:], y[1000:], strict=True):  # grown by a fifth
        learner.observe_vector(w[0], NAMES[label], earlier=w[1:])
    steps = 0
    while learner._work is not None or steps == 0:
        learner.observe_vector(W[-1, 0], NAMES[y[-1]], earlier=W[-1, 1:])  # a label, a build
        _ = learner.classifier
        steps += 1
    assert steps == MAX_LAG + 1 and learner._estimate[0] == 1201  # begun at the first build
    at_once = estimate_lag(np.concatenate([W, W[-1:]]), np.r_[y, y[-1]], k=5, n_labels=5)
    assert (learner.estimated_lag, learner.lag_agreement) == at_once
