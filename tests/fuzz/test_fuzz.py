"""The fuzz campaign of ``campaigns.fuzz`` at CI size (the full one: ``python -m campaigns.fuzz``, 10,000
hostile messages per key): every key and queryable of the server, learner, teacher and
controller, the snapshot, journal and world files, and both web servers' HTTP edges (the
Foxglove bridge, the console)."""

from __future__ import annotations

import pytest

from campaigns import fuzz

pytestmark = [pytest.mark.integration, pytest.mark.timeout(280)]


def _check(results):
    bad = [r.line() for r in results if not r.ok]
    assert not bad, "\n".join(bad)
    assert all(r.sent + r.valid_sent > 0 for r in results)


def test_server_keys_reject_every_hostile_message_and_keep_the_robot():
    results = fuzz.fuzz_server(per_key=300, seed=1)
    assert len(results) == 11  # 2 command keys + 9 queryables
    _check(results)
    cmd = results[0]
    assert cmd.sent == 300 and cmd.rejected == 300 and cmd.valid_processed == 30


def test_client_keys_reject_every_hostile_message_and_keep_working(tmp_path):
    results = fuzz.fuzz_clients(per_key=150, seed=2, workdir=tmp_path)
    assert len(results) == 6  # scan, action, notice, labeled, ack, snapshot
    _check(results)


def test_fuzzed_files_load_or_raise_one_typed_error_naming_the_file(tmp_path):
    results = fuzz.fuzz_files(per_file=150, seed=3, workdir=tmp_path)
    _check(results)
    assert all(r.sent > 0 for r in results)


def test_the_generator_makes_only_messages_the_oracle_rejects():
    import random

    from protocol.messages import VelCmd

    gen = fuzz.hostile({"v": 1, "vel": [0.0, 0.0, 0.0], "state": True, "source": "x"},
                       VelCmd.decode, random.Random(0))
    for _ in range(500):
        with pytest.raises(Exception):  # noqa: B017 - any rejection is the point
            VelCmd.decode(next(gen))


def test_no_writer_replaces_or_writes_into_a_non_regular_target(tmp_path):
    results = fuzz.fuzz_written(workdir=tmp_path)
    _check(results)
    assert all(r.sent == 7 and r.valid_processed == 1 for r in results)


def test_hostile_recordings_are_refused_or_read_up_to_the_cut(tmp_path):
    results = fuzz.fuzz_recordings(per_file=150, seed=4, workdir=tmp_path)
    _check(results)
    cut = results[1]
    assert cut.valid_sent + cut.sent > 3000  # every byte of the small recording


def test_the_foxglove_bridge_refuses_every_hostile_request_and_keeps_serving(tmp_path):
    results = fuzz.fuzz_bridge(per_kind=20, seed=5, workdir=tmp_path)
    _check(results)


def test_the_console_refuses_every_hostile_request_and_keeps_serving(tmp_path):
    results = fuzz.fuzz_console(per_kind=20, seed=6, workdir=tmp_path)
    _check(results)
    assert len(results) == 12  # 9 kinds, a header never finished, both consoles alive
