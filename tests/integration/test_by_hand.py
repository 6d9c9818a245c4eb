"""``rhbl demo --by-hand`` as a person uses it from the README: the real command (its server,
learner, console and controller as real processes), the real page in headless Chromium. The
person demonstrates with the keys, presses Enter at the terminal (a pseudo-terminal here), the
controller drives and the page is in correct mode; Enter again, and the command stops every
process, says the tree learned by the person rule and evaluates it. Waits on events only (a
line, a DOM attribute), never on fixed sleeps."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("aiohttp")

from test_console_teach import _attr, _int, _keys, _open, _press, _until  # noqa: E402
from waiting import patience  # noqa: E402

from client.journal import Journal, journal_path  # noqa: E402
from client.recording.mcap_file import read_recording  # noqa: E402
from lab.children import Child, rhbl_argv  # noqa: E402
from protocol.messages import TeacherAction  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]


def test_a_person_teaches_by_hand_with_one_command(browser, tmp_path):
    out = tmp_path / "hand"
    master, slave = os.openpty()
    demo = Child("demo", rhbl_argv("demo", "--by-hand", "--console", "127.0.0.1:0", "--out",
                                   str(out), "--demonstrate", "600", "--correct", "600",
                                   "--starts", "1", "--drive-seconds", "10", "--record"),
                 tmp_path, cwd=ROOT, stop_signal=signal.SIGINT, stop_timeout=60.0,
                 preexec_fn=lambda: os.dup2(slave, 0)).start()
    try:
        assert demo.wait_for_line("console: http", 90), demo.output()
        url = next(ln.split(" ", 1)[1] for ln in demo.lines if ln.startswith("console: "))
        _open(browser, url)
        _until(browser, lambda d: _attr(d, "learner", "up") == "1", 30, "a learner is up")
        # Home once the map is drawn, as a person does (the demo's simulator may still be
        # starting when the page opens: Home then says the world is not known yet)
        _until(browser, lambda d: d.execute_script("return window.rhbl.view().starts.length"),
               60, "the world's start poses on the page")
        _press(browser, "HOME")
        _until(browser, lambda d: "reset" in d.find_element("id", "info").text, 30, "reset")
        _keys(browser, ("down", "ARROW_UP"))
        try:
            _until(browser, lambda d: _int(d, "labels", "given") >= 15, 30, "15 labels")
        finally:
            _keys(browser, ("up", "ARROW_UP"))
        _until(browser, lambda d: _int(d, "labels", "held") == _int(d, "labels", "given"), 30,
               "the learner holds every label")
        os.write(master, b"\n")  # Enter: the demonstration is over
        _until(browser, lambda d: (d.execute_script("return window.rhbl.view().driver")
                                   or "").startswith("controller"), 90,
               "the controller drives the learned tree")
        _press(browser, "c")
        _until(browser, lambda d: d.find_element("css selector", "#modes input[value=correct]")
               .is_selected(), 5, "correct mode")
        os.write(master, b"\n")  # Enter: correcting is over
        assert demo.wait(patience(240)) is not None, demo.output()
    finally:
        demo.kill()
        os.close(master)
        os.close(slave)
    text = demo.output()
    assert demo.rc == 0, text
    assert "1. demonstrate" in text and "2. correct" in text  # it said each step
    assert "the person rule" in text and "labels standing" in text
    assert "evaluate it in rooms it never saw" in text
    with Journal.open(journal_path(out / "tree.rhbl"), readonly=True) as j:
        assert j.header["meta"]["learning"]["rule"] == "person"
        assert len(list(j.standing())) >= 15
    # the session's recording: the page's labels say they are a person's, so retraining it
    # (rhbl train --from-recording, its default --teacher auto) takes the person rule too
    labels = [TeacherAction.decode(m.data) for m in read_recording(out / "run.mcap")
              if m.kind == "label"]
    assert len(labels) >= 15 and {a.source for a in labels} == {"console"}
    done = subprocess.run(rhbl_argv("train", "--from-recording", str(out / "run.mcap"),
                                    "--features", "wall", "--out", str(tmp_path / "again.rhbl")),
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "the person (--teacher auto chose it: the first label came from 'console') rule" \
        in done.stdout, done.stdout
