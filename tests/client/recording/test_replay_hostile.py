"""Hostile recordings given to ``rhbl replay``: a topic read from the file is published only
when it is a robot's plain key (a wildcard topic reached every robot's subscribers; an empty
chunk or ``#``/``?`` gave a zenoh traceback), a log time near 2^64 or a 10^9 s pause plays
(pauses capped at ``--max-gap``) instead of an OverflowError or a silent sleep for ever."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zenoh

from client.recording.mcap_file import RecordingWriter
from process.session import make_config
from protocol import keys
from protocol import messages as m

ROOT = Path(__file__).resolve().parents[3]
R = np.full(36, 2.0, dtype=np.float32)


def recording(path: Path, topics_times: list[tuple[str, int]]) -> Path:
    with RecordingWriter(path, viewer=False) as w:
        for k, (topic, ns) in enumerate(topics_times):
            w.write(topic, m.Scan(ts=float(k), id=k, ranges=R).encode(), ns)
    return path


def rhbl(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lab.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("topic", [
    "rhbl/**/laser/0/data/scan", "rhbl/*/laser/0/data/scan", "rhbl/r$*0/laser/0/data/scan",
    "rhbl//laser/0/data/scan", "rhbl/r#0/laser/0/data/scan", "rhbl/r?0/laser/0/data/scan",
    "rhbl/r0/laser/00/data/scan",
])
def test_a_topic_that_is_not_a_plain_key_is_refused_before_any_connection(tmp_path, topic):
    rec = recording(tmp_path / "crafted.mcap", [(keys.scan_key("r0"), 10**9),
                                                (topic, 10**9 + 1)])
    r = rhbl("replay", str(rec), "--connect", "tcp/127.0.0.1:9", "--wait-subscriber", "0")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and repr(topic) in lines[0] and "not a robot's plain key" in \
        lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_huge_log_times_and_pauses_play_capped(tmp_path, free_port):
    """Three scans: at 1 s, 10^9 s later, then at 2^64-1 ns. Played with --max-gap 0.2 and
    --lockstep (the test answers each scan it gets, so every scan is known to have arrived):
    every scan arrives and the replay ends (it slept silently for ever, or raised
    OverflowError)."""
    import queue

    scan = keys.scan_key("r0")
    rec = recording(tmp_path / "gaps.mcap", [(scan, 10**9), (scan, 10**9 + 10**18),
                                             (scan, 2**64 - 1)])
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    got: queue.Queue[int] = queue.Queue()
    with zenoh.open(make_config(mode="router", listen=[endpoint])) as session:
        sub = session.declare_subscriber(
            scan, lambda s: got.put(m.Scan.decode(s.payload.to_bytes()).id))
        replay = subprocess.Popen(
            [sys.executable, "-m", "lab.cli", "replay", str(rec), "--connect", endpoint,
             "--max-gap", "0.2", "--wait-subscriber", "60", "--lockstep",
             "--lockstep-timeout", "60", "--log-level", "INFO"],
            cwd=ROOT, stderr=subprocess.PIPE, text=True)
        ids = []
        try:
            for _ in range(3):
                ids.append(got.get(timeout=60))
                session.put(keys.cmd_vel_key("r0", source="test"),
                            m.VelCmd(scan_id=ids[-1], source="test").encode())
            _, err = replay.communicate(timeout=60)
        finally:
            if replay.poll() is None:
                replay.kill()
        sub.undeclare()
    assert ids == [0, 1, 2]
    assert replay.returncode == 0, err
    assert "2 pauses longer than 0.2 s played as 0.2 s" in err, err
    assert "lock-step: 0 scans without an answer" in err and "Traceback" not in err, err


def test_only_the_named_robots_keys_are_published(tmp_path):
    from client.recording.replay import plan_replay

    rec = recording(tmp_path / "two.mcap", [(keys.scan_key("r0"), 10**9),
                                            (keys.scan_key("r1"), 10**9 + 1)])
    plan = plan_replay(rec, ["r1"], 5.0)
    assert plan.keys == {keys.scan_key("r1")} and plan.robots == ["r1"]
    with pytest.raises(ValueError, match="holds no sensor messages of robot r2"):
        plan_replay(rec, ["r2"], 5.0)
    assert os.path.getsize(rec) > 0
