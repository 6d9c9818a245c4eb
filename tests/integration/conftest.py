"""Fixtures of the browser tests (``browser.py`` has the helpers)."""

from __future__ import annotations

import pytest
from browser import chromium, close_chromium, find_chromium, in_ci


@pytest.fixture(scope="module")
def browser():
    """A headless Chromium for the module's tests; skipped with the reason when none is
    installed, except in CI (``CI=true``), where a missing browser fails."""
    found = find_chromium()
    if isinstance(found, str):
        if in_ci():
            pytest.fail(f"CI=true and {found}")
        pytest.skip(found)
    drv = chromium()
    yield drv
    close_chromium(drv)
