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
