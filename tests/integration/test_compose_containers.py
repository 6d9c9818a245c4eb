"""docker/compose.yaml in real containers: ``make compose-test``'s runner, end to end.

docker/compose_test.py builds the base image (or finds it cached), the rhbl image from
docker/Dockerfile, the router image, runs the compose file under a project name of its own on
free loopback ports and checks it from the host; this test runs that command as a real process
and holds it to every check it must report. Skipped where no container engine runs, except in
CI (``CI`` set), where .ci/run installs podman first and a missing engine fails.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from lab.children import Child

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
RUNNER = ROOT / "docker" / "compose_test.py"
# the first run on a machine makes the base image (about 1.5 min) and every run builds the
# rhbl image (about 2 min on a quiet machine): bounded well above both
TIMEOUT = 1800
CHECKS = (
    "base image",
    "services started",
    "health checks",
    "anonymous client refused",
    "image",
    "labels acknowledged",
    "tree grew",
    "controller drove",
    "console answered",
    "numba kernels from the image",
    "down -v left nothing",
)
STEPS = ("base image", "rhbl image", "router image", "compose up", "teaching",
         "compose down -v", "clean up")


def _probe() -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(RUNNER), "--probe"], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)


@pytest.mark.timeout(TIMEOUT + 300)
def test_compose_scenario_in_real_containers(tmp_path):
    probe = _probe()
    if probe.returncode == 3:
        if os.environ.get("CI"):
            pytest.fail(f"CI must run the containers: {probe.stderr.strip()}")
        pytest.skip(probe.stderr.strip())
    assert probe.returncode == 0, probe.stdout + probe.stderr

    child = Child("compose-test", [sys.executable, str(RUNNER), "--workdir",
                                   str(tmp_path / "run")], tmp_path, cwd=ROOT,
                  stop_timeout=120)
    child.start()
    try:
        code = child.wait(TIMEOUT)
    finally:
        if child.poll() is None:  # SIGTERM: it removes what it started, then exits
            child.stop(signal.SIGTERM)
    out = child.output()
    assert code is not None, f"compose-test did not end in {TIMEOUT} s:\n{child.tail(60)}"
    for check in CHECKS:
        assert f"compose-test: ok   {check}:" in out, f"{check}:\n{child.tail(60)}"
    assert "FAIL" not in out, child.tail(60)
    for step in STEPS:
        assert f"| {step} | " in out, step  # every step timed
    assert f"checks: {len(CHECKS)} passed, 0 failed" in out, child.tail(60)
    assert code == 0, child.tail(60)


def test_runner_rejects_bad_arguments():
    run = subprocess.run([sys.executable, str(RUNNER), "--teach-seconds", "10",
                          "--demonstrate-seconds", "20"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == [
        "compose_test.py: --demonstrate-seconds must be less than --teach-seconds"]
    run = subprocess.run([sys.executable, str(RUNNER), "--teach-seconds", "-1"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 2 and "must be positive: '-1'" in run.stderr
