"""A 20-patient report opened in a real headless browser (Debian's Chromium): every figure is
laid out and drawn, the page is not blank, and it prints to PDF with the metrics table and
the figures inside the page width.

Skipped only when no ``chromium`` is on PATH and FIELDBANK_REQUIRE_BROWSER is not "1" (CI sets
it, so there a missing browser fails instead of skipping).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fieldbank.storage import Database
from tests.browser_util import chromium
from tests.report_helpers import run_cli, store_cohort

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars")
#: A4 with the page's 10 mm side margins, in CSS pixels (96 per inch).
A4_CONTENT_PX = (210.0 - 2 * 10.0) / 25.4 * 96.0


def _png_pixels(path: Path) -> np.ndarray:
    from PIL import Image  # a matplotlib dependency

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.int32)


@pytest.mark.slow
def test_a_20_patient_report_in_chromium(tmp_path: Path) -> None:
    exe = chromium()
    from playwright.sync_api import sync_playwright

    url = f"sqlite:///{tmp_path / 'cohort.sqlite3'}"
    with Database.open(url) as db:
        store_cohort(db, 20)
    out = tmp_path / "report"
    res = run_cli("report", "--db", url, "--out", str(out), "--jobs", "2")
    assert res.exit_code == 0, res.output
    html = out / "report.html"
    text = html.read_text(encoding="utf-8")
    n_fig = text.count('class="fig"')
    # every case's figures (at least stretches, moving field, grades and a fourth) and the
    # cohort figure
    assert n_fig >= 20 * 4 + 1
    assert "<th>written</th>" in text  # dated by default
    page_url = html.resolve().as_uri()
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=["--no-sandbox",
                                                                 "--disable-gpu"])
        page = browser.new_page(viewport={"width": 1280, "height": 1400})
        page.goto(page_url)
        page.wait_for_function("document.body.getAttribute('data-figures-ok') !== null")
        # set by the page's own script after 'load': every figure laid out and drawn
        assert page.evaluate("document.body.getAttribute('data-figures')") == str(n_fig)
        assert page.evaluate("document.body.getAttribute('data-figures-ok')") == "yes"
        shot = tmp_path / "shot.png"
        page.screenshot(path=str(shot))
        # the first figures of the first case, scrolled into view, drawn
        page.locator("section.case figure").first.scroll_into_view_if_needed()
        fig_shot = tmp_path / "figure.png"
        page.locator("section.case figure").first.screenshot(path=str(fig_shot))
        # print layout: everything within the printable width of an A4 page
        page.emulate_media(media="print")
        page.set_viewport_size({"width": int(A4_CONTENT_PX), "height": 1000})
        widths = page.evaluate("""() => {
            const w = document.documentElement.clientWidth;
            const right = s => Math.max(0, ...Array.from(document.querySelectorAll(s))
                .map(e => e.getBoundingClientRect().right));
            return {page: w, table: right('table.metrics'), figures: right('svg.fig'),
                    tables: right('table'), scroll: document.documentElement.scrollWidth};
        }""")
        assert widths["table"] <= widths["page"] + 0.5, widths
        assert widths["figures"] <= widths["page"] + 0.5, widths
        assert widths["tables"] <= widths["page"] + 0.5, widths
        assert widths["scroll"] <= widths["page"] + 0.5, widths
        browser.close()
    for path in (shot, fig_shot):
        px = _png_pixels(path)
        assert (px.sum(axis=2) < 150).mean() > 0.002  # dark text and lines
        assert ((px.max(axis=2) - px.min(axis=2)) > 60).mean() > 0.001  # coloured plot pixels
        assert px.std() > 20

    # the page prints to PDF as a user would: chromium --print-to-pdf
    pdf = tmp_path / "report.pdf"
    r = subprocess.run([exe, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                        "--no-pdf-header-footer", f"--print-to-pdf={pdf}", page_url],
                       capture_output=True, text=True, timeout=180, check=False)
    assert r.returncode == 0 and pdf.exists(), r.stderr[-2000:]
    data = pdf.read_bytes()
    assert data[:5] == b"%PDF-"
    pages = len(re.findall(rb"/Type\s*/Page\b", data))
    assert pages >= 20  # each case starts a page

    # the check can fail: a page with one figure emptied reports it
    broken = tmp_path / "broken.html"
    i = text.index('class="fig"')
    j = text.index("</svg>", i)
    k = text.index(">", i) + 1
    broken.write_text(text[:k] + text[j:], encoding="utf-8")
    dom = subprocess.run([exe, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                          "--virtual-time-budget=10000", "--dump-dom",
                          broken.resolve().as_uri()],
                         capture_output=True, text=True, timeout=120, check=False)
    assert 'data-figures-ok="no"' in dom.stdout
