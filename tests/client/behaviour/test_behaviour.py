"""Action set, features, scripted teachers, perturbed demonstrations, learner snapshots."""

import numpy as np
import pytest

from client.behaviour.actions import DEFAULT_ACTIONS, ActionError, ActionSet
from client.behaviour.features import (
    FEATURES,
    HEADING_LEFT,
    HEADING_RIGHT,
    FeatureError,
    FeatureSpec,
)
from client.behaviour.learning import (
    DemonstrationLearner,
    IncompatibleSnapshotError,
    TreePolicy,
    check_compatible,
)
from client.behaviour.policies import (
    Demonstrator,
    MazeTeacher,
    ReactiveFollower,
    ReactiveMazeTeacher,
    WallFollower,
)
from client.behaviour.tasks import make_policy


def test_action_set_defaults_roundtrip_and_errors():
    assert DEFAULT_ACTIONS.names == ("fwd", "fwd-left", "rot-left", "fwd-right", "rot-right")
    assert all(v != (0.0, 0.0) for v in DEFAULT_ACTIONS.values())  # never stands still
    assert ActionSet.from_dict(DEFAULT_ACTIONS.to_dict()) == DEFAULT_ACTIONS
    assert DEFAULT_ACTIONS.mirror("fwd-left") == "fwd-right"
    assert DEFAULT_ACTIONS["rot-left"][1] > 0 > DEFAULT_ACTIONS["rot-right"][1]
    with pytest.raises(ActionError, match="unknown action 'jump'"):
        DEFAULT_ACTIONS["jump"]
    with pytest.raises(ActionError, match="stands still"):
        ActionSet({"stop": (0.0, 0.0)})


def test_features_beams_clamp_scale_heading():
    spec = FEATURES["wall"]
    r = np.full(360, 8.0, dtype=np.float32)
    r[0] = 0.5  # right
    assert spec.beam_indices() == [0, 45, 90, 135, 180]
    r[180] = 1.0  # the 90-deg beam (straight ahead)
    x = spec.extract(r, 0.0)
    assert x.shape == (5,)
    assert x[0] == pytest.approx(0.25)  # 0.5 m / 2.0
    assert x[4] == pytest.approx(0.5)
    assert np.all((x >= 0) & (x <= 1))
    maze = FEATURES["maze"]
    assert maze.extract(r, 0.1)[-1] == HEADING_RIGHT
    assert maze.extract(r, 3.0)[-1] == HEADING_LEFT
    assert FeatureSpec.from_dict(maze.to_dict()) == maze
    win = FeatureSpec(beams=(10.0,), window=10.0)
    assert win.extract(r, 0.0)[0] == pytest.approx(0.25)  # min over 0..20 deg sees the 0.5 m
    with pytest.raises(FeatureError, match="outside"):
        FeatureSpec(beams=(200.0,))
    with pytest.raises(FeatureError, match="exceed 1"):
        FeatureSpec(beams=(0.0,), clamp=3.0, scale=2.0)


def _corridor_scan(right: float, left: float) -> np.ndarray:
    b = np.linspace(-np.pi / 2, np.pi / 2, 360)
    with np.errstate(divide="ignore"):
        r = np.where(b < 0, right / np.abs(np.sin(b)), left / np.abs(np.sin(b)))
    return np.minimum(np.nan_to_num(r, posinf=8.0), 8.0).astype(np.float32)


def test_reactive_teacher_is_the_default_and_a_pure_function_of_the_scan():
    p = make_policy("wall-following")
    assert isinstance(p, ReactiveFollower)
    assert isinstance(make_policy("maze"), ReactiveMazeTeacher)
    assert p.act(_corridor_scan(0.6, 1.4), (0, 0, 0)) == "fwd"
    assert p.act(_corridor_scan(0.3, 1.7), (0, 0, 0)) in ("fwd-left", "rot-left")
    assert p.act(_corridor_scan(1.1, 0.9), (0, 0, 0)) == "fwd-right"
    assert p.act(np.full(360, 0.35, dtype=np.float32), (0, 0, 0)) == "rot-left"
    # no memory: the same scan always gets the same label, whatever came before
    rng = np.random.default_rng(0)
    scans = [_corridor_scan(float(a), float(b)) for a, b in rng.uniform(0.3, 2.0, (20, 2))]
    first = [p.act(s, (0, 0, 0)) for s in scans]
    assert [p.act(s, (0, 0, 0)) for s in reversed(scans)] == first[::-1]
    # a function of the feature spec's sectors: equal feature vectors -> equal labels
    x = p.features.extract(scans[0])
    assert p.decide(x * p.features.scale) == first[0]
    with pytest.raises(ValueError, match="teacher style"):
        make_policy("wall-following", style="dance")


def test_wall_follower_steers_towards_the_target_distance():
    p = make_policy("wall-following", style="smooth")
    assert isinstance(p, WallFollower)
    assert p.act(_corridor_scan(0.6, 1.4), (0, 0, 0)) == "fwd"
    p.reset()
    assert p.act(_corridor_scan(0.3, 1.7), (0, 0, 0)) in ("fwd-left", "rot-left")
    p.reset()
    assert p.act(_corridor_scan(1.1, 0.9), (0, 0, 0)) == "fwd-right"
    # a wall close ahead: rotate left, away from the followed side
    p.reset()
    assert p.act(np.full(360, 0.35, dtype=np.float32), (0, 0, 0)) == "rot-left"


def test_wall_follower_is_smooth_minimum_dwell():
    p = WallFollower(dwell=3)
    near, far = _corridor_scan(0.3, 1.7), _corridor_scan(1.1, 0.9)
    labels = [p.act(near if i % 2 else far, (0, 0, 0)) for i in range(12)]
    switches = sum(a != b for a, b in zip(labels, labels[1:], strict=False))
    assert switches <= 4  # a bang-bang expert would switch on every step


def test_maze_teacher_and_unknown_task():
    assert isinstance(make_policy("maze", style="smooth"), MazeTeacher)
    with pytest.raises(ValueError, match="no scripted teacher"):
        make_policy("dance")


def test_demonstrator_labels_with_the_expert_while_perturbing():
    rng = np.random.default_rng(1)
    demo = Demonstrator(make_policy("wall-following"), perturb=0.5, rng=rng)
    scan = _corridor_scan(0.6, 1.4)
    pairs = [demo.step(scan, (0, 0, 0)) for _ in range(400)]
    assert all(label == "fwd" for label, _ in pairs)
    executed = [e for _, e in pairs]
    off = sum(e != "fwd" for e in executed) / len(executed)
    assert 0.15 < off < 0.7
    # perturbations are held (0.5-1.5 s), not single-step flicker
    runs = sum(a != b for a, b in zip(executed, executed[1:], strict=False))
    assert runs < 0.3 * len(executed)
    calm = Demonstrator(make_policy("wall-following"), perturb=0.0)
    assert all(e == lab for lab, e in (calm.step(scan, (0, 0, 0)) for _ in range(50)))


def test_a_tree_extended_keeps_the_refinements_of_its_parent(tmp_path):
    """``rhbl refine``'s record (its lineage and its asks) stays in the snapshots of a learner
    that extends the refined tree: the console lists the asks from the learner's tree."""
    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following")
    learner.observe(_corridor_scan(0.3, 1.7), 0.0, "fwd-left")
    assert "refinement" not in learner.metadata()
    record = [{"parent": "a.rhbl", "asks": [{"world": "room", "pose": [1.0, 2.0, 0.0]}]}]
    path = tmp_path / "refined.rhbl"
    learner.classifier.save(str(path), metadata={**learner.metadata(), "refinement": record})
    again = DemonstrationLearner.resume(path)
    again.observe(_corridor_scan(1.1, 0.9), 0.0, "fwd-right")
    assert again.metadata()["refinement"] == record
    assert TreePolicy.load(again.save(tmp_path / "next.rhbl")).metadata["refinement"] == record


def test_learner_observe_save_resume_and_compatibility(tmp_path):
    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, task="wall-following",
                                   spawn="winner")
    near, far = _corridor_scan(0.3, 1.7), _corridor_scan(1.1, 0.9)
    for _ in range(5):
        assert learner.observe(near, 0.0, "fwd-left")
        assert learner.observe(far, 0.0, "fwd-right")
    assert learner.predict(near, 0.0) == "fwd-left"
    assert learner.predict(far, 0.0) == "fwd-right"
    meta = learner.metadata()
    assert set(meta) >= {"features", "actions", "task", "provenance"}
    assert meta["provenance"]["vectors"] == 10
    path = learner.save(tmp_path / "t.rhbl")
    again = DemonstrationLearner.resume(path)
    assert again.features == FEATURES["wall"] and again.actions == DEFAULT_ACTIONS
    assert again.parent == str(path)
    assert again.predict(far, 0.0) == "fwd-right"
    again.observe(near, 0.0, "rot-left")
    assert again.vectors == 11
    policy = TreePolicy.load(path)
    assert policy.act(near, (0, 0, 0)) == "fwd-left"
    check_compatible(meta, FEATURES["wall"], DEFAULT_ACTIONS)
    with pytest.raises(IncompatibleSnapshotError, match="other features"):
        check_compatible(meta, FEATURES["maze"])
    with pytest.raises(IncompatibleSnapshotError, match="other features"):
        TreePolicy.load(path, features=FEATURES["maze"])
    with pytest.raises(IncompatibleSnapshotError, match="no 'features'"):
        check_compatible({}, FEATURES["wall"])
    with pytest.raises(ValueError, match="not an action"):
        learner.observe(near, 0.0, "jump")


def test_learner_sample_selection():
    learner = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, stride=2)
    scan = _corridor_scan(0.6, 1.4)
    got = [learner.observe(scan, 0.0, "fwd") for _ in range(6)]
    assert got == [True, False, True, False, True, False]
    dedup = DemonstrationLearner(FEATURES["wall"], DEFAULT_ACTIONS, min_delta=0.01)
    assert [dedup.observe(scan, 0.0, "fwd") for _ in range(3)] == [True, False, False]
    assert dedup.observe(scan, 0.0, "fwd-left")  # a new label is always offered


def _windows_one_by_one(spec: FeatureSpec, ranges, yaw: float) -> np.ndarray:
    """The features as extract computed them window by window (before np.minimum.reduceat)."""
    r = np.asarray(ranges)
    out = np.empty(spec.dim, dtype=np.float64)
    for k, (lo, hi) in enumerate(spec._slices(r.size)):
        v = float(r[lo]) if hi - lo == 1 else float(r[lo:hi].min())
        out[k] = min(v if v >= 0.0 else spec.clamp, spec.clamp) / spec.scale
    if spec.heading == "lr":
        out[-1] = HEADING_RIGHT if np.cos(yaw) >= 0.0 else HEADING_LEFT
    return out


def test_features_in_one_call_equal_the_windows_one_by_one():
    """Every shipped spec and odd ones (a window reaching past either end of the scan, beams
    out of order) on scans of float32 and float64 with NaN, negative, zero and inf readings."""
    rng = np.random.default_rng(0)
    specs = [*FEATURES.values(), FeatureSpec(beams=(180.0, 0.0, 90.0), window=20.0),
             FeatureSpec(beams=(170.0, 180.0), window=15.0, heading="lr"),
             FeatureSpec(beams=(0.0,), window=200.0)]
    for spec in specs:
        for count in (2, 3, 90, 360, 361):
            for dtype in (np.float32, np.float64):
                for _ in range(40):
                    r = (rng.random(count) * 3).astype(dtype)
                    k = int(rng.integers(0, 4))
                    r[rng.integers(0, count, k)] = rng.choice([np.nan, -1.0, 0.0, np.inf], k)
                    yaw = float(rng.uniform(-4, 4))
                    assert (spec.extract(r, yaw).tobytes()
                            == _windows_one_by_one(spec, r, yaw).tobytes()), (spec, r)


def test_learner_learns_queued_vectors_whenever_the_tree_is_read():
    """observe queues vectors; every read of the tree (the learner's, or a TreePolicy's made
    from it) sees all of them, in the order offered: the same tree as one partial_fit per
    vector."""
    from rhbl import HypersphereClassifier

    spec = FEATURES["wall"]
    rng = np.random.default_rng(1)
    scans = (rng.random((700, 360)) * 2.5).astype(np.float32)
    labels = rng.choice(DEFAULT_ACTIONS.names, len(scans))
    learner = DemonstrationLearner(spec, DEFAULT_ACTIONS)
    drives = TreePolicy.from_learner(learner)  # a corrective round's: the tree as it grows
    one = HypersphereClassifier(default_label=DEFAULT_ACTIONS.names[0])
    for i, (r, label) in enumerate(zip(scans, labels, strict=True)):
        assert learner.observe(r, 0.0, label)
        one.partial_fit(spec.extract(r)[None, :], [label])
        if i in (0, 1, 17, 300, 650):
            want = one.predict_one(spec.extract(scans[i // 2]))
            assert drives.act(scans[i // 2], (0.0, 0.0, 0.0)) == want
            assert drives.classifier.node_count_ == one.node_count_
            assert learner.nodes == one.node_count_
            assert learner.predict(scans[i // 2]) == want
    assert learner.classifier.tree_equal(one) and learner.vectors == len(scans)
    assert learner.classifier.n_seen_ == one.n_seen_ == len(scans)
