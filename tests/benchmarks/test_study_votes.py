"""The votes the teaching studies compared (``benchmarks/study_votes.py``), kept for them;
the product's sided vote is ``client.behaviour.teaching.sided_actions``."""

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS
from client.behaviour.features import FEATURES
from client.behaviour.teaching import PersonLearner

NAMES = DEFAULT_ACTIONS.names


@pytest.fixture(scope="module")
def votes_module(request):
    return request.getfixturevalue("load_benchmark")("study_votes")


def test_majority_outvotes_a_lone_label_and_a_tie_keeps_the_own(votes_module):
    X = np.linspace(0.0, 1.0, 11).reshape(-1, 1)
    y = np.zeros(11, dtype=np.int64)
    y[5] = 3  # one wrong key in the middle of a run
    assert votes_module.majority_labels(X, y, 5, 5).tolist() == [0] * 11
    two = np.array([[0.0], [1.0]])
    assert votes_module.majority_labels(two, np.array([1, 2]), 2, 5).tolist() == [1, 2]


def test_the_interquartile_mean_hears_a_tapped_turn_as_forward(votes_module):
    votes = np.zeros((1, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, i["fwd"]], votes[0, i["rot-right"]], votes[0, i["rot-left"]] = 65, 35, 5
    assert NAMES[votes_module.trimmed_actions(votes, DEFAULT_ACTIONS)[0]] == "fwd"


def test_a_study_learner_edits_by_its_vote_and_refuses_an_unknown_one(votes_module):
    rng = np.random.default_rng(0)
    X = rng.uniform(0.2, 0.8, (120, 5))
    labels = [NAMES[k] for k in rng.integers(0, 5, 120)]
    mean = votes_module.StudyLearner(FEATURES["wall"], DEFAULT_ACTIONS, vote="mean", k=10)
    sided = votes_module.StudyLearner(FEATURES["wall"], DEFAULT_ACTIONS, vote="sided", k=10)
    person = PersonLearner(FEATURES["wall"], DEFAULT_ACTIONS, k=10)
    for learner in (mean, sided, person):
        learner.observe_vectors(X, labels)
    assert np.array_equal(sided.training_set()[1], person.training_set()[1])
    assert not np.array_equal(mean.training_set()[1], person.training_set()[1])
    assert mean.metadata()["learning"]["vote"] == "mean"
    with pytest.raises(ValueError, match="vote must be one of"):
        votes_module.StudyLearner(FEATURES["wall"], DEFAULT_ACTIONS, vote="mode")


def test_mean_action_of_left_and_right_steering_is_forward(votes_module):
    votes = np.zeros((3, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, [i["fwd-left"], i["fwd-right"]]] = 5
    votes[1, i["rot-left"]] = 4
    votes[1, i["fwd-left"]] = 1
    votes[2, i["fwd-right"]] = 1
    assert [NAMES[a] for a in votes_module.mean_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd", "rot-left", "fwd-right"]


def test_median_action_keeps_a_turn_a_minority_of_confused_keys_pulls_to_forward(votes_module):
    votes = np.zeros((3, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, i["fwd-right"]], votes[0, i["rot-left"]] = 6, 4     # left and right confused
    votes[1, [i["fwd-left"], i["fwd-right"]]] = 5                 # zig-zag: forward
    votes[2, i["rot-right"]], votes[2, i["fwd-left"]] = 6, 4
    assert [NAMES[a] for a in votes_module.median_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd-right", "fwd", "rot-right"]
    # the mean averages the minority in: forward, forward, an arc
    assert [NAMES[a] for a in votes_module.mean_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd", "fwd", "fwd-right"]



def test_median_turn_keeps_the_turn_of_the_median_and_the_pace_of_the_mean(votes_module):
    votes = np.zeros((2, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, i["fwd-right"]], votes[0, i["rot-left"]] = 6, 4     # left and right confused
    votes[1, i["rot-left"]], votes[1, i["fwd"]] = 6, 4            # turning, often going on
    assert [NAMES[a] for a in votes_module.median_turn_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd-right", "fwd-left"]
    # the median stops to rotate once half the keys were a rotation; the mean goes straight
    assert [NAMES[a] for a in votes_module.median_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd-right", "rot-left"]
    assert [NAMES[a] for a in votes_module.mean_actions(votes, DEFAULT_ACTIONS)] == ["fwd", "fwd-left"]


def test_the_interquartile_mean_averages_a_zig_zag_and_keeps_a_confused_turn(votes_module):
    votes = np.zeros((4, 5))
    i = {n: k for k, n in enumerate(NAMES)}
    votes[0, i["fwd-right"]], votes[0, i["fwd-left"]] = 55, 45    # over-steering: forward
    votes[1, i["fwd-right"]], votes[1, i["rot-left"]] = 6, 4      # left and right confused
    votes[2, i["rot-left"]], votes[2, i["fwd"]] = 6, 4
    votes[3, i["rot-right"]] = 3                                  # all agree
    assert [NAMES[a] for a in votes_module.trimmed_actions(votes, DEFAULT_ACTIONS)] == [
        "fwd", "fwd-right", "fwd-left", "rot-right"]
    # the median keeps the zig-zag's larger side; the mean lets the confusion pull to forward
    assert NAMES[votes_module.median_actions(votes[:1], DEFAULT_ACTIONS)[0]] == "fwd-right"
    assert NAMES[votes_module.mean_actions(votes[1:2], DEFAULT_ACTIONS)[0]] == "fwd"
