"""A fleet's scans answered together: ``FeatureSpec.extract_many`` and ``TreePolicy.act_many``
give what ``extract`` and ``act`` give one scan at a time, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES, FeatureError, FeatureSpec
from client.behaviour.learning import TreePolicy
from rhbl import HypersphereClassifier

specs = st.builds(
    FeatureSpec,
    beams=st.lists(st.sampled_from([0.0, 10.0, 22.5, 45.0, 90.0, 135.0, 170.0, 180.0]),
                   min_size=1, max_size=6).map(tuple),
    clamp=st.sampled_from([1.0, 2.0]), scale=st.just(2.0),
    heading=st.sampled_from([None, "lr"]), window=st.sampled_from([0.0, 5.0, 11.25, 40.0]))
values = st.one_of(st.floats(0.0, 9.0, width=32), st.sampled_from([np.nan, -1.0, 0.0, -0.0]))


@settings(max_examples=150, deadline=None)
@given(specs, st.integers(2, 40), st.integers(0, 6), st.data())
def test_extract_many_is_extract_row_by_row(spec, beams, n, data):
    ranges = np.array(data.draw(st.lists(st.lists(values, min_size=beams, max_size=beams),
                                         min_size=n, max_size=n)),
                      dtype=np.float32).reshape(n, beams)
    yaws = data.draw(st.lists(st.floats(-7.0, 7.0), min_size=n, max_size=n))
    many = spec.extract_many(ranges, yaws)
    one = [spec.extract(row, y) for row, y in zip(ranges, yaws, strict=True)]
    assert many.shape == (n, spec.dim) and many.dtype == np.float64
    assert many.tobytes() == np.array(one, dtype=np.float64).reshape(n, spec.dim).tobytes()


def test_extract_many_refuses_what_it_cannot_batch():
    spec = FEATURES["wall"]
    with pytest.raises(FeatureError, match="shape"):
        spec.extract_many(np.ones(360, np.float32))
    with pytest.raises(FeatureError, match="headings"):
        spec.extract_many(np.ones((2, 360), np.float32), [0.0])


def test_act_many_gives_the_actions_of_act():
    rng = np.random.default_rng(0)
    spec = FEATURES["wall"]
    scans = rng.uniform(0.1, 4.0, (300, 360)).astype(np.float32)
    names = list(DEFAULT_ACTIONS)
    clf = HypersphereClassifier().fit(spec.extract_many(scans[:200]),
                               [names[i % len(names)] for i in range(200)])
    policy = TreePolicy(clf, spec, DEFAULT_ACTIONS)
    yaws = rng.uniform(-3.0, 3.0, 300)
    assert policy.act_many(scans, yaws) == [policy.act(r, (0.0, 0.0, y))
                                            for r, y in zip(scans, yaws, strict=True)]
    assert policy.act_many(scans[:0]) == []
