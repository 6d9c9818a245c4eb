"""``benchmarks/bench_person.py``: the person rule's rebuild as a session grows."""

from __future__ import annotations

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.rule import PERSON

MAX_LAG = PERSON.alignment.max_lag


@pytest.fixture(scope="module")
def bench(request):
    return request.getfixturevalue("load_benchmark")("bench_person")


def test_the_demonstration_is_the_scripted_teachers_with_wrong_keys_and_earlier_scans(bench):
    W, y = bench.demonstration(400, wrong=0.12)
    assert W.shape == (400, MAX_LAG + 1, 5) and y.shape == (400,)
    # each label's lag j is the scan j steps before: label t's lag 1 is label t-1's lag 0
    assert np.array_equal(W[1:, 1], W[:-1, 0]) and np.array_equal(W[6:, 6], W[:-6, 0])
    assert set(np.unique(y)) <= set(range(len(DEFAULT_ACTIONS)))
    clean = bench.demonstration(400, wrong=0.0)[1]
    flipped = float(np.mean(clean != y))
    assert 0.06 < flipped < 0.2  # ~12% wrong keys, every one a different action


def test_it_prints_a_row_per_size_and_refuses_bad_sizes(bench, capsys):
    assert bench.main(["--sizes", "100,200", "--repeat", "1"]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| 1") or
            r.startswith("| 2")]
    assert [r.split("|")[1].strip() for r in rows] == ["100", "200"]
    for bad in (["--sizes", "10"], ["--sizes", "a,b"], ["--repeat", "0"]):
        with pytest.raises(SystemExit) as exc:
            bench.main(bad)
        assert exc.value.code == 2
