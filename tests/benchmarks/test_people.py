"""The models of people (``benchmarks/people.py``): what they see, when they press, when they
take over."""

from __future__ import annotations

import math

import numpy as np
import pytest

# a corridor along +x: the wall on the robot's right at y = 0, another at y = 3, an end at x = 10
WALLS = np.array([[0.0, 0.0, 10.0, 0.0], [0.0, 3.0, 10.0, 3.0], [10.0, 0.0, 10.0, 3.0]])


@pytest.fixture
def view(people):
    def make(t, pose, mode="demonstrate", **kw):
        return people.View(t=t, pose=pose, walls=WALLS, mode=mode, **kw)

    return make


def test_percept_reads_the_map(people, view):
    p = people.percept(view(0.0, (2.0, 0.7, 0.0)))
    assert p.right == pytest.approx(0.7)
    assert p.angle == pytest.approx(0.0)
    assert p.front == pytest.approx(8.0)  # to the end wall
    away = people.percept(view(0.0, (2.0, 0.7, 0.3)))
    assert away.angle == pytest.approx(0.3)  # heading away from the wall: positive
    ahead = people.percept(view(0.0, (9.5, 1.5, 0.0)))
    assert ahead.front == pytest.approx(0.5)


def test_every_model_answers_keys_only_and_is_deterministic(people, view):
    def drive(person):
        return [person.observe(view(0.1 * k, (2.0 + 0.03 * k, 0.7 + 0.02 * k, 0.1)))
                for k in range(40)]

    for name, make in people.PEOPLE.items():
        person = make(seed=3)
        keys = drive(person)
        assert set(keys) <= {*people.KEYS, None}, name
        assert keys[-1] is not None, name
        assert drive(make(seed=3)) == keys, name
        person.reset()
        assert drive(person) == keys, name


def test_a_person_presses_only_after_their_reaction_time(people, view):
    style = people.Style("test", reaction=0.3, reaction_sd=0.0, wrong=0.0, hesitate=0.0,
                         oversteer=0.0, noise=0.0)
    person = people.Person(style)
    presses = [(0.05 * k, person.observe(view(0.05 * k, (9.6, 1.5, 0.0)))) for k in range(20)]
    first = next(t for t, key in presses if key is not None)
    assert 0.3 - 1e-9 <= first <= 0.4  # a wall 0.4 m ahead: seen 0.3 s after it was shown
    assert presses[-1][1] == "rot-left"


def test_a_wrong_key_is_pressed_then_corrected(people, view):
    style = people.Style("test", reaction=0.2, reaction_sd=0.0, wrong=1.0, mirror=1.0,
                         hesitate=0.0, oversteer=0.0, noise=0.0)
    person = people.Person(style)
    keys = [person.observe(view(0.1 * k, (9.6, 1.5, 0.0))) for k in range(30)]
    assert "rot-right" in keys  # the mirror image of what was meant
    assert person.intent == "rot-left"


def test_correct_mode_hands_off_unless_needed(people, view):
    person = people.PEOPLE["steady"](seed=0)
    fine = [person.observe(view(0.1 * k, (1.0 + 0.04 * k, 0.65, 0.0), mode="correct",
                                 driver="controller", action="fwd")) for k in range(40)]
    assert fine == [None] * 40  # on the wall: the person watches
    close = [person.observe(view(4.0 + 0.1 * k, (3.0, 0.3, -0.3), mode="correct",
                                  driver="controller", action="fwd")) for k in range(10)]
    assert close[-1] is not None  # too close to the wall: takes over


def test_a_person_takes_over_a_robot_spinning_in_place(people, view):
    person = people.PEOPLE["steady"](seed=0)
    keys = []
    for k in range(80):
        yaw = math.remainder(0.8 * 0.1 * k, 2 * math.pi)  # rotating on the spot
        keys.append(person.observe(view(0.1 * k, (5.0, 1.2, yaw), mode="correct",
                                         driver="controller", action="rot-left")))
    assert any(k is not None for k in keys[40:])


def test_a_person_goes_round_the_end_of_the_wall_on_the_right(people):
    """A wall's free end (an inner wall's tip) abeam on the right: the person turns right round
    it, even with a wall ahead (rotating right in place when it is close); at a corner (the
    same wall end joined to another wall) they turn left as before."""
    person = people.Person(people.Style("test", noise=0.0))
    inner = [0.0, 0.0, 5.0, 0.0]  # ends free at x = 5; the robot just past it, 0.7 m off
    for ahead, key in ((6.2, "fwd-right"), (5.7, "rot-right")):
        walls = np.array([inner, [ahead, -3.0, ahead, 3.0]])
        p = people.percept(people.View(t=0.0, pose=(5.3, 0.65, 0.0), walls=walls))
        assert p.tip and p.front == pytest.approx(ahead - 5.3)
        assert person.wanted(p) == key
    corner = np.array([inner, [5.0, 0.0, 5.0, -3.0], [6.2, -3.0, 6.2, 3.0]])
    p = people.percept(people.View(t=0.0, pose=(5.3, 0.65, 0.0), walls=corner))
    assert not p.tip and person.wanted(p) == "fwd-left"


def test_a_pilot_aims_at_a_point_along_the_wall(people):
    style = people.PilotStyle("test", noise=0.0, lookahead=1.0, target=0.7, aim=0.12, spin=0.9)
    pilot = people.Pilot(style)
    along = people.percept(people.View(t=0.0, pose=(2.0, 0.7, 0.0), walls=WALLS))
    assert pilot.wanted(along) == "fwd"
    far = people.percept(people.View(t=0.0, pose=(2.0, 1.2, 0.0), walls=WALLS))
    assert pilot.wanted(far) == "fwd-right"  # off the wall: aims back at the liked distance
    away = people.percept(people.View(t=0.0, pose=(2.0, 0.7, 1.0), walls=WALLS))
    assert pilot.wanted(away) == "rot-right"  # heading far off the wall's way: turn in place
    bang = people.Pilot(people.PilotStyle("test", noise=0.0, arcs=False))
    assert bang.wanted(far) == "rot-right"  # no arc keys: a rotation instead


def test_a_model_without_arc_keys_never_presses_one(people, view):
    person = people.PEOPLE["bang"](seed=1)
    keys = {person.observe(view(0.1 * k, (2.0 + 0.03 * k, 0.4 + 0.03 * k, 0.2 * math.sin(k)))
                           ) for k in range(300)}
    assert keys <= {"fwd", "rot-left", "rot-right", None} and len(keys) >= 3


def test_a_pilot_looking_away_keeps_the_key_held(people, view):
    """A lapse of attention: nothing new is decided, the key stays down, then the pilot
    answers what it sees again."""
    style = people.PilotStyle("test", reaction=0.2, rt_sigma=0.0, wrong=0.0, hesitate=0.0,
                              oversteer=0.0, noise=0.0, lapse=1e6, lapse_for=(1.0, 1.0))
    pilot = people.Pilot(style)
    pilot.m.next_decision = math.inf  # no decision yet: hold fwd by hand
    pilot.m.intent = "fwd"
    keys = [pilot.observe(view(0.1 * k, (9.6, 1.5, 0.0))) for k in range(8)]
    assert keys == ["fwd"] * 8  # a wall 0.4 m ahead, but the pilot is not looking
    pilot.m.next_decision = 0.0
    pilot._lapse_until = -math.inf
    pilot.style = people.PilotStyle("test", reaction=0.2, rt_sigma=0.0, wrong=0.0,
                                    hesitate=0.0, oversteer=0.0, noise=0.0)
    later = [pilot.observe(view(1.0 + 0.1 * k, (9.6, 1.5, 0.0))) for k in range(8)]
    assert later[-1] == "rot-left"


@pytest.mark.parametrize("hz", [30, 70, 170])
def test_a_tapper_holds_each_tap_then_lets_go_whatever_the_page_rate(people, view, hz):
    """Taps of about ``taps`` s with gaps of ``tap_gap`` between them, read at any rate (a
    tap was once one poll long: the faster the page was read, the fewer labels it gave)."""
    style = people.Style("test", reaction=0.2, reaction_sd=0.0, wrong=0.0, hesitate=0.0,
                         oversteer=0.0, noise=0.0, taps=0.3, tap_gap=(0.2, 0.2))
    person = people.Person(style)
    keys = [person.observe(view(k / hz, (9.6, 1.5, 0.0))) for k in range(4 * hz)]
    held = [k is not None for k in keys[hz:]]  # after the reaction: rot-left, tapped
    assert set(keys[hz:]) == {"rot-left", None}
    assert 0.5 < sum(held) / len(held) < 0.7  # 0.21-0.39 s on, 0.2 s off
    starts = sum(1 for a, b in zip(held, held[1:], strict=False) if b and not a)
    assert 4 <= starts <= 8  # about two taps a second over 3 s


# -- a person for any behaviour (people.Follower) -------------------------------------------

def test_the_map_read_as_a_scan_is_what_the_laser_reads(people):
    """``scan_of``: the walls ray-cast from the robot as drawn give the simulator's scan."""
    from lab.behaviours import get, world_of
    from server.world import World

    for name in ("wandering", "dead-end"):
        b = get(name)
        spec = world_of(b, b.teach[0])
        world = World(spec, robots=1, seed=0)
        world.reset(poses=[tuple(spec.pose)])
        walls = np.asarray(spec.segments(), dtype=float).reshape(-1, 4)
        seen = people.scan_of(people.View(t=0.0, pose=tuple(spec.pose), walls=walls))
        assert np.allclose(seen, world.scan(0), atol=1e-4), name


def test_a_follower_means_what_the_behaviours_expert_answers(people, view):
    """No noise, no slips: after its reaction time a follower holds the expert's key."""
    from lab.behaviours import get

    style = people.FollowerStyle("test", reaction=0.2, rt_sigma=0.0, wrong=0.0, hesitate=0.0,
                                 oversteer=0.0, noise=0.0, bearing=0.0)
    for name, pose in (("corridor-centring", (2.0, 0.7, 0.0)),  # nearer the right wall
                       ("wandering", (9.5, 1.5, 0.0))):       # a wall just ahead
        f = people.Follower(style, name)
        keys = [f.observe(view(0.05 * k, pose)) for k in range(12)]
        expert = get(name).expert("reactive")
        want = expert.act(people.scan_of(view(0.0, pose)), None)
        assert keys[0] is None and keys[-1] == want, name
    assert want.startswith("rot")  # the wanderer turns on the spot at a wall


def test_every_follower_answers_keys_only_and_is_deterministic(people, view):
    def drive(person):
        return [person.observe(view(0.1 * k, (2.0 + 0.03 * k, 0.7 + 0.02 * k, 0.1)))
                for k in range(60)]

    for name in people.ANY:
        keys = drive(people.person(name, "corridor-centring", seed=3))
        assert set(keys) <= {*people.KEYS, None}, name
        assert drive(people.person(name, "corridor-centring", seed=3)) == keys, name
    assert set(people.ANY_DEV).isdisjoint(people.ANY_HELD_OUT)


def test_an_arcless_follower_presses_no_arc_key(people, view):
    person = people.person("arcless", "wall-following", seed=1)
    keys = {person.observe(view(0.1 * k, (2.0 + 0.03 * k, 0.4 + 0.03 * k, 0.2 * math.sin(k)))
                           ) for k in range(300)}
    assert keys <= {"fwd", "rot-left", "rot-right", None} and {"fwd", "rot-left"} <= keys


def test_a_follower_takes_over_a_robot_too_close_and_lets_go_when_fine(people, view):
    style = people.FollowerStyle("test", reaction=0.2, rt_sigma=0.0, wrong=0.0, hesitate=0.0,
                                 oversteer=0.0, noise=0.0, bearing=0.0, settle=0.5)
    f = people.Follower(style, "corridor-centring")
    calm = [f.observe(view(0.1 * k, (3.0, 1.5, 0.0), "correct", driver="controller",
                           action="fwd")) for k in range(10)]
    assert calm == [None] * 10  # midway along the corridor: hands off
    close = [f.observe(view(1.0 + 0.1 * k, (3.0, 0.27, 0.0), "correct", driver="controller",
                            action="fwd")) for k in range(10)]
    assert close[-1] == "fwd-left"  # 0.27 m from the right wall: steers off it
    back = [f.observe(view(2.0 + 0.1 * k, (3.0, 1.5, 0.0), "correct", driver="teacher",
                           action="fwd")) for k in range(30)]
    assert back[-1] is None  # fine again: lets go


def test_a_right_hand_wall_model_teaches_wall_following_only(people):
    assert isinstance(people.person("steady", "wall-following"), people.Person)
    with pytest.raises(ValueError, match="right-hand wall only"):
        people.person("steady", "wandering")
    with pytest.raises(ValueError, match="no person model 'nobody'"):
        people.person("nobody", "wandering")
