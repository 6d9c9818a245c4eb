"""The console's pure parts: episodes, undo and agreement (``Teaching``), where the learned
robot got into trouble (``Trouble``), the HTTP edge's refusals and message checks (``web``) and
what waits for a page (``_Page``: bounded)."""

from __future__ import annotations

import pytest

pytest.importorskip("aiohttp")

from client.roles.console.app import MAX_ERRORS, MAX_KINDS, _Page  # noqa: E402
from client.roles.console.lesson import MAX_ASKS, UNDO_MAX, Asks, Teaching, Trouble  # noqa: E402
from client.roles.console.web import MAX_DEPTH, Refusals, read_message  # noqa: E402


def _teach(t: Teaching, seqs, t0: float, dt: float = 0.1, pose=(1.0, 2.0, 0.0)):
    for k, seq in enumerate(seqs):
        t.labelled(seq, t0 + k * dt, pose)


def test_the_first_label_opens_an_episode_and_discard_gives_its_range():
    t = Teaching()
    _teach(t, range(0, 10), 0.0)
    assert t.current.n == 1 and t.current.start_pose == (1.0, 2.0, 0.0)
    t.stop(1.0)
    t.start((3.0, 4.0, 1.0), 2.0)
    _teach(t, range(10, 15), 2.0)
    e, first, upto = t.discard()
    assert (e.n, first, upto) == (2, 10, 15)
    assert t.withdrawn_range(first, upto) == 5
    t.discarded(e)
    assert e.state == "discarded" and e.labels == 0
    e, first, upto = t.discard()  # then the last one kept
    assert (e.n, first, upto) == (1, 0, 10)


def test_undo_takes_the_last_seconds_of_labels_still_standing():
    t = Teaching()
    _teach(t, range(0, 50), 0.0)  # 0.0 .. 4.9 s
    assert t.undo(1.0) == (40, 50)  # 3.9 .. 4.9
    assert t.withdrawn_range(40, 50) == 10
    assert t.undo(1.0) == (30, 40)  # again: the second before, not the withdrawn ones
    assert t.withdrawn_range(30, 40) == 10 and t.withdrawn == 20
    assert t.undo(UNDO_MAX) == (0, 30)
    t.withdrawn_range(0, 30)
    assert t.undo(1.0) is None
    for bad in (0, -1, UNDO_MAX + 1, float("nan"), "5", True, None):
        with pytest.raises(ValueError):
            t.undo(bad)


def test_agreement_counts_the_last_window_only():
    t = Teaching(window=60.0)
    for k in range(10):
        t.scored(k, agree=k % 2 == 0)
    assert t.agreement() == (0.5, 10)
    t.scored(100.0, True)  # the others are more than 60 s older
    assert t.agreement() == (1.0, 1)
    assert t.agreement(now=200.0) == (None, 0)


def test_a_rot_left_rot_right_loop_is_marked_where_it_began_and_the_robot_is_stuck():
    tr = Trouble()
    ts = 0.0
    for k in range(40):
        ts = k * 0.1
        tr.state(ts, (5.0, 5.0, 0.0), stall=False, controller_drives=True)
        tr.command(ts, "rot-left" if (k // 2) % 2 == 0 else "rot-right")
    assert tr.stuck is not None and tr.stuck["why"] == "loop"
    assert [m.kind for m in tr.markers].count("loop") == 1
    m = next(m for m in tr.markers if m.kind == "loop")
    assert (m.x, m.y) == (5.0, 5.0)
    tr.state(ts + 0.1, (5.0, 5.0, 0.0), stall=False, controller_drives=False)  # a person drives
    assert tr.stuck is None
    tr.clear()
    assert tr.markers == []


def test_the_controllers_guard_stepping_in_counts_as_a_loop_until_it_stays_out():
    tr = Trouble(guard_seconds=2.0)
    for k in range(10):  # the controller drives; its guard has not stepped in
        tr.state(k * 0.1, (2.0, 3.0, 0.0), stall=False, controller_drives=True)
        tr.guarded(k * 0.1, False)
    assert tr.stuck is None and tr.markers == []
    tr.guarded(1.0, True)  # it overruled a reversal: the loop is marked where the robot is
    tr.state(1.0, (2.0, 3.0, 0.5), stall=False, controller_drives=True)
    assert tr.stuck == {"why": "guard", "x": 2.0, "y": 3.0}
    assert [(m.kind, m.x, m.y) for m in tr.markers] == [("loop", 2.0, 3.0)]
    for k in range(11, 40):  # it steps in again and again: still one marker, still stuck
        tr.guarded(k * 0.1, k % 10 < 5)
        tr.state(k * 0.1, (2.0, 3.0, 0.1 * k), stall=False, controller_drives=True)
    assert tr.stuck["why"] == "guard" and len(tr.markers) == 1
    assert not any(m.kind == "stall" for m in tr.markers)  # turning in place: the guard's loop
    tr.state(6.5, (2.0, 3.0, 0.0), stall=False, controller_drives=True)  # 2 s without it
    assert tr.stuck is None or tr.stuck["why"] != "guard"
    tr.guarded(6.6, True)
    tr.state(6.6, (2.0, 3.0, 0.0), stall=False, controller_drives=True)
    assert tr.stuck["why"] == "guard" and tr.markers[0].count == 2  # the same place again
    tr.state(6.7, (2.0, 3.0, 0.0), stall=False, controller_drives=False)  # a person drives
    assert tr.stuck is None
    tr.guarded(6.8, True)  # a decision while the person drives: not the learned robot's
    assert tr.stuck is None and tr.markers[0].count == 2


def test_a_collision_and_a_stall_are_marked_once_each():
    tr = Trouble(stall_seconds=1.0)
    for k in range(30):
        tr.state(k * 0.1, (1.0, 1.0, 0.0), stall=10 <= k < 15, controller_drives=True)
        tr.command(k * 0.1, "fwd")
    kinds = sorted(m.kind for m in tr.markers)
    assert kinds == ["collision", "stall"]
    assert tr.stuck == {"why": "stall", "x": 1.0, "y": 1.0}


def test_refusals_say_a_burst_then_count_the_rest():
    now = [0.0]
    lines = []

    class _Log:
        def warning(self, fmt, *args):
            lines.append(fmt % args)

    r = Refusals(_Log(), burst=3, per=10.0, clock=lambda: now[0])
    for _ in range(100):
        r.say("GET / from 1.2.3.4: 400")
    assert len(lines) == 3 and r.total == 100
    now[0] = 11.0
    r.say("again")
    assert lines[3] == "97 more requests refused in 10 s (not each said)"
    assert len(lines) == 5


def test_read_message_refuses_deep_nesting_before_parsing():
    assert read_message('{"t": "undo", "seconds": 5}') == {"t": "undo", "seconds": 5}
    assert read_message('{"t": "x", "s": "[[[[[[[[[[[[["}')["s"].startswith("[")  # in a string
    with pytest.raises(ValueError, match="nested more than"):
        read_message("[" * 2000 + "]" * 2000)
    with pytest.raises(ValueError, match="nested more than"):
        read_message('{"a":' * (MAX_DEPTH + 1) + "1" + "}" * (MAX_DEPTH + 1))
    with pytest.raises(ValueError, match="JSON object"):
        read_message("[1, 2]")


def test_what_waits_for_a_page_that_does_not_read_is_bounded():
    page = _Page(1, ws=None, robot="r0")
    for k in range(10_000):
        page.push("error", f'{{"t": "error", "error": "bad {k}"}}')
        page.push(f"kind-{k}", "{}")  # sources invented on the bus
        page.push("scan", f'{{"k": {k}}}')
    assert len(page.pending) <= MAX_ERRORS + 1 + MAX_KINDS
    texts = page.take()
    assert '"k": 9999' in next(t for t in texts if '"k"' in t)  # the latest scan
    assert any("more errors" in t for t in texts)


def _refined(*asks) -> dict:
    """A refined snapshot's metadata with these asks in its latest refinement."""
    return {"refinement": [{"asks": []}, {"asks": list(asks)}]}


def _an_ask(world="room", pose=(1.0, 2.0, 0.5), scale=1.0, why="collision") -> dict:
    return {"world": world, "scale": scale, "start": [0.0, 0.0, 0.0], "seed": 0, "why": why,
            "step": 40, "pose": list(pose)}


def test_the_asks_of_the_world_shown_are_listed_and_the_others_counted():
    a = Asks()
    a.update(_refined(_an_ask(), _an_ask(pose=(3.0, 4.0, -1.0), why="band"),
                      _an_ask(scale=0.85), _an_ask(world="eval-room-l"),
                      _an_ask(world="worlds/room.toml", pose=(5.0, 1.0, 0.0))), "room")
    s = a.summary()
    assert [x["pose"] for x in s["asks"]] == [[1.0, 2.0, 0.5], [3.0, 4.0, -1.0], [5.0, 1.0, 0.0]]
    assert [x["n"] for x in s["asks"]] == [1, 2, 3]
    assert [x["why"] for x in s["asks"]] == ["collision", "band", "collision"]
    assert s["asks_elsewhere"] == 2 and s["asking"] is None and a.changed
    a.update(_refined(_an_ask()), None)  # no world known yet: every ask is elsewhere
    assert a.summary()["asks"] == [] and a.summary()["asks_elsewhere"] == 1


def test_labels_after_the_robot_is_put_at_an_ask_count_as_showing_it_there():
    a = Asks()
    a.update(_refined(_an_ask(), _an_ask(pose=(3.0, 4.0, -1.0))), "room")
    a.labelled()  # not put at an ask: counts for none
    assert [x["shown"] for x in a.summary()["asks"]] == [0, 0]
    assert a.place(2).pose == (3.0, 4.0, -1.0)
    a.labelled()
    a.labelled()
    assert [x["shown"] for x in a.summary()["asks"]] == [0, 2] and a.summary()["asking"] == 2
    # a newer tree with the same asks (the learner took the labels in) keeps the count
    a.update(_refined(_an_ask(pose=(3.0, 4.0, -1.0)), _an_ask()), "room")
    assert [(x["n"], x["shown"]) for x in a.summary()["asks"]] == [(1, 2), (2, 0)]
    assert a.summary()["asking"] == 1
    a.moved()
    a.labelled()
    assert [x["shown"] for x in a.summary()["asks"]] == [2, 0] and a.summary()["asking"] is None


@pytest.mark.parametrize("meta", [
    None, {}, {"refinement": "x"}, {"refinement": []}, {"refinement": [None]},
    {"refinement": [{"asks": {"pose": [1, 2, 3]}}]},
    _refined({"world": "room"}), _refined({"world": "room", "pose": [1, 2]}),
    _refined({"world": "room", "pose": [1, float("nan"), 0]}),
    _refined({"world": "room", "pose": [1, True, 0]}), _refined({"world": 3, "pose": [1, 2, 0]}),
    _refined("room"),
])
def test_malformed_asks_in_a_snapshot_are_left_out(meta):
    a = Asks()
    a.update(meta, "room")
    assert a.summary()["asks"] == []


def test_an_ask_that_is_not_there_is_refused_naming_the_range():
    a = Asks()
    with pytest.raises(ValueError, match="asks for nothing"):
        a.place(1)
    a.update(_refined(*[_an_ask(pose=(float(i), 1.0, 0.0)) for i in range(MAX_ASKS + 5)]),
             "room")
    assert len(a.summary()["asks"]) == MAX_ASKS
    for bad in (0, MAX_ASKS + 1, "1", True, 1.0, None):
        with pytest.raises(ValueError, match=f"1..{MAX_ASKS}"):
            a.place(bad)
