"""A hostile snapshot given to a command fails in one line that names the file, exit 2 (usage):
``rhbl evaluate --tree``, ``rhbl compact --tree``, ``rhbl learner --resume``. The loaders' cases
are in tests/rhbl/test_snapshot_hostile.py; a running controller's and learner's in the
contention campaign (campaigns/contention/snapshot.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import msgpack
import numpy as np
import pytest

from client.behaviour.features import FEATURES
from client.behaviour.learning import DemonstrationLearner

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bad(tmp_path_factory) -> dict[str, Path]:
    """A learner's snapshot made hostile: the header that wrapped to 0 in int64 (2^62 spheres
    of 4 features, no data), and metadata naming no valid features."""
    rng = np.random.default_rng(0)
    learner = DemonstrationLearner(FEATURES["wall"])
    for k in range(30):
        learner.observe(rng.uniform(0.2, 8.0, 360).astype(np.float32), 0.0, ("fwd", "fwd-left")[k % 2])
    folder = tmp_path_factory.mktemp("bad")
    learner.save(folder / "good.rhbl")
    good = msgpack.unpackb((folder / "good.rhbl").read_bytes(), raw=False)
    wrap = dict(good, n_features=4, radii=dict(good["radii"], shape=[2**62]),
                centers=dict(good["centers"], shape=[2**62, 4], data=b""))
    meta = dict(good, metadata=dict(good["metadata"], features={"kind": 5}))
    out = {}
    for name, doc in (("wrap", wrap), ("meta", meta)):
        out[name] = folder / f"{name} tree.rhbl"
        out[name].write_bytes(msgpack.packb(doc, use_bin_type=True))
    return out


def rhbl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lab.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=180)


@pytest.mark.parametrize("case", ["wrap", "meta"])
def test_evaluate_names_the_file_in_one_line(bad, case):
    r = rhbl("evaluate", "--tree", str(bad[case]), "--world", "room")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad[case]) in lines[0], r.stderr
    assert "Traceback" not in r.stderr and "reshape" not in r.stderr


def test_compact_names_the_file_in_one_line(bad, tmp_path):
    r = rhbl("compact", "--tree", str(bad["wrap"]), "--out", str(tmp_path / "small.rhbl"))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad["wrap"]) in lines[0], r.stderr
    assert not (tmp_path / "small.rhbl").exists()


def test_learner_resume_names_the_file_in_one_error_line(bad, tmp_path):
    r = rhbl("learner", "--resume", str(bad["wrap"]), "--out", str(tmp_path / "t.rhbl"))
    assert r.returncode == 2, r.stderr
    errors = [ln for ln in r.stderr.splitlines() if " ERROR " in ln]
    assert len(errors) == 1 and f"cannot load snapshot {bad['wrap']}: " in errors[0], r.stderr
    assert "Traceback" not in r.stderr
