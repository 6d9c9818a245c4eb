"""``waiting.eventually``: the answer once it comes, a failure that names what was awaited and
the last answer, at once when a process waited on ends; ``$RHBL_TEST_PATIENCE`` checked."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from waiting import Timeout, eventually, listening, patience

from lab.children import Child


def test_returns_the_answer_once_it_comes():
    answers = iter([0, [], None, 7])
    assert eventually(lambda: next(answers), timeout=5, every=0.001) == 7


def test_until_tests_the_answer():
    n = iter(range(100))
    assert eventually(lambda: next(n), timeout=5, every=0.001, until=lambda v: v >= 3) == 3


def test_timeout_names_what_and_the_last_answer():
    with pytest.raises(Timeout, match=r"not within .* s: three scans; last answer: \[1, 2\]"):
        eventually(lambda: [1, 2], timeout=0.05, every=0.01, what="three scans",
                   until=lambda v: len(v) >= 3)


def test_a_timeout_is_a_test_failure():
    assert issubclass(Timeout, AssertionError)


def test_ignored_exceptions_are_not_yet_others_go_up(tmp_path):
    path = tmp_path / "later.txt"
    with pytest.raises(Timeout, match="FileNotFoundError"):
        eventually(path.read_text, timeout=0.05, every=0.01, ignore=(FileNotFoundError,))
    with pytest.raises(FileNotFoundError):
        eventually(path.read_text, timeout=5)
    path.write_text("here")
    assert eventually(path.read_text, timeout=5, ignore=(FileNotFoundError,)) == "here"


def test_a_process_that_ends_fails_the_wait_at_once():
    child = Child("short", [sys.executable, "-c", "print('bye from the child')"]).start()
    t0 = time.monotonic()
    with pytest.raises(Timeout, match=r"(?s)short ended \(exit 0\).*bye from the child"):
        eventually(lambda: False, timeout=60, what="a fact", alive=[child])
    assert time.monotonic() - t0 < 30


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="timeout and every must be > 0 s"):
        eventually(lambda: True, timeout=0)


@pytest.mark.parametrize("value", ["0.5", "slow", "-1"])
def test_patience_must_be_a_factor_of_one_or_more(value):
    env = {**os.environ, "RHBL_TEST_PATIENCE": value}
    r = subprocess.run([sys.executable, "-c", "import waiting"], capture_output=True, text=True,
                       env=env, cwd=os.path.dirname(__file__), timeout=60)
    assert r.returncode == 1 and "RHBL_TEST_PATIENCE must be a number >= 1" in r.stderr
    assert repr(value) in r.stderr


def test_patience_stretches_deadlines():
    env = {**os.environ, "RHBL_TEST_PATIENCE": "2.5"}
    r = subprocess.run([sys.executable, "-c", "import waiting; print(waiting.patience(4))"],
                       capture_output=True, text=True, env=env, cwd=os.path.dirname(__file__),
                       timeout=60)
    assert r.stdout.strip() == "10.0", r.stderr
    assert patience(4) >= 4


def test_listening_sees_a_listening_port_without_connecting():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        assert not listening(port)  # bound, not listening
        s.listen()
        assert listening(port)
    assert not listening(port)
