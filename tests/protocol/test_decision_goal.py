"""The goal of a controller's decision (``Decision.goal``, ``goal_why``: optional fields added
after v1, docs/protocol.md): round trips, a decision without them encoded as before, and hostile
values refused with the field named, never anything but a DecodeError."""

from __future__ import annotations

import contextlib

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.codec import DecodeError
from protocol.messages import Decision, DecisionGoal

WHY = ("goal 1/2 (beacon 1) done at 12.3 s: completion tree: sphere 95 (depth 91) says done "
       "at beacon 1 (range 0.59 m, bearing 5 deg)")
PLAIN = Decision(scan_id=9, action="fwd", path=((0, 0, 2.5, "fwd"),), ts=1.5,
                 snapshot_id="ab:3", nodes=3)
GOAL = Decision(scan_id=9, action="fwd", path=((0, 0, 2.5, "fwd"),), ts=1.5,
                snapshot_id="ab:3", nodes=3, goal=DecisionGoal(1, 2, 2), goal_why=WHY)


def _map(msg) -> dict:
    return msgpack.unpackb(msg.encode(), raw=False)


def _pack(m: dict) -> bytes:
    return msgpack.packb(m, use_bin_type=True)


def test_round_trips():
    assert Decision.decode(GOAL.encode()) == GOAL
    got = _map(GOAL)
    assert got["goal"] == {"index": 1, "count": 2, "beacon": 2} and got["goal_why"] == WHY
    assert GOAL.goal.describe() == "goal 2/2 (beacon 2)"
    first = Decision(scan_id=1, action="fwd", goal=DecisionGoal(0, 3, 5))  # no change yet
    assert Decision.decode(first.encode()) == first and "goal_why" not in _map(first)


def test_a_decision_without_goals_is_encoded_as_before():
    """A tree without goals: the fields are left out, an old peer's decision decodes to None."""
    m = _map(PLAIN)
    assert "goal" not in m and "goal_why" not in m
    assert _map(GOAL).keys() - m.keys() == {"goal", "goal_why"}
    old = {k: v for k, v in _map(GOAL).items() if k not in ("goal", "goal_why")}
    got = Decision.decode(_pack(old))
    assert got == PLAIN and got.goal is None and got.goal_why is None
    assert Decision.decode(_pack(dict(old, goal=None, goal_why=None))) == PLAIN  # nil: absent


@pytest.mark.parametrize("goal, field, says", [
    ([1, 2, 2], "goal", "a map of index, count, beacon"),
    ("goal 2", "goal", "a map of index, count, beacon"),
    ({"count": 2, "beacon": 2}, "goal.index", "missing"),
    ({"index": 0, "beacon": 2}, "goal.count", "missing"),
    ({"index": 0, "count": 2}, "goal.beacon", "missing"),
    ({"index": -1, "count": 2, "beacon": 2}, "goal.index", ">= 0"),
    ({"index": True, "count": 2, "beacon": 2}, "goal.index", "an integer"),
    ({"index": 0.0, "count": 2, "beacon": 2}, "goal.index", "an integer"),
    ({"index": 0, "count": 2, "beacon": -3}, "goal.beacon", ">= 0"),
    ({"index": 0, "count": "2", "beacon": 2}, "goal.count", "an integer"),
    ({"index": 2, "count": 2, "beacon": 2}, "goal", "index below count"),
    ({"index": 0, "count": 0, "beacon": 2}, "goal", "index below count"),
])
def test_a_hostile_goal_is_refused_naming_the_field(goal, field, says):
    with pytest.raises(DecodeError, match=f"field '{field}': .*{says}"):
        Decision.decode(_pack(dict(_map(GOAL), goal=goal)))


@pytest.mark.parametrize("why, says", [
    (5, "a string"), (b"done", "a string"), (["done"], "a string"),
    ("x" * (Decision.MAX_GOAL_WHY + 1), f"a string of at most {Decision.MAX_GOAL_WHY} characters"),
])
def test_a_hostile_goal_why_is_refused_naming_the_field(why, says):
    with pytest.raises(DecodeError, match=f"field 'goal_why': expected {says}"):
        Decision.decode(_pack(dict(_map(GOAL), goal_why=why)))


values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats()
    | st.text(max_size=5) | st.binary(max_size=8),
    lambda c: st.lists(c, max_size=4) | st.dictionaries(
        st.sampled_from(["index", "count", "beacon", "x"]), c, max_size=4),
    max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(values, values)
def test_random_goals_only_ever_raise_decode_error(goal, why):
    with contextlib.suppress(DecodeError):
        d = Decision.decode(_pack(dict(_map(GOAL), goal=goal, goal_why=why)))
        assert d.goal is None or 0 <= d.goal.index < d.goal.count and d.goal.beacon >= 0
        assert d.goal_why is None or isinstance(d.goal_why, str)
