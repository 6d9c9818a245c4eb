"""Keyboard teleop on a pseudo-terminal: keys select actions; a terminal that goes away pauses
(the last key must not keep driving the robot with nobody at the keyboard)."""

from __future__ import annotations

import os
import pty

from waiting import eventually

from client.behaviour.actions import DEFAULT_ACTIONS
from client.roles.keyboard import KeyboardPolicy, parse_keys


def test_parse_keys_keeps_arrow_sequences_whole():
    assert parse_keys("w\x1b[Dq") == ["w", "\x1b[D", "q"]


def test_keys_drive_and_a_closed_terminal_pauses():
    master, slave = pty.openpty()
    stream = os.fdopen(slave, "rb", buffering=0)
    kb = KeyboardPolicy(DEFAULT_ACTIONS, stream=stream)
    try:
        assert kb.step(None, None) == (None, None)
        os.write(master, b"w")
        eventually(lambda: kb.current, 10, "the key w read", until=lambda a: a == "fwd")
        assert kb.step(None, None) == ("fwd", "fwd")
        os.close(master)  # the terminal hangs up
        eventually(lambda: kb.current, 10, "a pause once the terminal is gone (the held key "
                   "keeps driving)", until=lambda a: a is None)
        eventually(lambda: not kb._thread.is_alive(), 10, "the reader thread ended")
    finally:
        kb.close()  # restoring a hung-up terminal must not raise
        stream.close()
