"""``benchmarks/bench_sim.py`` keeps working: its in-process run and its side-by-side laser
comparison (which checks the batched cast against one robot at a time) on a small scale."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import server
from server.world import load_world

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_sim.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_sim", _PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_in_process_run_reports_its_figures():
    r = _bench().bench_in_process("room", seconds=2.0, repeats=1)
    assert r["segments"] == len(load_world(server.world_path("room")).segments())
    for key in ("rtf", "tick_us", "scan_us", "step_us"):
        assert math.isfinite(r[key]) and r[key] > 0, key
    assert r["scan_us"] + r["step_us"] < 2 * r["tick_us"] + 1e3  # parts of the same ticks


def test_compare_scans_checks_and_times_both_casts():
    bench = _bench()
    one, together = bench.compare_scans(load_world(server.world_path("room")), 12, tiles=1,
                                        repeats=1)
    assert one > 0 and together > 0
