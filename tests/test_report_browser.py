"""A report opened in a real headless browser (Debian's Chromium) renders with all its images.

Skipped only when no ``chromium`` is on PATH and FIELDBANK_REQUIRE_BROWSER is not "1" (CI sets
it, so there a missing browser fails instead of skipping).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests.report_helpers import build_batch, run_cli

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars")


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("FIELDBANK_REQUIRE_BROWSER") == "1":
            pytest.fail("FIELDBANK_REQUIRE_BROWSER=1 but no chromium on PATH "
                        "(apt-get install -y chromium).")
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    return exe


def _run(exe: str, profile: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([exe, *FLAGS, f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=120, check=False)


def _png_pixels(path: Path) -> np.ndarray:
    from PIL import Image  # a matplotlib dependency

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.int32)


def test_report_renders_with_all_images_in_chromium(tmp_path: Path) -> None:
    exe = _chromium()
    batch = build_batch(tmp_path / "batch", patients=("SYN-003",))
    out = tmp_path / "report"
    res = run_cli("report", "--db", batch["url"], "--out", str(out), "--patient", "SYN-003")
    assert res.exit_code == 0, res.output
    html = out / "report.html"
    n_img = html.read_text(encoding="utf-8").count("<img ")
    assert n_img == 9  # botulinum (5 figures) + lengthening (4)
    url = html.resolve().as_uri()
    dom = _run(exe, tmp_path / "profile", "--virtual-time-budget=10000", "--dump-dom", url)
    assert dom.returncode == 0, dom.stderr[-2000:]
    body = re.search(r"<body[^>]*>", dom.stdout)
    assert body is not None, dom.stdout[:500]
    # set by the page's own script after 'load': every <img> complete with naturalWidth > 0
    assert f'data-images="{n_img}"' in body.group(0)
    assert 'data-images-ok="yes"' in body.group(0)
    shot = tmp_path / "shot.png"
    r = _run(exe, tmp_path / "profile", "--window-size=1000,1400", f"--screenshot={shot}", url)
    assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
    px = _png_pixels(shot)
    assert px.shape[:2] == (1400, 1000)
    # not blank: dark text and coloured plot pixels are present, the page is mostly light
    assert (px.sum(axis=2) < 150).mean() > 0.002
    colour = (px.max(axis=2) - px.min(axis=2)) > 60
    assert colour.mean() > 0.001
    assert px.std() > 20

    # the check can fail: a page with one broken image reports it
    broken = tmp_path / "broken.html"
    text = html.read_text(encoding="utf-8")
    i = text.index("data:image/png;base64,") + len("data:image/png;base64,")
    broken.write_text(text[:i] + "AAAA" + text[i + 4:], encoding="utf-8")
    dom = _run(exe, tmp_path / "profile", "--virtual-time-budget=10000", "--dump-dom",
               broken.resolve().as_uri())
    assert 'data-images-ok="no"' in dom.stdout
