"""Benchmark: a batch report over 100 patients, fitted and not.

Targets: ≤ 100 ms and ≤ 100 kB per case on one core, figures included (so that 100 patients
take ≤ 15 s on 2 cores), for a cohort of **fitted** patients: each case then also carries the
95% intervals of its fit's 40 parameter samples carried through the plan (one vectorised pass,
:class:`fieldbank.model.ArmBatch`) and the plan's check against the maps measured after it.

Cohorts, each in a fresh SQLite database:

* ``fitted`` (``tests/report_helpers.py`` ``store_fitted_cohort``): N patients with 'pre' and
  'post' sessions of maps, a fit of the 'pre' maps with its parameter samples (six real fits;
  the other patients are their namesakes with their own stored maps, models and fits), one plan
  each (botulinum, lengthening, rhizotomy, casting, tenotomy in turn) recorded as given;
* ``synthetic`` (``store_cohort``): models synthesized at several severities, no fits.

Measured in this process, per cohort:

* the baseline: the metrics alone of every case - both models compiled, every before/after
  metric and clinical read-out, the botulinum weeks (what a report computes without drawing);
* every case with its figures (SVG), and for fitted cases its intervals computed (the first
  report) - per case: wall and CPU time and size, as ratios to the baseline;
* the whole report with ``--jobs 1`` (one core) twice - the first computes the intervals and
  keeps them with the fits, the second reads them back - and with ``--jobs N``: time, size of
  ``report.html`` per case, identical bytes across the runs.

Run: python benchmarks/bench_report.py [--patients 100] [--jobs 2] [--cohort fitted|synthetic|both]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
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
from tests.report_helpers import store_cohort, store_fitted_cohort

TARGET_MS_PER_CASE = 100.0
TARGET_KB_PER_CASE = 100.0
TARGET_S_PER_100 = 15.0
FILES = ("report.html", "metrics.csv", "metrics.json")


def metrics_only(spec: CaseSpec) -> None:
    """What a case computes before any drawing."""
    arms = ArmCache()
    arm_b, arm_a = arms(spec.before), arms(spec.after)
    cond = Conditions.standard(arm_b)
    compare(arm_b, arm_a, cond)
    if spec.plan is not None and any(isinstance(s, Botulinum) for s in spec.plan.steps):
        stretch_course(arm_b, spec.plan, TIMECOURSE_WEEKS, arms=arms)


def timed(fn: Callable[[], object]) -> tuple[float, float]:
    """(wall, CPU) seconds of one call."""
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def run_cohort(kind: str, n: int, jobs: int, tmp: Path) -> list[tuple[str, float, bool, str]]:
    """Measure one cohort; returns the target checks (what, value, met, unit)."""
    url = f"sqlite:///{tmp / f'{kind}.sqlite3'}"
    with Database.open(url) as db:
        t = time.perf_counter()
        (store_fitted_cohort if kind == "fitted" else store_cohort)(db, n)
        print(f"\n== {kind} cohort: stored {n} patients, maps, models"
              + (", fits" if kind == "fitted" else "") + f" and plans in "
              f"{time.perf_counter() - t:.1f} s")
        cases = select_cases(db, Selection())
        compute_case(cases[0])  # warm-up: imports, first compilations
        # the baseline and the full case alternate, case by case, so that both see the same
        # load on a shared machine
        base_w = base_c = full_w = full_c = 0.0
        fig_bytes = 0
        for c in cases:
            w, cpu = timed(lambda c=c: metrics_only(c))
            base_w, base_c = base_w + w, base_c + cpu
            w0, c0 = time.perf_counter(), time.process_time()
            figs = compute_case(c).figures
            full_w += time.perf_counter() - w0
            full_c += time.process_time() - c0
            fig_bytes += sum(len(f.svg.encode("utf-8")) for f in figs)
        base = base_w / len(cases)
        full = full_w / len(cases)
        print(f"baseline  metrics only (compare, read-outs, weeks)   {1e3 * base:7.1f} ms per "
              f"case ({1e3 * base_c / len(cases):.1f} ms CPU)")
        print("case      metrics + figures"
              + (" + intervals + check" if kind == "fitted" else "                  ")
              + f" {1e3 * full:6.1f} ms per case ({1e3 * full_c / len(cases):.1f} ms CPU; "
              f"{full / base:.2f}x baseline; CPU {full_c / base_c:.2f}x), figures "
              f"{fig_bytes / len(cases) / 1e3:.1f} kB")
        times: dict[str, float] = {}
        cpus: dict[str, float] = {}
        sizes: dict[str, int] = {}
        runs = [("jobs1-first", 1), ("jobs1-again", 1), (f"jobs{jobs}", jobs)]
        for name, j in runs:
            w, c = timed(lambda j=j, name=name: build_report(db, Selection(), tmp / kind / name,
                                                            jobs=j))
            times[name], cpus[name] = w, c
            sizes[name] = (tmp / kind / name / "report.html").stat().st_size
            what = {"jobs1-first": "--jobs 1, intervals computed" if kind == "fitted" else
                    "--jobs 1", "jobs1-again": "--jobs 1, intervals kept with the fits"
                    if kind == "fitted" else "--jobs 1, again"}.get(name, f"--jobs {j}")
            print(f"report    {what:<40} {w:6.2f} s: {1e3 * w / n:6.1f} ms per case "
                  f"({w / n / base:.2f}x baseline; CPU of this process {1e3 * c / n:.1f} ms = "
                  f"{c / base_c:.2f}x the baseline's CPU), report.html "
                  f"{sizes[name] / n / 1e3:.1f} kB per case")
    same = all((tmp / kind / a / f).read_bytes() == (tmp / kind / b / f).read_bytes()
               for a, _ in runs for b, _ in runs for f in FILES)
    print(f"identical bytes from all three reports: {'yes' if same else 'NO'}")
    one_core = times["jobs1-first"] / n
    kb = sizes["jobs1-first"] / n / 1e3
    best = min(times.values())
    cpu_one = cpus["jobs1-first"] / n
    return [
        (f"{kind}: <= {TARGET_MS_PER_CASE:g} ms per case on one core (first report)",
         1e3 * one_core, 1e3 * one_core <= TARGET_MS_PER_CASE, "ms"),
        (f"{kind}: <= {TARGET_MS_PER_CASE:g} ms CPU per case on one core (first report; what "
         "an idle core would take)", 1e3 * cpu_one, 1e3 * cpu_one <= TARGET_MS_PER_CASE, "ms"),
        (f"{kind}: <= {TARGET_KB_PER_CASE:g} kB of report.html per case", kb,
         kb <= TARGET_KB_PER_CASE, "kB"),
        (f"{kind}: {n} patients <= {TARGET_S_PER_100 * n / 100:g} s (best run)", best,
         best <= TARGET_S_PER_100 * n / 100, "s"),
        (f"{kind}: identical bytes", float(same), same, ""),
    ]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cohort", choices=("fitted", "synthetic", "both"), default="both")
    args = ap.parse_args()
    print(f"load average at start: {', '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    checks = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in (("fitted", "synthetic") if args.cohort == "both" else (args.cohort,)):
            checks += run_cohort(kind, args.patients, args.jobs, Path(tmp))
    print(f"\nload average at end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    for what, value, ok, unit in checks:
        print(f"target: {what}: {value:.1f} {unit} ({'met' if ok else 'NOT met'})")
    return 0 if all(ok for what, _, ok, _ in checks if what.endswith("identical bytes")) else 1


if __name__ == "__main__":
    sys.exit(main())
