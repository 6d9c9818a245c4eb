"""server.arbiter: who drives (pure)."""

from __future__ import annotations

import pytest

from server.arbiter import Arbiter, priority_of, role_of


def test_roles_and_priorities():
    assert role_of("teacher-2") == "teacher" and role_of("controller") == "controller"
    assert priority_of("teacher") > priority_of("controller") > priority_of("keyboard")
    assert priority_of("") == 0


def test_teacher_overrides_while_commanding_then_controller_again():
    a = Arbiter(timeout=0.5)
    a.offer("controller", 0.3, 0.0, True, now=0.0)
    assert a.command(0.1) == (0.3, 0.0, "controller")
    a.offer("teacher", 0.0, 0.5, True, now=0.1)
    a.offer("controller", 0.3, 0.0, True, now=0.2)
    assert a.command(0.2) == (0.0, 0.5, "teacher")  # the later controller command loses
    a.offer("controller", 0.3, 0.0, True, now=0.6)
    assert a.command(0.6) == (0.0, 0.5, "teacher")  # teacher's last command 0.5 s ago
    assert a.command(0.61) == (0.3, 0.0, "controller")  # teacher timed out


def test_liveliness_release_is_immediate():
    a = Arbiter(timeout=10.0)
    a.offer("controller", 0.3, 0.0, True, now=0.0)
    a.offer("teacher-a", 0.0, 0.5, True, now=0.0)
    assert a.command(0.0)[2] == "teacher-a"
    a.release_role("teacher")
    assert a.command(0.0)[2] == "controller"


def test_watchdog_stops_and_motors_off():
    a = Arbiter(timeout=0.5)
    a.offer("x", 0.3, 0.1, True, now=0.0)
    assert a.command(0.5) == (0.3, 0.1, "x")
    assert a.command(0.51) == (0.0, 0.0, "")
    a.offer("x", 0.3, 0.1, False, now=1.0)
    assert a.command(1.0) == (0.0, 0.0, "x")


def test_same_priority_most_recent_wins():
    a = Arbiter()
    a.offer("a", 0.1, 0.0, True, now=0.0)
    a.offer("b", 0.2, 0.0, True, now=0.0)
    assert a.command(0.0)[2] == "b"
    with pytest.raises(ValueError):
        Arbiter(timeout=0)


def test_timeout_must_be_finite():
    with pytest.raises(ValueError, match="finite"):
        Arbiter(timeout=float("inf"))  # the watchdog would never stop the robot


def test_a_flood_of_invented_sources_is_bounded_and_keeps_the_teacher():
    a = Arbiter(timeout=0.5, max_sources=8)
    a.offer("teacher", 0.2, 0.0, True, now=0.0)
    for k in range(1000):
        a.offer(f"x{k}", 0.5, 0.5, True, now=0.0)
    assert len(a._held) <= 8 and a.holds("teacher")
    assert a.command(0.1) == (0.2, 0.0, "teacher")
