"""A label is checked against the laser it claims to come from (issue 36.2): a label carrying
100,000 beams, or negative ranges, was journaled and learned, and a flood of them grew the
journal by 1.35 GB. ``client.laser.Laser`` learns the robot's laser from the server's scans (or
the lineage's journal) and refuses what does not fit it, counted by kind; ``Pairing`` keeps
nothing it refuses, and its queue of labeled scans is bounded in bytes as well as in count."""

from __future__ import annotations

import numpy as np
import pytest

from client.labels import Pairing, scan_bytes
from client.laser import Laser, LaserMismatch
from client.lineage import Lineage, Refused
from protocol.messages import LabeledScan, Scan, TeacherAction


def _scan(sid: int, beams: int = 360, low: float = 0.2, **kw) -> Scan:
    ranges = np.random.default_rng(sid).uniform(low, 3.0, beams).astype(np.float32)
    return Scan(ts=0.1 * sid, id=sid, ranges=ranges, **{"resolution": np.pi / (beams - 1), **kw})


def _labeled(seq: int, beams: int = 360, low: float = 0.2) -> bytes:
    s = _scan(seq, beams, low)
    return LabeledScan(scan_id=seq, action="fwd", origin="s1", seq=seq, ranges=s.ranges,
                       yaw=0.0).encode()


def test_the_laser_is_learned_from_the_first_consistent_scan_and_holds():
    laser = Laser()
    with pytest.raises(LaserMismatch, match="not known"):
        laser.check_ranges(np.ones(360, np.float32), "label 0")
    with pytest.raises(LaserMismatch, match="not one laser's geometry") as bad:
        laser.check_scan(_scan(1, 100_000, resolution=np.pi / 359))  # 100,000 beams, 360 steps
    assert bad.value.kind == "geometry" and laser.beams is None
    laser.check_scan(_scan(2))
    assert laser.beams == 360 and laser.max_range == 8.0
    with pytest.raises(LaserMismatch, match="has 100000 beams, the laser 360"):
        laser.check_scan(_scan(3, 100_000))  # consistent in itself: another laser
    with pytest.raises(LaserMismatch, match="ranges from -1"):
        laser.check_ranges(np.full(360, -1.0, np.float32), "label 4")
    with pytest.raises(LaserMismatch, match="ranges from"):
        laser.check_ranges(np.full(360, 9.0, np.float32), "label 5")  # past max_range
    assert laser.too_big(400_100, "a label") and not laser.too_big(360 * 4 + 200, "a label")
    assert laser.refused == {"beams": 1}


def test_pairing_keeps_no_label_that_does_not_fit_the_laser():
    laser = Laser()
    p = Pairing(laser=laser)
    p.on_labeled(_labeled(0))  # no scan seen yet: refused (its teacher resends it)
    p.on_scan(_scan(1).encode())
    p.on_labeled(_labeled(2, beams=100_000))
    p.on_labeled(_labeled(3, low=-1.0))
    p.on_labeled(_labeled(4))
    assert laser.refused == {"no_laser": 1, "beams": 1, "ranges": 1}
    assert p.waiting() == 1 and p.get(0.0)[1].seq == 4


def test_pairing_is_bounded_in_bytes():
    p = Pairing(max_ready_bytes=10 * 360 * 4)
    for sid in range(30):
        p.on_scan(_scan(sid).encode())
        p.on_label(TeacherAction(scan_id=sid, action="fwd").encode())
    assert p.waiting() == 10 and p.stats["lost"] == 20 and p.ready_bytes == 10 * 360 * 4
    assert scan_bytes(p.get(0.0)[0]) == 360 * 4 and p.ready_bytes == 9 * 360 * 4


def test_a_lineage_learns_from_one_laser(tmp_path):
    core = Lineage(tmp_path / "t.rhbl", features="wall")
    with pytest.raises(Refused, match="negative") as bad:
        core.learn(0, 0.0, -np.ones(360, np.float32), 0.0, "fwd", "s1", 0)
    assert bad.value.kind == "ranges" and core.applied == 0
    assert core.learn(1, 0.1, _scan(1).ranges, 0.0, "fwd", "s1", 1) is not None
    with pytest.raises(Refused, match="has 100000 beams, the lineage's laser 360"):
        core.learn(2, 0.2, np.ones(100_000, np.float32), 0.0, "fwd", "s1", 2)
    core.close()
    again = Lineage(tmp_path / "t.rhbl", features="wall")  # the journal's labels say so
    assert again.beams == 360 and again.applied == 1


def test_a_resent_label_of_goals_in_order_with_every_beacon_in_view_fits():
    """A resent label carries what the fiducial finder saw (at most MAX_BEACONS items): it is
    not refused as too big for the laser, a flood of 400 KB labels still is."""
    import numpy as np

    from client.laser import Laser
    from protocol.messages import (
        MAX_BEACONS,
        SEEN_BYTES,
        FiducialItem,
        LabeledScan,
        TeacherAction,
    )

    items = tuple(FiducialItem(2**32 - 1, 1e300, -3.14159) for _ in range(MAX_BEACONS))
    act = TeacherAction(scan_id=1, action="fwd", origin="o" * 64, seq=2**40, goal=2**32 - 1,
                        reached=2**32 - 1, seen=items)
    size = len(LabeledScan.of(act, np.ones(180, np.float32), 0.0).encode())
    laser = Laser(beams=180)
    assert not laser.too_big(size, "a label", "teacher/labeled", extra=SEEN_BYTES)
    assert laser.too_big(400_000, "a label", "teacher/labeled", extra=SEEN_BYTES)
