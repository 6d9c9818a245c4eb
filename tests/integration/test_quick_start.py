"""The README's quick start on a stock machine: ``make demo`` in a fresh copy of the repository
with the system's own ``python3`` where that one is "externally managed" (PEP 668: Debian 12,
Ubuntu 24.04), which refuses ``pip install`` outside a virtual environment.

The copy holds the repository's tracked files as they are on disk (what a fresh clone has, plus
uncommitted edits): no virtual environment, no installed package. The Makefile must make its own
virtual environment from that interpreter, install into it and run the demo (shortened through
``DEMO_ARGS``). It costs one ``pip install`` of the dependencies (about a minute; pip's cache
makes it faster).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(900)]

ROOT = Path(__file__).resolve().parents[2]
SYSTEM_PYTHON = "/usr/bin/python3"
_PROBE = ("import os, sys, sysconfig; print(sys.version_info >= (3, 11), sys.prefix == "
          "sys.base_prefix and os.path.isfile(os.path.join(sysconfig.get_path('stdlib'), "
          "'EXTERNALLY-MANAGED')))")


def _externally_managed_python() -> str:
    """The system's python3 if it is externally managed and new enough; else skip, saying why."""
    if not os.access(SYSTEM_PYTHON, os.X_OK):
        pytest.skip(f"no system interpreter {SYSTEM_PYTHON}")
    r = subprocess.run([SYSTEM_PYTHON, "-I", "-c", _PROBE], capture_output=True, text=True,
                       timeout=60)
    new_enough, managed = (r.stdout.split() + ["False", "False"])[:2]
    if managed != "True":
        pytest.skip(f"{SYSTEM_PYTHON} is not externally managed (no PEP 668 marker): the case "
                    "this test is about does not arise here")
    if new_enough != "True":
        pytest.skip(f"{SYSTEM_PYTHON} is older than Python 3.11, which rhbl needs")
    for tool in ("make", "git", "bash"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed")
    return SYSTEM_PYTHON


def _fresh_copy(dest: Path) -> None:
    r = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, timeout=60)
    if r.returncode != 0:
        pytest.skip("the repository is not a git checkout: no tracked files to copy")
    for name in filter(None, r.stdout.decode().split("\0")):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


def test_make_demo_with_an_externally_managed_system_python(tmp_path):
    python = _externally_managed_python()
    clone = tmp_path / "rhbl"
    out = tmp_path / "demo"
    _fresh_copy(clone)
    assert (clone / "Makefile").is_file() and not (clone / ".venv").exists()
    # nothing of this checkout's environment may leak into the copy's
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "MAKEFLAGS", "MAKELEVEL")}
    try:
        r = subprocess.run(
            ["make", f"PYTHON={python}", "demo",
             f"DEMO_ARGS=--teach-seconds 10 --rounds 0 --drive-seconds 10 --starts 1 --quiet "
             f"--out {out}"],
            cwd=clone, env=env, capture_output=True, text=True, timeout=840)
        log = (r.stdout + r.stderr)[-6000:]
        assert r.returncode == 0, log
        assert "rhbl is installed in the virtual environment .venv/" in r.stdout, log
        # the environment was made from the system interpreter, and the package is the copy's
        cfg = (clone / ".venv" / "pyvenv.cfg").read_text()
        assert f"home = {os.path.dirname(python)}" in cfg.splitlines(), cfg
        where = subprocess.run([str(clone / ".venv/bin/python"), "-c",
                                "import lab; print(lab.__file__)"], cwd=tmp_path, env=env,
                               capture_output=True, text=True, timeout=60)
        assert where.stdout.strip() == str(clone / "lab" / "__init__.py"), where.stderr
        # the demo ran to its end: the table, the learned robot, the files
        assert "| wall-following |" in r.stdout and "learned robot: " in r.stdout, log
        summary = json.loads((out / "summary.json").read_text())
        assert len(summary["teacher"]) == 1 and len(summary["learned"]) == 1
        assert summary["tree"]["nodes"] > 1
        helped = subprocess.run([str(clone / ".venv/bin/rhbl"), "--help"], env=env,
                                capture_output=True, text=True, timeout=60)
        assert helped.returncode == 0 and "demo" in helped.stdout, helped.stderr
        # a second `make demo` installs nothing again (the stamp is newer than pyproject.toml)
        again = subprocess.run(["make", "-n", f"PYTHON={python}", "demo"], cwd=clone, env=env,
                               capture_output=True, text=True, timeout=60)
        assert again.returncode == 0 and "pip install" not in again.stdout, again.stdout
    finally:
        shutil.rmtree(clone, ignore_errors=True)  # the environment is a few hundred MB
