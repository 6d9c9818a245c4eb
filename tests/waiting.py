"""Waiting on facts, one way for every test: ``eventually`` asks a question again until the
answer is what the test waits for, within a deadline that a slow machine can stretch.

    from waiting import eventually, patience

    stats = eventually(lambda: _read_json(path), what=f"{path} written")      # the value
    eventually(lambda: len(got) >= 3, timeout=20, what="3 scans", alive=[srv])
    eventually(lambda: n_records(out), what="the journal's records",
               until=lambda n: n >= 40)                                     # a test on the value
    wait_token(session, keys.alive_key("learner", f"r0-{learner.pid}"), alive=[learner])

A loaded machine (several suites at once, two cores) slows a test down but must not fail it:
every deadline is multiplied by ``$RHBL_TEST_PATIENCE`` (default 1; ``RHBL_TEST_PATIENCE=3``
on a machine three times slower; tests/conftest.py stretches each test's timeout by as much)
and the default deadlines are generous, well above what a quiet machine takes. What fails a
wait is the fact never coming, said in the message with the last answer seen; a process the
test started that ends while the test waits for it (``alive=``) fails the wait at once, with
its last lines, instead of at the deadline.

``tests/`` is on ``sys.path`` (its conftest.py is not in a package), so every test imports
this module as ``waiting``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from typing import Any, TypeVar

__all__ = ["PATIENCE", "Timeout", "eventually", "listening", "patience", "wait_token"]

T = TypeVar("T")


def _patience() -> float:
    raw = os.environ.get("RHBL_TEST_PATIENCE", "1")
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"RHBL_TEST_PATIENCE must be a number >= 1 (a factor on every "
                         f"test deadline), not {raw!r}") from None
    if not value >= 1.0:
        raise ValueError(f"RHBL_TEST_PATIENCE must be a number >= 1 (a factor on every test "
                         f"deadline), not {raw!r}")
    return value


PATIENCE = _patience()


def patience(seconds: float) -> float:
    """``seconds`` stretched by ``$RHBL_TEST_PATIENCE``: for a deadline handed to something
    else (``Child.wait``, ``Condition.wait_for``, a subscriber's ``recv`` loop)."""
    return seconds * PATIENCE


class Timeout(AssertionError):
    """A wait whose fact did not come within its deadline (an AssertionError: a test failure,
    not an error of the test)."""


def _ended(alive: Iterable[Any]) -> Any:
    for child in alive:
        if child.poll() is not None:
            return child
    return None


def _tails(alive: Iterable[Any]) -> str:
    return "".join(f"\n{child.name} (pid {child.pid}, exit {child.poll()}) said:\n"
                   f"{child.tail(30)}" for child in alive)


def eventually(predicate: Callable[[], T], timeout: float = 30.0, what: str = "", *,
               until: Callable[[T], Any] = bool, every: float = 0.05,
               alive: Iterable[Any] = (), ignore: tuple[type[BaseException], ...] = ()) -> T:
    """Call ``predicate()`` until ``until(answer)`` is true (default: the answer itself is
    truthy) and return that answer; after ``timeout`` seconds (times ``$RHBL_TEST_PATIENCE``)
    raise :class:`Timeout` naming ``what`` was awaited and the last answer seen.

    ``every``: seconds between two questions (the question is asked once more at the
    deadline). ``alive``: processes (``lab.children.Child``) that must keep running while the
    test waits: one that ends fails the wait at once with its last lines; their lines are in
    the timeout's message too. ``ignore``: exception types that mean "not yet" (a file not
    written yet), kept as the last answer; any other exception of the predicate is the test's
    failure and goes up as it is."""
    if timeout <= 0 or every <= 0:
        raise ValueError(f"eventually: timeout and every must be > 0 s, not {timeout!r} and "
                         f"{every!r}")
    alive = list(alive)
    limit = patience(timeout)
    deadline = time.monotonic() + limit
    last: Any = "(not asked yet)"
    while True:
        try:
            answer = predicate()
        except ignore as exc:
            last = f"{type(exc).__name__}: {exc}"
        else:
            if until(answer):
                return answer
            last = answer
        gone = _ended(alive)
        if gone is not None:
            raise Timeout(f"{what or 'the awaited fact'}: {gone.name} ended (exit "
                          f"{gone.poll()}) while waited for; last answer: {_short(last)}"
                          f"{_tails(alive)}")
        left = deadline - time.monotonic()
        if left <= 0:
            raise Timeout(f"not within {limit:g} s: {what or 'the awaited fact'}; last "
                          f"answer: {_short(last)}{_tails(alive)}")
        time.sleep(min(every, left))


def _short(value: Any, limit: int = 600) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def wait_token(session: Any, key: str, timeout: float = 30.0, alive: Iterable[Any] = ()) -> None:
    """Until the liveliness token ``key`` is seen on ``session`` (a zenoh session): a process
    is up, as it says itself on the bus (``rhbl/alive/<role>/<id>``: the learner's once it
    receives labels, the others' once their session is open)."""
    eventually(lambda: any(r.ok is not None for r in session.liveliness().get(key, timeout=1.0)),
               timeout, f"the liveliness token {key}", alive=alive)


def listening(port: int) -> bool:
    """Whether a TCP socket listens on ``port`` of this machine (Linux: /proc/net/tcp and
    tcp6), asked without connecting to it: a server's log and counters see no probe."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            with open(table) as f:
                next(f)  # the header
                for line in f:
                    local, state = line.split()[1], line.split()[3]
                    if state == "0A" and int(local.rsplit(":", 1)[1], 16) == port:
                        return True
        except FileNotFoundError:
            continue
    return False
