"""``benchmarks/bench_live.py``: a person's tree reflecting new labels as a session grows."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.teaching import PersonLearner


@pytest.fixture(scope="module")
def bench(request):
    return request.getfixturevalue("load_benchmark")("bench_live")


def test_the_search_of_before_finds_the_kd_trees_neighbours(bench):
    rng = np.random.default_rng(0)
    X, Q = rng.uniform(0, 1, (300, 5)), rng.uniform(0, 1, (40, 5))
    d, i = bench.BruteIndex(X).query(Q, 7)
    from scipy.spatial import cKDTree

    dk, ik = cKDTree(X).query(Q, k=7)
    assert np.allclose(d, dk) and np.array_equal(i, ik)


def test_it_prints_a_row_per_size_and_refuses_bad_sizes(bench, capsys):
    assert bench.main(["--sizes", "120,2000", "--repeat", "2", "--batch", "3",
                       "--old-max", "200"]) == 0
    rows = [r.split("|") for r in capsys.readouterr().out.splitlines()
            if r.startswith("| 1") or r.startswith("| 2")]
    assert [r[1].strip() for r in rows] == ["120", "2000"]
    assert all(float(r[2]) > 0 for r in rows) and rows[0][15].strip().endswith("x")
    short, long = ([c.strip() for c in r[7:12]] for r in rows)
    assert short == ["-"] * 5  # below extend_above: no growth point to time
    # past it: the growth point's label, the labels while it relearned (worst, builds), the
    # relearn's seconds, the label relearned in its place, a new lag's label
    assert all(float(c.split()[0]) >= 0 for c in long) and long[1].endswith(")")
    for bad in (["--sizes", "10"], ["--sizes", "a,b"], ["--repeat", "0"]):
        with pytest.raises(SystemExit) as exc:
            bench.main(bad)
        assert exc.value.code == 2


def test_the_memory_figure_counts_the_learners_arrays(bench):
    learner = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS)
    rng = np.random.default_rng(1)
    learner.observe_vectors(rng.uniform(0, 1, (100, 5)), ["fwd"] * 100)
    _ = learner.classifier
    assert bench.learner_mb(learner) > learner._W.nbytes / 1e6
