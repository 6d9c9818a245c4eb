"""The controller's Decision message and key: round trip and validation."""

from __future__ import annotations

import msgpack
import pytest

from protocol import DecodeError, keys
from protocol.messages import Decision


def test_decision_key():
    assert keys.controller_decision_key("r1") == "rhbl/r1/controller/decision"
    with pytest.raises(ValueError):
        keys.controller_decision_key("a/b")


def test_decision_round_trip():
    d = Decision(scan_id=7, action="fwd-left", ts=1.5, snapshot_id="ab12:300", nodes=41,
                 path=((0, 0, 5.0, "fwd"), (3, 1, 1.25, "fwd-left")))
    back = Decision.decode(d.encode())
    assert back == d
    assert msgpack.unpackb(d.encode())["path"][1] == [3, 1, 1.25, "fwd-left"]


def test_the_loop_guards_fields_are_optional():
    d = Decision(scan_id=7, action="rot-left", executed="rot-right", looping=True)
    assert Decision.decode(d.encode()) == d
    plain = msgpack.unpackb(Decision(scan_id=7, action="fwd").encode())
    assert "looping" not in plain and "executed" not in plain  # said only when they apply
    back = Decision.decode(msgpack.packb({"v": 1, "scan_id": 1, "action": "fwd"}))
    assert back.looping is False and back.executed is None
    with pytest.raises(DecodeError, match="looping"):
        Decision.decode(_raw(looping="yes"))
    with pytest.raises(DecodeError, match="executed"):
        Decision.decode(_raw(executed=3))


def _raw(**fields):
    m = {"v": 1, "scan_id": 1, "action": "fwd", "path": [[0, 0, 1.0, "fwd"]]}
    m.update(fields)
    return msgpack.packb(m)


@pytest.mark.parametrize("fields, names", [
    ({"scan_id": -1}, "scan_id"),
    ({"action": 3}, "action"),
    ({"path": "x"}, "path"),
    ({"path": [[0, 0, 1.0]]}, "path[0]"),
    ({"path": [[0, 0, float("nan"), "fwd"]]}, "radius"),
    ({"path": [[-1, 0, 1.0, "fwd"]]}, "index"),
    ({"path": [[0, 0, 1.0, "fwd"]] * 2000}, "path"),
    ({"v": 2}, "version"),
])
def test_decision_rejects_bad_fields(fields, names):
    with pytest.raises(DecodeError, match="decision") as e:
        Decision.decode(_raw(**fields))
    assert names in str(e.value) or names == "version"


def test_decision_minimal_map_defaults():
    d = Decision.decode(msgpack.packb({"v": 1, "scan_id": 2, "action": "rot-left"}))
    assert d.path == () and d.snapshot_id == "" and d.nodes == 0
