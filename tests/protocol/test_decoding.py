"""The one decode-or-drop: counted by kind, logged at a bounded rate, never raised."""

from __future__ import annotations

import logging

from protocol.decoding import Decoder
from protocol.messages import Scan, VelCmd


def test_drops_are_counted_by_kind_and_logged_first_then_every_hundredth(caplog):
    log = logging.getLogger("test.decoding")
    d = Decoder(log)
    with caplog.at_level(logging.WARNING, logger="test.decoding"):
        for _ in range(250):
            assert d.decode(Scan, b"junk", where="rhbl/r0/laser/0/data/scan") is None
        assert d.decode(VelCmd, b"\x81\xa1v\x02") is None  # another version
    assert d.counts == {"scan": 250, "cmd/vel": 1} and d.total == 251
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 10 + 2 + 1  # the first ten, the 100th and 200th, and the command
    assert said[0].startswith("dropped a malformed scan (1 so far): rhbl/r0/laser/0/data/scan:")
    assert "(200 so far)" in said[-2] and "cmd/vel (1 so far)" in said[-1]
    assert "unsupported protocol version 2" in said[-1]
    good = VelCmd(vx=0.1).encode()
    assert d.decode(VelCmd, good) == VelCmd(vx=0.1) and d.total == 251


def test_a_callers_counters_and_other_refusals():
    counters: dict[str, int] = {"accepted": 7}
    d = Decoder(logging.getLogger("test.decoding"), counts=counters, total="rejected",
                verb="rejected")
    assert d.drop("cmd_source", "its source does not match its key") == 1
    assert d.decode(VelCmd, b"", what="cmd") is None
    assert counters == {"accepted": 7, "cmd_source": 1, "cmd": 1, "rejected": 2}
    assert d.total == 2
