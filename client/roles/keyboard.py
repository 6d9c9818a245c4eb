"""Keyboard teleop for ``rhbl teacher --policy keyboard``: a person demonstrates at a terminal.

Keys (the five actions; the last key pressed holds until another one):

    w / Up     fwd            q  fwd-left          a / Left   rot-left
                              e  fwd-right         d / Right  rot-right
    space      pause (no commands, no labels: the server's watchdog stops the robot)
    x / Ctrl-C quit

``KeyboardPolicy.step(ranges, pose) -> (label, executed)`` like ``Demonstrator`` (the person's
choice is both the label and the executed action), or ``(None, None)`` while paused. The terminal
is put in cbreak mode by a reader thread and restored by ``close()``.
"""

from __future__ import annotations

import logging
import os
import select
import signal
import sys
import threading

__all__ = ["KEYMAP", "KeyboardPolicy", "parse_keys"]

log = logging.getLogger(__name__)

KEYMAP = {
    "w": "fwd", "\x1b[A": "fwd",
    "q": "fwd-left",
    "a": "rot-left", "\x1b[D": "rot-left",
    "e": "fwd-right",
    "d": "rot-right", "\x1b[C": "rot-right",
    " ": None,
}
QUIT = {"x", "\x03"}


def parse_keys(data: str) -> list[str]:
    """Split raw terminal input into keys (escape sequences of arrow keys stay whole)."""
    out, i = [], 0
    while i < len(data):
        if data[i] == "\x1b" and data[i + 1:i + 2] == "[" and i + 2 < len(data):
            out.append(data[i:i + 3])
            i += 3
        else:
            out.append(data[i].lower())
            i += 1
    return out


class KeyboardPolicy:
    def __init__(self, actions, stream=None):
        self.actions = actions
        self.current: str | None = None
        self._stop = threading.Event()
        self._stream = stream if stream is not None else sys.stdin
        self._saved = None
        try:
            fd = self._stream.fileno()
            if not os.isatty(fd):
                raise OSError("not a terminal")
        except (OSError, ValueError, AttributeError) as exc:
            from process.runtime import EXIT_USAGE, ProcessError

            raise ProcessError(f"teacher: keyboard teleop needs an interactive terminal ({exc})",
                               EXIT_USAGE) from exc
        import termios
        import tty

        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        print("keyboard teleop: w/Up fwd, q fwd-left, a/Left rot-left, e fwd-right, "
              "d/Right rot-right, space pause, x quit", file=sys.stderr, flush=True)
        self._thread = threading.Thread(target=self._read, name="keyboard", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._fd], [], [], 0.1)
                if not ready:
                    continue
                raw = os.read(self._fd, 32)
            except OSError as exc:  # the terminal went away (EIO, EBADF)
                raw, why = b"", str(exc)
            else:
                why = "end of input"
            if not raw:
                # nobody can press a key any more: the held key must not keep driving
                self.current = None
                log.warning("teleop: the terminal is gone (%s): paused", why)
                return
            for key in parse_keys(raw.decode("utf-8", "replace")):
                self.press(key)

    def press(self, key: str) -> None:
        if key in QUIT:
            os.kill(os.getpid(), signal.SIGINT)
            return
        if key in KEYMAP:
            name = KEYMAP[key]
            if name is not None and name not in self.actions:
                return
            if name != self.current:
                log.info("teleop: %s", name or "paused")
            self.current = name

    def reset(self) -> None:
        self.current = None

    def step(self, ranges, pose):
        a = self.current
        return a, a

    def close(self) -> None:
        self._stop.set()
        if self._saved is not None:
            import termios

            try:
                termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            except (termios.error, OSError) as exc:  # the terminal is gone: nothing to restore
                log.debug("could not restore the terminal: %s", exc)
            self._saved = None
