"""Debian's Chromium for the tests that open a page in a real browser."""

from __future__ import annotations

import os
import shutil

import pytest


def chromium() -> str:
    """The browser's executable; a skip when it is missing, a failure when CI requires it
    (FIELDBANK_REQUIRE_BROWSER=1)."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("FIELDBANK_REQUIRE_BROWSER") == "1":
            pytest.fail("FIELDBANK_REQUIRE_BROWSER=1 but no chromium on PATH "
                        "(apt-get install -y chromium).")
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    return exe
