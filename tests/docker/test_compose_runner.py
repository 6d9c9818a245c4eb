"""docker/compose_test.py's pure parts (the whole run: tests/integration/test_compose_containers.py)."""

from __future__ import annotations

import datetime as dt
import importlib.util
import sys
from pathlib import Path

import pytest

DOCKER = Path(__file__).resolve().parents[2] / "docker"


@pytest.fixture(scope="module")
def runner():
    sys.path.insert(0, str(DOCKER))  # it imports compose_local and router_standin beside it
    try:
        spec = importlib.util.spec_from_file_location("compose_test", DOCKER / "compose_test.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules["compose_test"] = module  # its dataclasses look their module up
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(DOCKER))


def test_engine_time_stamps(runner):
    want = dt.datetime(2026, 12, 1, 19, 18, 43, tzinfo=dt.UTC).timestamp()
    assert runner._when("2026-12-01T19:18:43.300033382Z") == pytest.approx(want + 0.300033382)
    assert runner._when("2026-12-01T20:18:43.5+01:00") == pytest.approx(want + 0.5)
    assert runner._when("2026-12-01T19:18:43Z") == want
    with pytest.raises(ValueError, match="not a time stamp: 'yesterday'"):
        runner._when("yesterday")
    lines = runner._timed_lines("2026-12-01T19:18:44.25Z 19:18:44 server[1] INFO server up (x)\n"
                                "no stamp here\n")
    assert lines == [(pytest.approx(want + 1.25), "19:18:44 server[1] INFO server up (x)")]


def test_image_names_are_qualified_for_podman(runner):
    assert runner._qualified("python:3.11-slim-bookworm") == \
        "docker.io/library/python:3.11-slim-bookworm"
    assert runner._qualified("eclipse/zenoh:1.10.2") == "docker.io/eclipse/zenoh:1.10.2"
    assert runner._qualified("localhost/rhbl:1") == "localhost/rhbl:1"
    assert runner._qualified("quay.io/x/y:2") == "quay.io/x/y:2"
    assert runner._qualified("registry:5000/y:2") == "registry:5000/y:2"


def test_the_base_image_is_the_dockerfiles_python(runner):
    assert runner.dockerfile_default("PYTHON_IMAGE") == "python:3.11-slim-bookworm"
    assert runner.dockerfile_default("PYTHON_IMAGE", DOCKER / "router-standin.Dockerfile") == \
        "python:3.11-slim-bookworm"
    with pytest.raises(runner.StepFailed, match="no default for ARG NOPE"):
        runner.dockerfile_default("NOPE")


def test_base_recipe_is_named_by_its_digest(runner):
    argv, digest = runner.base_recipe("http://m/debian", "http://m/security")
    assert argv[-4:] == ["{tarball}", "deb http://m/debian bookworm main",
                         "deb http://m/debian bookworm-updates main",
                         "deb http://m/security bookworm-security main"]
    assert "--include=ca-certificates,python3,python3-venv" in argv
    assert runner.base_recipe("http://m/debian", "http://m/security")[1] == digest
    assert runner.base_recipe("http://other/debian", "http://m/security")[1] != digest


def test_no_engine_says_why(runner, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    assert runner.find_engine("podman") == "no container engine: no podman"
    assert runner.find_engine("docker") == "no container engine: no docker"


def test_report(runner, capsys):
    report = runner.Report()
    assert not report.passed  # nothing checked is nothing passed
    with report.step("one"):
        pass
    report.check("a", True, "fine")
    assert report.passed
    report.check("b", False, "broken")
    assert not report.passed
    summary = report.summary()
    assert "| one | 0.0 |" in summary
    assert summary.endswith("checks: 1 passed, 1 failed (b)")
    out = capsys.readouterr().out
    assert "compose-test: ok   a: fine" in out and "compose-test: FAIL b: broken" in out
