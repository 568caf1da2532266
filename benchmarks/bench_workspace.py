"""Speed of the workspace where a clinician waits (``fieldbank serve``), against its targets:

* a dose change in the plan composer to an updated summary, grades, warnings, 95% intervals and
  figures (``POST /api/whatif``, 40 fit samples carried, SYN-001's fitted model whose fit held
  eight reflex parameters): ≤ 150 ms of CPU at p95;
* the patient page (the patient, its plans with their checks, the figures of its latest
  session's maps): ≤ 300 ms of CPU at p95;
* the page's weight (the page, its scripts and styles and what it fetches): ≤ 500 kB.

Baseline in the same run: ``fieldbank whatif``'s own computation of the same plans on the same
model (:func:`fieldbank.interventions.whatif.run_whatif` from the resolved model, a fresh use
case each time, as the command runs it; text and JSON output left out). The application runs in
this process behind aiohttp's test server; CPU is this process's (the server's threads, and the
test client's share, so it errs high), beside the wall time and the load average.

Run: python benchmarks/bench_workspace.py [--changes N]
"""

from __future__ import annotations

import argparse
import asyncio
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line

#: Targets: CPU seconds at p95, and bytes.
DOSE_TARGET_S = 0.150
PAGE_TARGET_S = 0.300
WEIGHT_TARGET_B = 500_000
PASSWORD = "a benchmark's password"


def p95(xs: list[float]) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, round(0.95 * (len(s) - 1)))]


def build(root: Path) -> str:
    from fieldbank.cli.demo import populate
    from fieldbank.storage import Database
    from fieldbank.web.accounts import add_user

    url = f"sqlite:///{root / 'fieldbank.sqlite3'}"
    with Database.open(url) as db:
        populate(db, root / "samples", patients=("SYN-001",))
        add_user(db, "bench", "clinician", PASSWORD)
    return url


def baseline(url: str, doses: list[int]) -> list[float]:
    """CPU s of ``run_whatif`` per plan, as ``fieldbank whatif SYN-001 --botox ef=DU`` runs."""
    from fieldbank import modelsource
    from fieldbank.interventions.spec import build_plan
    from fieldbank.interventions.whatif import run_whatif
    from fieldbank.storage import Database

    with Database.open(url) as db:
        source = modelsource.latest_of_patient(db, "SYN-001")
    out = []
    run_whatif(source, build_plan(botox=("ef=100U",)), interval_samples=40)  # warm-up
    for d in doses:
        plan = build_plan(botox=(f"ef={d}U",))
        c0 = time.process_time()
        run_whatif(source, plan, interval_samples=40)
        out.append(time.process_time() - c0)
    return out


async def workspace(url: str, doses: list[int], pages: int) -> dict[str, Any]:
    from aiohttp.test_utils import TestClient, TestServer

    from fieldbank.interventions.workspace import ComposerRoutes
    from fieldbank.storage import Database
    from fieldbank.web.app import make_app
    from fieldbank.web.core_api import CoreRoutes

    db = Database.open(url)
    app = make_app(db, [CoreRoutes(), ComposerRoutes()])
    res: dict[str, Any] = {"dose_cpu": [], "dose_wall": [], "page_cpu": [], "page_wall": []}
    async with TestClient(TestServer(app)) as c:
        shell = await (await c.get("/")).read()
        csrf = re.search(rb'name="csrf-token" content="([^"]+)"', shell)
        assert csrf
        r = await c.post("/api/login", json={"name": "bench", "password": PASSWORD},
                         headers={"X-CSRF-Token": csrf.group(1).decode()})
        token = (await r.json())["csrf"]
        assets = [m.decode() for m in re.findall(rb'(?:src|href)="(/static/[^"]+)"', shell)]
        asset_bytes = sum([len(await (await c.get(a)).read()) for a in assets])

        async def patient_page() -> int:
            n = 0
            doc = await (await c.get("/api/patients/SYN-001")).json()
            n += len(str(doc).encode())
            n += len(await (await c.get("/api/patients/SYN-001/plans")).read())
            latest = doc["sessions"][-1]["label"]
            for m in doc["maps"]:
                if m["session"] == latest:
                    n += len(await (await c.get(f"/api/maps/{m['id']}/figure.svg")).read())
            return n

        page_b = 0
        c0 = time.process_time()
        await patient_page()  # the first load checks the given plans against later maps
        res["page_first"] = time.process_time() - c0
        for _ in range(pages):
            c0, w0 = time.process_time(), time.perf_counter()
            page_b = await patient_page()
            res["page_cpu"].append(time.process_time() - c0)
            res["page_wall"].append(time.perf_counter() - w0)
        whatif_b = 0
        for k, d in enumerate([200, *doses]):
            c0, w0 = time.process_time(), time.perf_counter()
            r = await c.post("/api/whatif", json={"patient": "SYN-001", "botox": f"ef={d}U"},
                             headers={"X-CSRF-Token": token})
            body = await r.read()
            assert r.status == 200, body[:300]
            if k:  # the first request prepares the model (once per model and server)
                res["dose_cpu"].append(time.process_time() - c0)
                res["dose_wall"].append(time.perf_counter() - w0)
            whatif_b = len(body)
        res["weight_patient"] = len(shell) + asset_bytes + page_b
        res["weight_composer"] = len(shell) + asset_bytes + whatif_b + page_b
        res["assets"] = len(shell) + asset_bytes
    db.close()
    return res


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--changes", type=int, default=40, help="dose changes timed")
    ap.add_argument("--pages", type=int, default=20, help="patient page loads timed")
    args = ap.parse_args()
    doses = [50 + (37 * k) % 300 for k in range(args.changes)]
    with tempfile.TemporaryDirectory() as tmp:
        url = build(Path(tmp))
        print(load_line())
        base = baseline(url, doses[:10])
        ws = asyncio.run(workspace(url, doses, args.pages))
        print(load_line())
    b = statistics.median(base)
    dose, page = p95(ws["dose_cpu"]), p95(ws["page_cpu"])
    ok = {True: "OK", False: "OVER"}
    print(f"baseline  fieldbank whatif's own compute, one plan  {b * 1e3:7.1f} ms CPU median "
          f"(p95 {p95(base) * 1e3:.1f} ms) over {len(base)} plans")
    print(f"dose change -> summary, grades, intervals, figures  {dose * 1e3:7.1f} ms CPU p95 "
          f"(median {statistics.median(ws['dose_cpu']) * 1e3:.1f}; wall p95 "
          f"{p95(ws['dose_wall']) * 1e3:.1f} ms) over {len(ws['dose_cpu'])} changes; "
          f"{dose / b:.2f}x baseline; target <= {DOSE_TARGET_S * 1e3:.0f} ms "
          f"{ok[dose <= DOSE_TARGET_S]}")
    print(f"patient page (patient, plans + checks, figures)     {page * 1e3:7.1f} ms CPU p95 "
          f"(median {statistics.median(ws['page_cpu']) * 1e3:.1f}; wall p95 "
          f"{p95(ws['page_wall']) * 1e3:.1f} ms) over {len(ws['page_cpu'])} loads; "
          f"{page / b:.2f}x baseline; target <= {PAGE_TARGET_S * 1e3:.0f} ms "
          f"{ok[page <= PAGE_TARGET_S]}")
    print(f"patient page, first load (plans checked afresh)     {ws['page_first'] * 1e3:7.1f} ms "
          f"CPU (again only when the patient's plans, maps or models change)")
    for name in ("patient", "composer"):
        w = ws[f"weight_{name}"]
        print(f"page weight, {name:<9} page (page, scripts, data)   {w / 1e3:7.1f} kB "
              f"(the page and its scripts {ws['assets'] / 1e3:.1f} kB); target <= "
              f"{WEIGHT_TARGET_B / 1e3:.0f} kB {ok[w <= WEIGHT_TARGET_B]}")


if __name__ == "__main__":
    main()
