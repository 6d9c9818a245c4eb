"""The console's map in a world with beacons, in a real headless Chromium against a real
server and console process: the beacons drawn where the walls are, those the robot's fiducial
finder sees highlighted, as the robot is put where it sees one, none, the other."""

from __future__ import annotations

import math

import pytest

zenoh = pytest.importorskip("zenoh")
pytest.importorskip("aiohttp")

from browser import ConsoleProcess  # noqa: E402
from test_console import _errors, _open  # noqa: E402
from waiting import eventually  # noqa: E402

from client.player import PlayerClient  # noqa: E402
from process.session import make_config  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]


@pytest.fixture(scope="module")
def env(start_module_server):
    srv = start_module_server("beacons-room")
    console = ConsoleProcess(srv.endpoint)
    console.wait_url()
    with zenoh.open(make_config(mode="client", connect=[srv.endpoint])) as session:
        yield {"console": console, "sim": PlayerClient(session=session, source="test").simulation}
    rc = console.stop()
    assert rc == 0, console.output()


def _seen(browser) -> str:
    return browser.find_element("id", "view").get_attribute("data-seen")


def test_the_map_draws_the_beacons_and_highlights_the_ones_in_view(env, browser):
    _open(browser, env["console"].url)
    canvas = browser.find_element("id", "view")
    eventually(lambda: canvas.get_attribute("data-beacons") == "1,2", 20, "the beacons drawn")
    env["sim"].set_pose2d(6.5, 3.0, 0.0)  # facing the green beacon, id 2, a little to the left
    # (from the start pose beacon 2 is in view too, to the right: the message of the new pose
    # is the one whose bearing is positive)
    eventually(lambda: browser.execute_script("return window.rhbl.view().seen"), 20,
               "beacon 2 alone in view, a little to the left",
               until=lambda seen: [i["id"] for i in seen] == [2] and seen[0]["bearing"] > 0)
    assert _seen(browser) == "2"
    view = browser.execute_script("return window.rhbl.view()")
    assert [(b["id"], b["colour"]) for b in view["beacons"]] == [(1, "#dc2828"), (2, "#28aa3c")]
    env["sim"].set_pose2d(1.0, 3.0, 0.0)  # the partition hides beacon 2, beacon 1 behind
    eventually(lambda: _seen(browser) == "", 20, "none highlighted")
    env["sim"].set_pose2d(1.0, 3.0, math.pi)
    eventually(lambda: _seen(browser) == "1", 20, "beacon 1 highlighted")
    assert not _errors(browser)
