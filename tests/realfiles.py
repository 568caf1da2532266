"""Where the real recordings written by other labs' software are (``../shared/realfiles``).

``FIELDBANK_REALFILES`` names the folder, else ``<repository>/../shared/realfiles``; when
neither exists a test that needs them skips, saying why — or fails when
``FIELDBANK_REQUIRE_REALFILES=1`` (``scripts/test`` sets it when the folder is there).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def realfiles_dir() -> Path | None:
    env = os.environ.get("FIELDBANK_REALFILES")
    for cand in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "realfiles"]:
        if cand.is_dir():
            return cand
    return None


def all_realfiles() -> list[Path]:
    """Every file in the folder (a file added later is tested too); [] when absent."""
    base = realfiles_dir()
    if base is None:
        return []
    return sorted(p for p in base.rglob("*") if p.is_file())


def need_realfiles() -> Path:
    base = realfiles_dir()
    if base is None:
        why = ("no real recordings: set FIELDBANK_REALFILES or put them in "
               f"{ROOT.parent / 'shared' / 'realfiles'}")
        if os.environ.get("FIELDBANK_REQUIRE_REALFILES") == "1":
            pytest.fail(why)
        pytest.skip(why)
    return base
