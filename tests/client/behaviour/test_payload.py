"""A scan read in place from its payload (``FeatureSpec.reader()``, the controller's hot path)
gives what ``Scan.decode`` and ``FeatureSpec.extract`` give, and reads nothing they would
refuse. Every test runs twice: with the kernel compiled ahead of time (setup.py; skipped where
it is not built) and with numba's."""

from __future__ import annotations

import importlib

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client.behaviour import _payload_layout as layout
from client.behaviour import features
from client.behaviour.features import FEATURES, FeatureSpec, PayloadReader
from protocol.codec import PROTOCOL_VERSION, DecodeError
from protocol.messages import MAX_BEAMS, Scan

# the kernels numba compiles when first used: the same checks, after tens of seconds of
# compiling; only in the whole suite (`make test`), not the fast tier (`make check`)
NUMBA = pytest.param("numba", marks=pytest.mark.slow)


@pytest.fixture(autouse=True, scope="module", params=["ahead-of-time", NUMBA])
def kernel(request):
    """The kernel every reader of the module uses."""
    if request.param == "numba":
        read = importlib.import_module("client.behaviour._payload_kernels").read_features
    else:
        try:
            aot = importlib.import_module("client.behaviour._payload_aot")
        except ImportError:
            aot = None
        if aot is None or aot.source_hash() != layout.source_hash():
            pytest.skip("no payload kernel compiled ahead of time from this source (setup.py: "
                        "no C compiler, or the source changed since make install)")
        read = aot.read_features
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(features, "_payload_kernel", lambda: read)
        yield request.param


specs = st.builds(
    FeatureSpec,
    beams=st.lists(st.sampled_from([0.0, 10.0, 22.5, 45.0, 90.0, 135.0, 170.0, 180.0]),
                   min_size=1, max_size=6).map(tuple),
    clamp=st.sampled_from([1.0, 2.0]), scale=st.just(2.0),
    heading=st.sampled_from([None, "lr"]), window=st.sampled_from([0.0, 5.0, 11.25, 40.0]))
finite = st.floats(allow_nan=False, allow_infinity=False)
ranges_values = st.one_of(st.floats(-1.0, 9.0, width=32), st.sampled_from([0.0, -0.0, 3e38]))
poses = st.tuples(finite, finite, st.one_of(finite, st.sampled_from([np.pi / 2, -np.pi / 2])))
scans = st.builds(
    lambda ts, sid, rs, pose, truth, angles: Scan(
        ts=ts, id=sid, ranges=np.array(rs, dtype=np.float32), pose=pose, truth=truth,
        min_angle=angles[0], max_angle=angles[1], resolution=angles[2], max_range=angles[3]),
    finite, st.one_of(st.integers(0, 300), st.integers(0, 2**64 - 1)),
    st.lists(ranges_values, min_size=1, max_size=400), poses, st.none() | poses,
    st.tuples(*[st.floats(-1e6, 1e6)] * 4))


def assert_read_as_decoded(reader: PayloadReader, data: bytes) -> None:
    """``reader`` holds the scan ``Scan.decode(data)`` gives, and the features of it."""
    ref = Scan.decode(data)
    for name in ("ts", "id", "pose", "truth", "min_angle", "max_angle", "resolution",
                 "max_range", "count"):
        assert getattr(reader, name) == getattr(ref, name), name
        assert type(getattr(reader, name)) is type(getattr(ref, name)), name
    assert np.array_equal(reader.ranges, ref.ranges) and reader.ranges.dtype == np.float32
    assert np.array_equal(reader.bearings(), ref.bearings())
    assert np.array_equal(reader.x, reader.spec.extract(ref.ranges, ref.pose[2]))
    scan = reader.to_scan()
    assert scan.ranges.flags.writeable and np.array_equal(scan.ranges, ref.ranges)
    assert (scan.ts, scan.id, scan.pose, scan.truth) == (ref.ts, ref.id, ref.pose, ref.truth)


def test_the_layout_is_the_one_scan_encode_writes():
    assert layout.VERSION == PROTOCOL_VERSION and layout.MAX_BEAMS == MAX_BEAMS
    plain = Scan(ts=1.0, id=1, ranges=np.ones(3, np.float32))
    assert ("v", *plain.to_map()) == layout.KEYS[:-1]
    assert ("v", *plain.__class__(**{**plain.__dict__, "truth": (1.0, 2.0, 3.0)}).to_map()
            ) == layout.KEYS


@settings(max_examples=200, deadline=None)
@given(specs, scans)
def test_a_scan_as_senders_write_it_is_read_as_decoded(spec, scan):
    reader = spec.reader()
    data = scan.encode()
    read = reader.read(data)
    if scan.count < 2 or scan.id >= 2**63:  # left to the decoder (and extract, which names it)
        assert not read
        return
    assert read
    assert_read_as_decoded(reader, data)


@settings(max_examples=300, deadline=None)
@given(specs, scans, st.data())
def test_a_damaged_payload_is_read_only_when_it_decodes_to_the_same(spec, scan, data):
    """Bytes changed, cut or added anywhere: whatever the reader reads, the decoder accepts
    with the same values; what the decoder refuses, the reader never reads."""
    payload = bytearray(scan.encode())
    for _ in range(data.draw(st.integers(1, 3))):
        how = data.draw(st.sampled_from(["flip", "cut", "add"]))
        at = data.draw(st.integers(0, max(0, len(payload) - 1)))
        if how == "flip" and payload:
            payload[at] = data.draw(st.integers(0, 255))
        elif how == "cut":
            del payload[at:at + data.draw(st.integers(1, 9))]
        else:
            payload[at:at] = bytes(data.draw(st.lists(st.integers(0, 255), min_size=1,
                                                      max_size=9)))
    reader = spec.reader()
    if not reader.read(bytes(payload)):
        return
    assert_read_as_decoded(reader, bytes(payload))


def test_other_valid_layouts_are_left_to_the_decoder():
    reader = FEATURES["wall"].reader()
    scan = Scan(ts=0.5, id=3, ranges=np.linspace(0.1, 3.0, 360, dtype=np.float32))
    fields = {"v": PROTOCOL_VERSION, **scan.to_map()}
    for data in (msgpack.packb(dict(reversed(list(fields.items()))), use_bin_type=True),
                 msgpack.packb(fields, use_bin_type=True, use_single_float=True),
                 msgpack.packb({**fields, "extra": 1}, use_bin_type=True),
                 bytearray(scan.encode())):
        assert not reader.read(data)
        assert Scan.decode(bytes(data)).id == 3  # valid: the controller decodes and answers it


def test_what_the_decoder_refuses_is_not_read():
    reader = FEATURES["wall"].reader()
    good = np.full(360, 2.0, np.float32)
    for bad in (np.r_[good[:-1], np.nan], np.r_[np.inf, good[1:]], np.r_[good[:-1], -np.inf]):
        data = Scan(ts=1.0, id=1, ranges=bad.astype(np.float32)).encode()
        assert not reader.read(data)
        with pytest.raises(DecodeError):
            Scan.decode(data)
    for data in (Scan(ts=np.nan, id=1, ranges=good).encode(),
                 Scan(ts=1.0, id=1, ranges=good, pose=(0.0, np.inf, 0.0)).encode(),
                 Scan(ts=1.0, id=1, ranges=good).encode() + b"\xc0",
                 Scan(ts=1.0, id=1, ranges=good).encode()[:-1], b"", b"\x89"):
        assert not reader.read(data)
        with pytest.raises(DecodeError):
            Scan.decode(data)


def test_scans_of_another_beam_count_take_their_own_windows():
    spec = FEATURES["wall"]
    reader = spec.reader()
    rng = np.random.default_rng(0)
    for count in (360, 181, 360, 2, 1000):
        scan = Scan(ts=1.0, id=count, ranges=rng.uniform(0.1, 4.0, count).astype(np.float32))
        assert reader.read(scan.encode())
        assert np.array_equal(reader.x, spec.extract(scan.ranges, 0.0)) and reader.id == count
    assert not reader.read(Scan(ts=1.0, id=1, ranges=np.ones(1, np.float32)).encode())
    with pytest.raises(features.FeatureError):  # what the controller logs for it
        spec.extract(np.ones(1, np.float32))
