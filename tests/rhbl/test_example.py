"""The ``rhbl example`` command runs end to end quickly."""

from __future__ import annotations

from lab.cli import main


def test_example_command(tmp_path, capsys):
    out = tmp_path / "ex.rhbl"
    assert main(["example", "--vectors", "300", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "extended tree equals training in one go: True" in text
    assert out.exists()
