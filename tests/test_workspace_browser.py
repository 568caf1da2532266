"""The workspace in a real browser (Debian's Chromium driven by Playwright) beside a real
``fieldbank serve``: a clinician logs in, finds SYN-001, composes 200 U into ef and reads the
summary ``fieldbank whatif`` prints, feels before and after on the simulated robot in the same
application, saves the plan and marks it given; a viewer cannot save; a stranger's API call is
401 and a change without the CSRF token is refused; a patient code and a plan label with markup
are shown as text; axe-core finds no serious or critical violation on the login, patient,
composer and robot pages.

Skipped only when no ``chromium`` is on PATH and FIELDBANK_REQUIRE_BROWSER is not "1".
Screenshots of the patient page, the composer and the robot view at 1280×800 and 800×600 are
written where FIELDBANK_WORKSPACE_SHOTS names a folder.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from datetime import date
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from fieldbank.cli.main import cli
from fieldbank.storage import Database
from tests.browser_util import chromium
from tests.workspace_util import PASSWORDS, Workspace, build_db

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]
MARKUP_CODE = "<img src=x onerror=window.pwned=1>"
MARKUP_LABEL = "<script>window.pwned=3</script><b>bold?</b>"
SIZES = ((1280, 800), (800, 600))


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Workspace, str]]:
    root = tmp_path_factory.mktemp("wsb")
    url = build_db(root)
    with Database.open(url) as db:  # as another program might have written it: no code check
        db.raw_sql("INSERT INTO patients (code, body_mass_kg, height_m, side, notes, "
                   f"created_at) VALUES ('{MARKUP_CODE}', 70, 1.7, 'right', "
                   "'<script>window.pwned=2</script>', '2024-01-01 00:00:00')")
    with Workspace(url) as ws:
        yield ws, url


def _wait(page: Any, expr: str, timeout_s: float = 60.0) -> Any:
    """Poll ``expr`` in the page until it is truthy (the page's policy allows no eval, so
    Playwright's wait_for_function cannot run)."""
    end = time.monotonic() + timeout_s
    while True:
        v = page.evaluate(expr)
        if v:
            return v
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {expr}")
        page.wait_for_timeout(100)


def _axe(page: Any, where: str) -> None:
    from axe_playwright_python.sync_playwright import Axe

    res = Axe().run(page)
    bad = [(v["id"], v["impact"], v["help"], [n["target"] for n in v["nodes"]][:3])
           for v in res.response["violations"] if v["impact"] in ("serious", "critical")]
    assert not bad, (where, bad)


def _shot(page: Any, name: str) -> None:
    folder = os.environ.get("FIELDBANK_WORKSPACE_SHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(folder) / name))


def _login(page: Any, base: str, name: str) -> None:
    page.goto(base)
    page.fill("#login-name", name)
    page.fill("#login-password", PASSWORDS[name])
    page.click("form.login button[type=submit]")
    page.wait_for_selector("#find")


@pytest.fixture(scope="module")
def browser(served: tuple[Workspace, str]) -> Iterator[Any]:
    exe = chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=ARGS)
        try:
            yield b
        finally:
            b.close()


def test_a_clinician_composes_feels_saves_and_gives_a_plan(
        served: tuple[Workspace, str], browser: Any) -> None:
    ws, url = served
    cli_doc = json.loads(CliRunner().invoke(
        cli, ["whatif", "SYN-001", "--botox", "ef=200U", "--db", url, "--json"]).stdout)
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(ws.url)
    _axe(page, "login")
    _login(page, ws.url, "alice")
    page.fill("#find", "SYN-00")
    page.click("a[href='#/patients/SYN-001']")
    page.wait_for_selector("#s-plans ~ table", timeout=120_000)
    assert page.inner_text("h1") == "Patient SYN-001"
    assert "under-determined" in page.inner_text("main")  # the fit's status, and why
    _axe(page, "patient page")
    page.click("text=Compose a plan")
    page.wait_for_selector("#bt-ef")
    page.fill("#bt-ef", "200")
    _wait(page, "window.fbComposer.last && window.fbComposer.last.plan_label.includes('ef 200 U')",
          120)
    shown = page.locator("#summary-lines p").all_inner_texts()[:3]
    assert shown == cli_doc["summary"]["lines"]
    ef_row = page.locator("#grades tr", has_text="ef elbow flexors").locator("td")
    assert ef_row.nth(2).inner_text() == "mild → very mild"  # as the CLI's grade line says
    assert page.locator("#whatif-figure").get_attribute("src", timeout=5000).startswith("blob:")
    _axe(page, "composer")
    # a dose change updates everything: the summary follows 100 U
    page.fill("#bt-ef", "100")
    _wait(page, "window.fbComposer.last.plan_label.includes('ef 100 U')", 120)
    assert page.locator("#summary-lines p").all_inner_texts()[0] != shown[0]
    page.fill("#bt-ef", "200")
    _wait(page, "window.fbComposer.last.plan_label.includes('ef 200 U')", 120)
    # feel it: one click, the robot starts (simulated here), the view opens in this app
    page.click("#feel")
    page.wait_for_url("**/robot", timeout=180_000)
    info = _wait(page, "window.fb && window.fb.info && window.fb.info.models", 120)
    assert info["A"]["model_id"] == 1 and "what-if result" in info["B"]["label"]
    assert "ef 200 U" in info["B"]["plan"]
    _wait(page, "window.fb.frames.length > 5 || window.fb.drawn > 5", 60)
    _axe(page, "robot view")
    blend = ("fetch('/api/robot').then(r => r.json()).then(d => d.renderer && "
             "d.renderer.blend {})")
    page.click("#btn-b")  # after
    _wait(page, blend.format("> 0.99"), 60)
    page.click("#btn-a")  # before again
    _wait(page, blend.format("< 0.01"), 60)
    # back to the plan: the doses are still there; save it, mark it given
    page.click("text=← back to the plan")
    page.wait_for_selector("#bt-ef")
    assert page.input_value("#bt-ef") == "200"
    _wait(page, "window.fbComposer.last && window.fbComposer.last.plan_label.includes('ef 200 U')",
          120)
    page.click("#save")
    saved = _wait(page, "window.fbComposer.saved", 60)
    page.fill("#give-date", date.today().isoformat())
    page.click("#give")
    page.wait_for_selector(f"text=Plan {saved['plan_id']} recorded as given on", timeout=60_000)
    assert not errors, errors
    page.close()
    with Database.open(url) as db:
        plan = db.get_plan(saved["plan_id"])
        assert plan.spec["given_on"] == date.today().isoformat() and plan.patient_code == "SYN-001"
        acts = [(e.action, e.entity) for e in db.audit_entries(200, actor="alice")]
        assert ("add", "plan") in acts and ("give", "plan") in acts and ("read", "patient") in acts


def test_screenshots_at_both_sizes(served: tuple[Workspace, str], browser: Any) -> None:
    ws, _ = served
    for w, h in SIZES:
        page = browser.new_page(viewport={"width": w, "height": h})
        _login(page, ws.url, "alice")
        page.goto(ws.url + "#/patients/SYN-001")
        page.wait_for_selector("#s-plans ~ table", timeout=120_000)
        page.wait_for_timeout(500)
        _shot(page, f"patient-{w}x{h}.png")
        page.goto(ws.url + "#/patients/SYN-001/compose")
        page.wait_for_selector("#bt-ef")
        page.fill("#bt-ef", "200")
        _wait(page, "window.fbComposer.last && window.fbComposer.last.plan_label.includes('200')",
              120)
        _shot(page, f"composer-{w}x{h}.png")
        # the summary is in view beside (or above) the doses, and nothing spills sideways
        box = page.locator("#summary").bounding_box()
        assert box is not None and box["y"] < h and box["x"] + box["width"] <= w + 1
        assert page.evaluate("document.documentElement.scrollWidth") <= w + 1
        running = page.evaluate("fetch('/api/robot').then(r => r.json()).then(d => d.running)")
        if not running:  # this test run alone: the robot with the stored plan 1 (models 1, 2)
            assert page.evaluate("""() => fetch('/api/robot/push', {method: 'POST',
                headers: {'Content-Type': 'application/json', 'X-CSRF-Token': window.fbApp.csrf},
                body: JSON.stringify({a_model_id: 1, b_model_id: 2})}).then(r => r.status)""") \
                == 200
        page.goto(ws.url.rstrip("/") + "/robot")
        _wait(page, "window.fb && window.fb.drawn > 5", 120)
        _shot(page, f"robot-{w}x{h}.png")
        # nothing of the page spills sideways at this size
        assert page.evaluate("document.documentElement.scrollWidth") <= w + 1
        page.close()


def test_a_viewer_cannot_save_a_stranger_gets_401_no_csrf_no_change_markup_is_text(
        served: tuple[Workspace, str], browser: Any) -> None:
    ws, url = served
    # a stranger: no cookie, no token
    ctx = browser.new_context()
    resp = ctx.request.get(ws.url + "api/patients/SYN-001")
    assert resp.status == 401 and resp.json() == {
        "error": "log in first (or send Authorization: Bearer TOKEN)"}
    ctx.close()
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    _login(page, ws.url, "victor")
    page.goto(ws.url + "#/patients/SYN-001/compose")
    page.wait_for_selector("#bt-ef")
    page.fill("#bt-ef", "150")
    _wait(page, "window.fbComposer.last && window.fbComposer.last.plan_label.includes('150')", 120)
    assert page.is_disabled("#save") and page.is_disabled("#feel")
    status = page.evaluate("""async () => (await fetch('/api/plans', {method: 'POST',
        headers: {'Content-Type': 'application/json', 'X-CSRF-Token': window.fbApp.csrf},
        body: JSON.stringify({patient: 'SYN-001', botox: 'ef=150U'})})).status""")
    assert status == 403
    page.close()
    # a clinician's page, a change without its CSRF token: refused, nothing stored
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    _login(page, ws.url, "alice")
    with Database.open(url) as db:
        n = len(db.list_plans())
    got = page.evaluate("""async () => { const r = await fetch('/api/plans', {method: 'POST',
        headers: {'Content-Type': 'application/json'},
        body: JSON.stringify({patient: 'SYN-001', botox: 'ef=150U'})});
        return [r.status, (await r.json()).error]; }""")
    assert got[0] == 403 and "CSRF" in got[1]
    # a plan whose label carries markup, saved the proper way
    ok = page.evaluate("""async (label) => (await fetch('/api/plans', {method: 'POST',
        headers: {'Content-Type': 'application/json', 'X-CSRF-Token': window.fbApp.csrf},
        body: JSON.stringify({patient: 'SYN-001', botox: 'ef=60U', label})})).status""",
                       MARKUP_LABEL)
    assert ok == 200
    with Database.open(url) as db:
        assert len(db.list_plans()) == n + 1
    page.goto(ws.url + "#/patients/SYN-001")
    page.wait_for_selector("#s-plans ~ table", timeout=120_000)
    # in the plans table and as the label of its after model, as typed
    cells = page.locator("td", has_text="window.pwned=3").all_inner_texts()
    assert len(cells) == 2 and set(cells) == {MARKUP_LABEL}
    # a patient code with markup: listed, its page titled, as text
    page.goto(ws.url + "#/")
    page.fill("#find", "img")
    page.wait_for_selector("ul.patients a")
    assert page.locator("ul.patients a").first.inner_text() == MARKUP_CODE
    page.locator("ul.patients a").first.click()
    page.wait_for_selector("text=Sessions", timeout=60_000)
    assert page.inner_text("h1") == f"Patient {MARKUP_CODE}"
    assert "<script>window.pwned=2</script>" in page.inner_text("p.lead")
    assert page.evaluate("window.pwned") is None
    assert page.locator("main img[src='x'], main script, main b:has-text('bold?')").count() == 0
    page.close()
