"""``rhbl console --behaviour NAME|FILE`` in a real headless Chromium against a real server and
console process: the page shows the behaviour's instructions and its success rule in words (a
behaviour given by file, made here); without ``--behaviour`` the world's behaviour (the room's:
wall following); a bad ``--behaviour`` is one line and exit status 2. Tests wait on the DOM with
deadlines, never on fixed sleeps.

Skipped with the reason when no Chromium is installed, except in CI (``CI=true``).
"""

from __future__ import annotations

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("aiohttp")

from browser import ConsoleProcess  # noqa: E402

from client.behaviour.given import rule_words  # noqa: E402
from client.behaviour.spec import behaviour  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

BEHAVIOUR = """
name = "hug-left"
summary = "keep the wall on the robot's left, never touching it"
perception = "wall"
instructions = '''
Keep the wall on the robot's LEFT at about 0.6 m: the hug-left lesson.
Go round every corner with it.
'''

[expert]
name = "wall-follower"
side = "left"

[worlds]
teach = ["room"]

[starts]
room = [[8.0, 0.7, 3.14159], [3.0, 0.7, 3.14159]]

[success]
time-limit = { seconds = 90 }
no-collision = {}
wall-band = { side = "left", near = 0.4, far = 1.0, fraction = 0.75 }
"""


def _shown(browser, url: str, timeout: float = 20.0) -> dict:
    """The page's behaviour section once it is shown: name, instructions, rule."""
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(url)
    WebDriverWait(browser, timeout).until(
        lambda d: d.find_element("id", "behaviour").get_attribute("data-name"))
    return {k: browser.find_element("id", i).get_attribute("textContent")
            for k, i in (("name", "behaviour-name"), ("instructions", "instructions"),
                         ("rule", "rule"))}


def test_the_page_shows_the_instructions_and_rule_of_a_behaviour_given_by_file(
        start_module_server, browser, tmp_path):
    path = tmp_path / "hug-left.toml"
    path.write_text(BEHAVIOUR)
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint, "--behaviour", str(path))
    try:
        shown = _shown(browser, console.wait_url())
    finally:
        rc = console.stop()
    assert rc == 0, console.output()
    assert shown["name"] == "hug-left"
    assert "the hug-left lesson" in shown["instructions"]
    assert "Go round every corner with it." in shown["instructions"]
    # the rule in words, as the file says it (not the room's own behaviour's)
    assert shown["rule"] == f"success: {rule_words(behaviour(path))}"
    assert "the wall on the left within 0.4-1 m for 75% of the time" in shown["rule"]


def test_home_puts_the_robot_at_the_behaviours_own_start_pose(start_module_server, browser,
                                                              tmp_path):
    from selenium.webdriver.support.ui import WebDriverWait

    path = tmp_path / "hug-left.toml"
    path.write_text(BEHAVIOUR)
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint, "--behaviour", str(path))
    try:
        _shown(browser, console.wait_url())
        WebDriverWait(browser, 20).until(
            lambda d: d.find_element("id", "pose").get_attribute("data-x"))
        browser.find_element("id", "reset").click()  # Home: its first start pose, not the room's
        WebDriverWait(browser, 20).until(lambda d: abs(
            float(d.find_element("id", "pose").get_attribute("data-x") or 0) - 8.0) < 0.05 and abs(
            float(d.find_element("id", "pose").get_attribute("data-yaw") or 0)) > 3.0)
        # the start pose list is the behaviour's too
        assert len(browser.find_elements("css selector", "#starts option")) == 2
    finally:
        rc = console.stop()
    assert rc == 0, console.output()


def test_without_behaviour_the_page_shows_the_worlds(start_module_server, browser):
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint)
    try:
        shown = _shown(browser, console.wait_url())
    finally:
        rc = console.stop()
    assert rc == 0, console.output()
    wall = behaviour("wall-following")
    assert shown["name"] == "wall-following"
    assert shown["instructions"].split() == wall.instructions.split()
    assert shown["rule"] == f"success: {rule_words(wall)}"


def test_a_bad_behaviour_is_one_line_and_exit_2(start_module_server, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(BEHAVIOUR.replace('no-collision = {}', 'dance = {}'))
    srv = start_module_server("room")
    console = ConsoleProcess(srv.endpoint, "--behaviour", str(bad))
    assert console.wait(30) == 2, console.output()
    out = console.output()
    assert "Traceback" not in out
    assert f"{bad}: field 'success.dance': unknown rule" in out
