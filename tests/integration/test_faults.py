"""The fault campaign (``python -m campaigns.faults``) at CI size: no label the teacher publishes is
lost when the learner is SIGKILLed (acknowledged or resent with its scan until journaled, once),
also with labels in flight at the kill; a restarted server is driven again by the teacher; a
learner whose folder turns read-only (its mode, or a read-only bind mount) loses no label and
writes its snapshot once it is writable again; the compose scenario's services reconnect to a
restarted router."""

from __future__ import annotations

import os
import random

import pytest

from campaigns import faults

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]


def test_learner_kills_lose_no_label(tmp_path):
    r = faults.learner_kill(tmp_path, random.Random(1), kills=2, speedup=2.0)
    assert r["ok"] and r["labels published"] > 50, r
    assert r["lost"] == 0 and r["duplicates in journal"] == 0, r
    assert r["journaled"] == r["distinct labels"] == r["labels published"], r


def test_labels_in_flight_at_a_kill_are_resent_and_journaled_once(tmp_path):
    """The learner is stopped (SIGSTOP) while the teacher labels, so labels reach a process that
    never journals them (in flight), then SIGKILLed and restarted with the same command, 3 times:
    every label published is in the journal exactly once. Without the resends (the teacher's
    outbox) this loses the labels of every stop."""
    c = faults.Campaign(tmp_path)
    out = tmp_path / "tree.rhbl"
    try:
        c.watch()
        c.server("--speedup", "2")
        learner = faults._learner(c, out)
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower",
                          "--wait-learner-timeout", "60")
        assert c.wait(lambda: len(c.labels) > 20, 120), "no labels"
        for _ in range(3):
            mark = len(c.labels)
            learner.pause()
            # labels published to the stopped learner: received by nobody who journals
            assert c.wait(lambda m=mark: len(c.labels) >= m + 5, 60), "no label in flight"
            learner.kill()
            learner = faults._learner(c, out)
            mark = len(c.labels)
            assert c.wait(lambda m=mark: len(c.labels) >= m + 20, 120), "labelling not resumed"
        teacher_rc = teacher.stop()
        published = list(c.label_ids)
        assert learner.stop(timeout=60) == 0 and teacher_rc == 0
        recs, held = faults._held_labels(out)
        assert all(o is not None for o, _ in published)
        assert len(set(published)) == len(published) > 80
        assert sorted(set(published) - set(recs)) == []  # every label journaled...
        assert len(recs) == len(set(recs))  # ...once
        assert c.resent >= 15, c.resent  # at least 5 labels per stop came back as resends
    finally:
        c.close()


def test_a_restarted_server_is_driven_again(tmp_path):
    r = faults.server_restart(tmp_path, random.Random(2), restarts=1)
    assert r["ok"], r
    assert r["max s"] < 30


def test_a_killed_controller_stops_the_robot_within_the_watchdog(tmp_path):
    """Its liveliness token goes with it: the server takes the commands it sent before, then
    releases its hold (taken the other way round, the robot drove on until the watchdog)."""
    r = faults.controller_kill(tmp_path, random.Random(5))
    assert r["ok"] and r["max s"] < r["watchdog s"], r


def test_a_folding_learner_killed_recovers_with_a_bounded_journal(tmp_path):
    r = faults.learner_kill(tmp_path, random.Random(3), kills=2, speedup=2.0, fold=True)
    assert r["ok"] and r["labels published"] > 50, r
    # every label held (the snapshot's label set: folded ones too), none lost, none twice
    assert r["lost"] == 0 and r["journaled"] == r["distinct labels"], r
    assert r["duplicates in journal"] == 0
    # folded: the file holds about one snapshot interval of records, not all of them
    assert r["journal bytes"] < r["journaled"] * 1538 / 2, r


@pytest.mark.parametrize("how", ["mode", "mount"])
def test_a_read_only_folder_loses_no_label_and_is_written_again(tmp_path, how):
    if how == "mount" and os.geteuid() != 0:
        pytest.skip("a bind mount needs root")
    r = faults.readonly_folder(tmp_path, ro_for=3.0, how=how)
    assert r["ok"], r
    assert ("Errno 13" if how == "mode" else "Errno 30") in r["first error"], r
    assert r["labels while read-only"] > 0 and r["labels lost"] == 0, r
    assert r["error names the folder"] and not r["snapshot written while read-only"], r


def test_the_compose_scenario_reconnects_after_a_router_restart(tmp_path):
    r = faults.router_restart(tmp_path, random.Random(4), restarts=1)
    assert r["ok"], r
    assert r["services that exited"] == [] and r["max s"] < 30, r


def test_unacknowledged_labels_are_resent_and_a_full_outbox_pauses_the_teacher(tmp_path):
    """A "learner" that holds the token but never acknowledges (this test's session): the
    teacher resends its labels, stops labelling when its outbox (--outbox 30) is full, and
    labels again once an acknowledgement comes."""
    from protocol import keys
    from protocol.messages import LearnerAck

    c = faults.Campaign(tmp_path)
    token = None
    try:
        c.watch()
        token = c.session.liveliness().declare_token(keys.alive_key("learner", "r0-999999"))
        c.server("--speedup", "2")
        teacher = c.start("teacher", "teacher", "--policy", "wall-follower", "--outbox", "30",
                          "--resend-after", "1", "--wait-learner-timeout", "60")
        assert c.wait(lambda: len(c.labels) >= 30, 120), "no labels"
        # nothing acknowledged for 1 s: all 30 resent (with their scans), and no 31st label
        assert c.wait(lambda: c.resent >= 30, 30), c.resent
        assert len(c.labels) == 30 and len(set(c.label_ids)) == 30
        origin = c.label_ids[0][0]
        c.session.put(keys.learner_ack_key("r0"),
                      LearnerAck(origin=origin, upto=30).encode())
        assert c.wait(lambda: len(c.labels) >= 40, 60), "the teacher did not resume"
        assert [q for _, q in c.label_ids[:40]] == list(range(40))
        token.undeclare()  # no learner: the teacher does not wait for acks on exit
        token = None
        assert teacher.stop() == 0
    finally:
        if token is not None:
            token.undeclare()
        c.close()
