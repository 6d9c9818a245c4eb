"""Keyboard teleop on a pseudo-terminal: keys select actions; a terminal that goes away pauses
(the last key must not keep driving the robot with nobody at the keyboard)."""

from __future__ import annotations

import os
import pty
import time

from client.behaviour.actions import DEFAULT_ACTIONS
from client.roles.keyboard import KeyboardPolicy, parse_keys


def _until(cond, timeout=5.0):
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(0.01)
    return cond()


def test_parse_keys_keeps_arrow_sequences_whole():
    assert parse_keys("w\x1b[Dq") == ["w", "\x1b[D", "q"]


def test_keys_drive_and_a_closed_terminal_pauses():
    master, slave = pty.openpty()
    stream = os.fdopen(slave, "rb", buffering=0)
    kb = KeyboardPolicy(DEFAULT_ACTIONS, stream=stream)
    try:
        assert kb.step(None, None) == (None, None)
        os.write(master, b"w")
        assert _until(lambda: kb.current == "fwd")
        assert kb.step(None, None) == ("fwd", "fwd")
        os.close(master)  # the terminal hangs up
        assert _until(lambda: kb.current is None), "the held key keeps driving"
        assert _until(lambda: not kb._thread.is_alive())
    finally:
        kb.close()  # restoring a hung-up terminal must not raise
        stream.close()
