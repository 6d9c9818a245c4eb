"""The one bus tap: every sink gets the bus in the order received; a sink that fails is left
out, the others go on; ``sync`` waits until what arrived was delivered."""

from __future__ import annotations

import threading

import pytest

zenoh = pytest.importorskip("zenoh")

from waiting import patience  # noqa: E402

from client.recording.mcap_file import RecordingError  # noqa: E402
from client.recording.tap import BusTap  # noqa: E402
from process.session import make_config  # noqa: E402
from protocol import keys  # noqa: E402
from protocol.messages import TreeNotice  # noqa: E402


class ListSink:
    def __init__(self, fail_after: int | None = None):
        self.got, self.alive, self.closed, self.fail_after = [], [], False, fail_after
        self._changed = threading.Condition()

    def write(self, key, data, recv_ns, kind=None, robot=None, sim_time=None):
        if self.fail_after is not None and len(self.got) >= self.fail_after:
            raise RecordingError("the disk is full")
        with self._changed:
            self.got.append((key, kind, robot, data))
            self._changed.notify_all()

    def write_alive(self, key, alive, recv_ns):
        with self._changed:
            self.alive.append((key, alive))
            self._changed.notify_all()

    def wait_for(self, messages: int, alive: int = 0, timeout: float = 10.0) -> bool:
        """Until the tap delivered ``messages`` messages and ``alive`` liveliness changes
        (puts reach the session's own subscribers on zenoh's threads, after ``put`` returns)."""
        with self._changed:
            return self._changed.wait_for(
                lambda: len(self.got) >= messages and len(self.alive) >= alive,
                patience(timeout))

    def maybe_flush(self, now=None):
        pass

    def close(self):
        self.closed = True


def test_every_sink_gets_the_bus_and_a_failing_one_is_left_out(free_port):
    config = make_config(mode="peer", listen=[f"tcp/127.0.0.1:{free_port()}"])
    with zenoh.open(config) as session:
        good, bad = ListSink(), ListSink(fail_after=2)
        tap = BusTap(session, [good, bad], robots=["r0"], world=False)
        token = session.liveliness().declare_token(keys.alive_key("learner", "r0-1"))
        notices = [TreeNotice(seq=i, nodes=i + 1, height=1).encode() for i in range(5)]
        for data in notices:
            session.put(keys.learner_notice_key("r0"), data)
        session.put(keys.learner_notice_key("r1"), notices[0])  # not a robot it taps
        assert good.wait_for(len(notices), alive=1)
        assert tap.sync()
        assert [d for _k, _kind, _r, d in good.got] == notices
        assert {(k, kind, r) for k, kind, r, _d in good.got} == {
            (keys.learner_notice_key("r0"), "notice", "r0")}
        assert len(bad.got) == 2 and tap.error(bad) is not None and not tap.failed
        assert tap.error(good) is None
        assert (keys.alive_key("learner", "r0-1"), True) in good.alive
        errors = tap.close()
        token.undeclare()
    assert good.closed and not bad.closed and list(errors.values()) == [tap.error(bad)]
