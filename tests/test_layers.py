"""The one-way dependency rule of docs/architecture.md, checked on the source itself."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = {"rhbl", "protocol", "process", "server", "client", "lab"}
# package -> packages of ours it may import
ALLOWED = {
    "rhbl": set(),
    "protocol": set(),
    "process": {"protocol"},
    "server": {"protocol", "process"},
    "client": {"protocol", "process", "rhbl"},
    "lab": OURS,
}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found & OURS


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_the_layers_below(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"{package}/ has no Python files"
    bad = {
        str(f.relative_to(ROOT)): sorted(_imports(f) - ALLOWED[package] - {package})
        for f in files
    }
    bad = {f: mods for f, mods in bad.items() if mods}
    assert not bad, f"{package}/ imports layers it must not: {bad}"


def test_behaviour_code_is_pure():
    """client/behaviour runs in the zenoh processes and in the in-process harness alike."""
    for f in sorted((ROOT / "client" / "behaviour").rglob("*.py")):
        tree = ast.parse(f.read_text())
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
        assert "zenoh" not in names, f"{f} imports zenoh"


def test_offline_commands_load_no_zenoh():
    """Retraining from a recording and compacting pair labels with scans (client.labels) and
    read recordings without a session: no zenoh is imported."""
    import subprocess
    import sys

    code = ("import sys, lab.retrain, lab.compact, client.labels, client.recording.inspect; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'zenoh'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, check=True).stdout.strip()
    assert out == "[]"
