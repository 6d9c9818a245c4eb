"""The benchmarks' modules for their tests: ``benchmarks/`` is not a package, so its files are
loaded by path (``people`` under its own name, as the study imports it)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_DIR = Path(__file__).resolve().parents[2] / "benchmarks"


def load(name: str):
    """``benchmarks/<name>.py`` as the module ``name`` (loaded once)."""
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, _DIR / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


@pytest.fixture(scope="session")
def load_benchmark():
    return load


@pytest.fixture(scope="session")
def people():
    return load("people")


@pytest.fixture(scope="session")
def study():
    return load("bench_teach_study")
