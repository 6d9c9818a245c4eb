"""``process.files``: the one rule for the files a person names. Written: only a regular file
or a new one (a symlink followed to its file), never a device, FIFO, socket or folder, which
are left as they are; read: only a regular file, a FIFO refused without blocking."""

from __future__ import annotations

import os
import socket
import stat

import pytest

from process import files


@pytest.fixture
def odd(tmp_path):
    """Every kind of non-regular target."""
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "folder").mkdir()
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "sock"))
    os.symlink("/dev/null", tmp_path / "to-device")
    os.symlink(tmp_path / "fifo", tmp_path / "to-fifo")
    yield {"fifo": tmp_path / "fifo", "folder": tmp_path / "folder", "sock": tmp_path / "sock",
           "device": "/dev/null", "to-device": tmp_path / "to-device",
           "to-fifo": tmp_path / "to-fifo"}
    sock.close()


def _kinds(paths) -> dict:
    return {k: stat.S_IFMT(os.stat(p).st_mode) for k, p in paths.items()}


def test_no_writer_replaces_or_writes_into_what_is_not_a_regular_file(odd):
    before = _kinds(odd)
    for name, path in odd.items():
        with pytest.raises(files.FileRuleError, match="only a regular file"):
            files.check_output(path, "--out")
        with pytest.raises(files.FileRuleError):
            files.write_text(path, "x")
        with pytest.raises(files.FileRuleError), files.replace_file(path):
            pytest.fail(f"{name}: the block ran")
        for overwrite in (False, True):
            with pytest.raises((files.FileRuleError, FileExistsError)):
                os.close(files.open_output(path, overwrite=overwrite))
    assert _kinds(odd) == before  # every one left as it was
    assert not any(p.name.endswith(".tmp") for p in odd["folder"].parent.iterdir())


def test_a_symlink_is_followed_to_its_file_and_kept(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    os.symlink(target, link)
    files.write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"


def test_a_missing_folder_is_made_by_the_writer_not_by_the_check(tmp_path):
    out = tmp_path / "a" / "b" / "out.json"
    files.check_output(out)
    assert not (tmp_path / "a").exists()
    files.write_text(out, "{}")
    assert out.read_text() == "{}"
    (tmp_path / "file").write_text("")
    with pytest.raises(files.FileRuleError, match="cannot write there"):
        files.check_output(tmp_path / "file" / "out.json")


def test_reading_refuses_what_is_not_a_regular_file_without_blocking(odd, tmp_path):
    for path in [*odd.values(), tmp_path / "missing"]:
        with pytest.raises(files.FileRuleError):
            files.check_input(path)
        with pytest.raises(files.FileRuleError):
            files.open_input(path).close()
    good = tmp_path / "good"
    good.write_bytes(b"abc")
    with files.open_input(good) as f:
        assert f.read() == b"abc"
