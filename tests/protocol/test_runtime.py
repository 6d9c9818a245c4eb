"""Stop signals of every rhbl process (``protocol.runtime``), with a real process and real
signals: a SIGTERM that lands where code swallows the ``SystemExit`` it raises (a signal during
numpy's first lazy import of ``numpy.random`` was lost that way) is delivered again until the
process stops."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

from lab.children import Child

ROOT = Path(__file__).resolve().parents[2]

# the first SystemExit is swallowed, as library code can; only a second one ends the program
PROGRAM = """
import sys, time
from protocol.runtime import install_signal_handlers
install_signal_handlers()
try:
    print("ready", flush=True)  # inside: a signal right after it must land in this block
    while True:
        time.sleep(0.01)
except SystemExit:
    print("swallowed", flush=True)
try:
    while True:
        time.sleep(0.01)
except SystemExit:
    print("stopped", flush=True)
    sys.exit(0)
"""


def test_a_swallowed_stop_signal_is_delivered_again(tmp_path):
    p = Child("swallower", [sys.executable, "-c", PROGRAM], tmp_path, cwd=ROOT,
              env={**os.environ, "PYTHONPATH": str(ROOT)}, escalate=False).start()
    try:
        assert p.wait_for_line("ready", 30), p.output()
        p.send_signal(signal.SIGTERM)  # once
        assert p.wait_for_line("swallowed", 10), p.output()
        assert p.wait_for_line("stopped", 10), p.output()
        assert p.wait(10) == 0, p.output()
    finally:
        p.stop(signal.SIGKILL)
