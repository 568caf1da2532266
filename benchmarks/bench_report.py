"""Benchmark: a batch report over 100 synthetic patients.

Targets (issue: reports a clinician reads at a glance): ≤ 100 ms and ≤ 100 kB per case,
figures included, so that 100 patients take ≤ 15 s on 2 cores.

Builds a fresh SQLite database with N synthetic patients (``tests/report_helpers.py``
``store_cohort``: models synthesized at several severities, one stored plan each, botulinum
into flexors and extensors, lengthening, rhizotomy, casting, tenotomy in turn; no fits), then
measures in this process:

* the baseline: the metrics alone of every case - both models compiled, every before/after
  metric and clinical read-out, the botulinum weeks (what a report computes without drawing);
* every case with its figures (SVG text), per case: time and size, as ratios to the baseline;
* the whole report with ``--jobs 1`` and ``--jobs N`` (selection, figures, cohort figures,
  HTML, CSV, JSON written): total time, size of ``report.html`` per case, identical bytes.

Run: python benchmarks/bench_report.py [--patients 100] [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions, compare
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.course import stretch_course
from fieldbank.interventions.report import Selection, build_report, select_cases
from fieldbank.interventions.report.compute import TIMECOURSE_WEEKS, compute_case
from fieldbank.interventions.report.select import CaseSpec
from fieldbank.storage import Database
from tests.report_helpers import store_cohort

TARGET_MS_PER_CASE = 100.0
TARGET_KB_PER_CASE = 100.0
TARGET_S_PER_100 = 15.0


def metrics_only(spec: CaseSpec) -> None:
    """What a case computes before any drawing."""
    arms = ArmCache()
    arm_b, arm_a = arms(spec.before), arms(spec.after)
    cond = Conditions.standard(arm_b)
    compare(arm_b, arm_a, cond)
    if spec.plan is not None and any(isinstance(s, Botulinum) for s in spec.plan.steps):
        stretch_course(arm_b, spec.plan, TIMECOURSE_WEEKS, arms=arms)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    n = args.patients
    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{Path(tmp) / 'bench.sqlite3'}"
        with Database.open(url) as db:
            t = time.perf_counter()
            store_cohort(db, n)
            print(f"stored {n} synthetic patients, models and plans in "
                  f"{time.perf_counter() - t:.1f} s")
            cases = select_cases(db, Selection())
            compute_case(cases[0])  # warm-up: imports, first compilations
            t = time.perf_counter()
            for c in cases:
                metrics_only(c)
            base = (time.perf_counter() - t) / len(cases)
            t = time.perf_counter()
            fig_bytes = 0
            for c in cases:
                fig_bytes += sum(len(f.svg.encode("utf-8")) for f in compute_case(c).figures)
            full = (time.perf_counter() - t) / len(cases)
            print(f"baseline  metrics only (compare, read-outs, weeks)  {1e3 * base:7.1f} ms "
                  "per case")
            print(f"case      metrics + figures (SVG)                   {1e3 * full:7.1f} ms "
                  f"per case ({full / base:.2f}x baseline; drawing "
                  f"{1e3 * (full - base):.1f} ms), figures {fig_bytes / len(cases) / 1e3:.1f} "
                  "kB per case")
            times, sizes = {}, {}
            for jobs in dict.fromkeys((1, args.jobs)):
                t = time.perf_counter()
                out = build_report(db, Selection(), Path(tmp) / f"jobs{jobs}", jobs=jobs)
                times[jobs] = time.perf_counter() - t
                sizes[jobs] = out.html.stat().st_size
                print(f"report    --jobs {jobs}: {out.n_cases} cases in {times[jobs]:5.2f} s "
                      f"({1e3 * times[jobs] / out.n_cases:5.1f} ms per case, "
                      f"{times[jobs] / out.n_cases / base:.2f}x baseline; "
                      f"{out.jobs_used} process(es)); report.html "
                      f"{sizes[jobs] / 1e6:.2f} MB, {sizes[jobs] / out.n_cases / 1e3:.1f} kB "
                      "per case")
        same = all((Path(tmp) / "jobs1" / f).read_bytes()
                   == (Path(tmp) / f"jobs{args.jobs}" / f).read_bytes()
                   for f in ("report.html", "metrics.csv", "metrics.json"))
    best = min(times.values())
    per_case_kb = sizes[1] / n / 1e3
    if args.jobs != 1:
        print(f"speed-up of --jobs {args.jobs} over --jobs 1: "
              f"{times[1] / times[args.jobs]:.2f}x")
    print(f"identical bytes from both runs: {'yes' if same else 'NO'}")
    checks = [
        (f"<= {TARGET_MS_PER_CASE:g} ms per case, figures included", 1e3 * full,
         1e3 * full <= TARGET_MS_PER_CASE, "ms"),
        (f"<= {TARGET_KB_PER_CASE:g} kB of report.html per case", per_case_kb,
         per_case_kb <= TARGET_KB_PER_CASE, "kB"),
        (f"{n} patients <= {TARGET_S_PER_100 * n / 100:g} s (best run)", best,
         best <= TARGET_S_PER_100 * n / 100, "s"),
    ]
    for what, value, ok, unit in checks:
        print(f"target: {what}: {value:.1f} {unit} ({'met' if ok else 'NOT met'})")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
