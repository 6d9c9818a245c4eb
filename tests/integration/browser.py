"""A real headless Chromium (Debian's ``chromium`` and ``chromium-driver``) and a real
``rhbl console`` process, for the console's browser tests and benchmark.

``chromium()`` starts a browser (selenium); when none is installed the caller skips with the
reason, except in CI (``CI=true``), where a missing browser is a failure. ``ConsoleProcess``
starts ``rhbl console`` on a free loopback port and reads the URL it prints.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from lab.children import Child, rhbl_argv

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--disable-dev-shm-usage", "--window-size=1200,800")


def find_chromium() -> tuple[str, str] | str:
    """(browser, driver) paths, or the reason there are none."""
    browser = next((p for p in ("/usr/bin/chromium", shutil.which("chromium") or "")
                    if p and os.access(p, os.X_OK)), None)
    driver = next((p for p in ("/usr/bin/chromedriver", shutil.which("chromedriver") or "")
                   if p and os.access(p, os.X_OK)), None)
    if browser and driver:
        return browser, driver
    return ("no Chromium to drive: install Debian's chromium and chromium-driver "
            "(scripts/ci-browser.sh); missing: "
            + ", ".join(n for n, p in (("chromium", browser), ("chromedriver", driver)) if not p))


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def chromium(*extra_flags: str):
    """A selenium Chrome driver for a new headless Chromium with an empty profile (and
    ``extra_flags``, e.g. ``--ignore-certificate-errors`` for a test certificate)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    found = find_chromium()
    if isinstance(found, str):
        raise RuntimeError(found)
    browser, driver = found
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    profile = tempfile.mkdtemp(prefix="rhbl-chromium-")
    for flag in (*CHROMIUM_FLAGS, *extra_flags, f"--user-data-dir={profile}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    drv = webdriver.Chrome(options=opts, service=Service(driver))
    drv.set_page_load_timeout(30)
    drv._rhbl_profile = profile  # removed by close_chromium
    return drv


def close_chromium(drv) -> None:
    try:
        drv.quit()
    finally:
        shutil.rmtree(getattr(drv, "_rhbl_profile", ""), ignore_errors=True)


class ConsoleProcess(Child):
    """``rhbl console --connect ENDPOINT --http 127.0.0.1:0 ...`` (a ``lab.children.Child``:
    stopped by PID with SIGTERM, then SIGKILL); ``url`` once it printed it."""

    def __init__(self, endpoint: str, *extra: str):
        super().__init__("rhbl console", rhbl_argv("console", "--connect", endpoint, "--http",
                                                   "127.0.0.1:0", *extra), cwd=ROOT)
        self.url: str | None = None
        self.start()

    def wait_url(self, timeout: float = 30.0) -> str:
        """The URL of its line ``console: <URL>``; stops it and raises if none comes."""
        if self.wait_for_line("console: http", timeout):
            self.url = next((ln.split(" ", 1)[1] for ln in self.output().splitlines()
                             if ln.startswith("console: ")), None)
        if self.url is None:
            self.stop()
            raise RuntimeError(f"rhbl console did not print its URL:\n{self.output()}")
        return self.url

    @property
    def base(self) -> str:
        return self.url.split("?", 1)[0]
