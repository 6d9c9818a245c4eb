"""The wire format, held to bytes committed before the messages were restated: every message
type encoded once (tests/protocol/fixtures/make_messages.py, a value other than the default in
every field), how the decoders answered hostile maps then, and a short recording made with
``rhbl record``. Each decodes to the same values and encodes again to the same bytes."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path

import msgpack
import numpy as np
import pytest

from client.recording.mcap_file import read_recording
from protocol import messages as m
from protocol.codec import DecodeError
from tests.protocol.fixtures.make_messages import ADDED, ADDED_AFTER_V1, MESSAGES

FIXTURES = Path(__file__).resolve().parent / "fixtures"
STORED = msgpack.unpackb((FIXTURES / "messages-v1.msgpack").read_bytes(), raw=False)
# the message types added after the v1 bytes, each in a file of its own (make_messages.py)
for _file in sorted((FIXTURES / "added").glob("*.msgpack")):
    _added = msgpack.unpackb(_file.read_bytes(), raw=False)
    STORED["messages"].update(_added["messages"])
    STORED["hostile"] += _added["hostile"]
MESSAGES = {**MESSAGES, **ADDED}


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                and np.array_equal(a, b))
    return type(a) is type(b) and a == b


def test_every_message_type_is_in_the_fixture():
    every = {c.__name__ for c in vars(m).values()
             if isinstance(c, type) and issubclass(c, m._Message) and c is not m._Message}
    assert set(STORED["messages"]) == every == set(MESSAGES)


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_every_field_is_set_to_other_than_its_default(name):
    msg = MESSAGES[name]
    for f in dataclasses.fields(msg):
        if not f.init or f.name in ADDED_AFTER_V1.get(name, ()):
            continue  # a constant (an ack's ``ok``), or a field the v1 bytes predate
        default = (f.default_factory() if f.default_factory is not dataclasses.MISSING
                   else f.default)
        assert not _same(getattr(msg, f.name), default), f"{name}.{f.name} is its default"


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_stored_bytes_decode_to_every_value_and_encode_again_the_same(name):
    data = STORED["messages"][name]
    expected = MESSAGES[name]
    got = type(expected).decode(data)
    for f in dataclasses.fields(expected):
        want, have = getattr(expected, f.name), getattr(got, f.name)
        assert _same(have, want), f"{name}.{f.name}: {have!r} != {want!r}"
    assert got.encode() == data
    assert expected.encode() == data


def test_hostile_maps_are_answered_as_before():
    """The same maps accepted (the same message) and refused (the same text)."""
    changed = []
    for name, data, (verdict, result) in STORED["hostile"]:
        cls = getattr(m, name)
        try:
            now = ["ok", cls.decode(data).encode()]
        except DecodeError as exc:
            now = ["error", str(exc)]
        if now != [verdict, result]:
            changed.append(f"{name} {msgpack.unpackb(data, raw=False)!r:.160}: "
                           f"was {verdict} {result!r:.120}, now {now[0]} {now[1]!r:.120}")
    assert not changed, f"{len(changed)} of {len(STORED['hostile'])}:\n" + "\n".join(changed[:20])


def test_a_recording_made_before_decodes_and_encodes_again_the_same():
    kinds: Counter = Counter()
    for rec in read_recording(FIXTURES / "recording-v1.mcap"):
        if rec.kind not in m.CARRIES:
            continue
        msg = m.CARRIES[rec.kind].decode(rec.data)
        assert msg.encode() == rec.data, f"{rec.key}: encodes to other bytes"
        kinds[rec.kind] += 1
    assert kinds == {"state": 115, "scan": 115, "cmd": 43, "label": 21, "decision": 21,
                     "driver": 11, "ack": 11, "notice": 2, "world": 1}
