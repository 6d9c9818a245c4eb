"""protocol.ros2.attachment, against zenoh's own serialiser (what rmw_zenoh's zenoh-cpp uses)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from zenoh.ext import Int64, z_serialize

from protocol import DecodeError
from protocol.ros2.attachment import Attachment

GID = bytes(range(0xA0, 0xB0))


def _zenoh_current(seq, stamp, gid) -> bytes:
    """rmw_zenoh 0.2.4+/0.6.0+: serializer.serialize(int64), (int64), (std::array<uint8_t, 16>)."""
    return z_serialize((Int64(seq), Int64(stamp), gid)).to_bytes()


def _zenoh_keyed(seq, stamp, gid) -> bytes:
    """rmw_zenoh 0.2.0-0.2.3: each value after its key, a zenoh-ext string."""
    return z_serialize(("sequence_number", Int64(seq), "source_timestamp", Int64(stamp),
                        "source_gid", gid)).to_bytes()


def test_layout_is_33_bytes_as_rmw_zenohs_design_says():
    a = Attachment(7, 1_733_000_000_123_456_789, GID)
    data = a.encode()
    assert len(data) == 33
    assert data[:8] == (7).to_bytes(8, "little")
    assert data[8:16] == (1_733_000_000_123_456_789).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == GID


@given(st.integers(-2**63, 2**63 - 1), st.integers(-2**63, 2**63 - 1), st.binary(min_size=16,
                                                                                   max_size=16))
def test_encode_equals_zenoh_ext_and_decodes_both_layouts(seq, stamp, gid):
    a = Attachment(seq, stamp, gid)
    assert a.encode() == _zenoh_current(seq, stamp, gid)
    assert Attachment.decode(_zenoh_current(seq, stamp, gid)) == a
    assert Attachment.decode(_zenoh_keyed(seq, stamp, gid)) == a


@pytest.mark.parametrize(("data", "match"), [
    (b"", "needs 8 bytes at offset 0"),
    (Attachment(1, 2, GID).encode()[:20], "needs 16 bytes at offset 17"),
    (Attachment(1, 2, GID).encode() + b"\0", "1 bytes left over"),
    (_zenoh_current(1, 2, GID)[:16] + b"\x08" + GID[:8], "expected 16 bytes, got 8"),
    (_zenoh_keyed(1, 2, GID).replace(b"source_timestamp", b"source_timestamq"),
     "expected the key 'source_timestamp'"),
    (_zenoh_keyed(1, 2, GID)[:40], "needs"),
    (_zenoh_current(1, 2, GID)[:16] + b"\xff" * 10, "longer than 64 bits"),
    ("not bytes", "expected bytes"),
])
def test_malformed_attachments_are_decode_errors(data, match):
    with pytest.raises(DecodeError, match=match):
        Attachment.decode(data)


def test_bad_values_are_refused():
    with pytest.raises(ValueError, match="gid must be 16 bytes"):
        Attachment(1, 2, b"short")
    with pytest.raises(ValueError, match="int64"):
        Attachment(2**63, 0, GID)
