"""Fault and fuzz campaigns: the proofs that the processes survive faults and hostile input.

They drive the real processes from a source checkout (``python -m campaigns.faults``,
``python -m campaigns.fuzz``); they are not part of the installed packages, like
``benchmarks/``. The suite runs them at CI size (tests/integration/test_faults.py,
tests/fuzz/test_fuzz.py)."""
