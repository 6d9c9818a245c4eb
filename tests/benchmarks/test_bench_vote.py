"""``benchmarks/bench_vote.py``: a session's labels learned again with other settings."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.rule import PERSON
from client.behaviour.teaching import PersonLearner


@pytest.fixture(scope="module")
def bench(request):
    return request.getfixturevalue("load_benchmark")("bench_vote")


@pytest.fixture(scope="module")
def session(request):
    W, y = request.getfixturevalue("load_benchmark")("bench_person").demonstration(300, wrong=0.1)
    return W, [DEFAULT_ACTIONS.names[i] for i in y]


def test_the_labels_learned_again_are_the_labels_as_a_learner_took_them(bench, session):
    W, labels = session
    again = bench.learn_again("person", W, labels, shuffle=3)
    direct = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following", seed=3)
    for w, label in zip(W, labels, strict=True):
        direct.observe_vector(w[0], label, earlier=w[1:])
    X1, y1 = again.training_set()
    X2, y2 = direct.training_set()
    assert np.array_equal(X1, X2) and np.array_equal(y1, y2)
    assert again.estimated_lag == direct.estimated_lag
    # another shuffle: every labelled vector again, in another order, with other copies
    other = bench.learn_again("person", W, labels, shuffle=4)
    X3, y3 = other.training_set()
    assert not np.array_equal(X1, X3) and len(X3) == len(X1) == (1 + PERSON.editing.copies) * len(labels)
    labelled = set(map(tuple, direct._vectors()))
    assert labelled <= set(map(tuple, X1)) and labelled <= set(map(tuple, X3))
    # without copies: the same vectors and votes, only the order differs
    a = bench.learn_again("person:copies=0", W, labels, shuffle=3).training_set()[0]
    b = bench.learn_again("person:copies=0", W, labels, shuffle=4).training_set()[0]
    assert not np.array_equal(a, b) and sorted(map(tuple, a)) == sorted(map(tuple, b))
    # a fixed lag takes the scan that many before each label's own
    fixed = bench.learn_again("person:lag=2+k=10+copies=0", W, labels, shuffle=0)
    assert fixed.k == 10 and fixed.estimated_lag == 2
    assert np.array_equal(np.sort(fixed.training_set()[0], axis=0), np.sort(W[:, 2], axis=0))


def test_it_refuses_an_unknown_method_or_person_before_teaching(bench):
    with pytest.raises(ValueError, match="unknown method"):
        bench.main(["--sessions", "steady:0", "--methods", "person,best"])
    with pytest.raises(SystemExit, match="no person model 'nobody'"):
        bench.main(["--sessions", "nobody:0"])


def test_a_learners_journal_gives_the_labels_it_holds_and_is_left_as_it_was(bench, tmp_path):
    from client.lineage import Lineage
    from protocol.messages import Withdrawal

    out = tmp_path / "tree.rhbl"
    core = Lineage(out, features="wall", teacher="person")
    rng = np.random.default_rng(2)
    scans = [(rng.uniform(0.2, 3.0, 360).astype(np.float32), float(rng.uniform(-3, 3)))
             for _ in range(60)]
    for k in range(6, 60):
        core.learn(k, 0.1 * k, *scans[k], DEFAULT_ACTIONS.names[k % 5], origin="p" * 16, seq=k,
                   earlier=[scans[k - i] for i in range(1, 7)])
    assert core.withdraw(Withdrawal(origin="p" * 16, id=0, first=50, upto=60, reason="undo"))
    assert core.rebuild()
    core.snapshot()
    held = core.learner.labelled()
    core.close()
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    W, labels = bench.labels_of(str(out))
    assert W.shape == (44, 7, 5) and len(labels) == 44  # the 10 withdrawn are left out
    assert np.array_equal(W, held[0]) and labels == held[1]
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    with pytest.raises(SystemExit, match="has no journal"):
        bench.labels_of(str(tmp_path / "other.rhbl"))
