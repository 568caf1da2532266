"""Benchmark: a batch report over N patients, fitted and not, in this process and on a Dask
worker.

Targets, per case on one core, judged on CPU time (the machine is shared): the fitted report
≤ 100 ms with its 95% intervals computed and ≤ 60 ms with them kept with the fits; the same
report on a Dask worker ≤ 1.2 × this process's ``--jobs 1``; ≤ 100 kB of ``report.html`` per
case. A **fitted** case carries the 95% intervals of its fit's 40 parameter samples carried
through the plan (one vectorised pass, :class:`fieldbank.armbatch.ArmBatch`) and the plan's
check against the maps measured after it.

Cohorts (``tests/report_helpers.py``):

* ``fitted`` (``store_fitted_cohort``): N patients with 'pre' and 'post' sessions of maps, a
  fit of the 'pre' maps with its parameter samples (six real fits; the other patients are
  their namesakes with their own stored maps, models and fits), one plan each (botulinum,
  lengthening, rhizotomy, casting, tenotomy in turn) recorded as given;
* ``synthetic`` (``store_cohort``): models synthesized at several severities, no fits.

Measured per cohort and number of patients, in a fresh SQLite database:

* the baseline: the metrics alone of every case - both models compiled, every before/after
  metric and clinical read-out, the botulinum weeks (what a report computes without drawing);
* every case with its figures, and for fitted cases its intervals and check;
* the whole report with ``--jobs 1`` twice - the first computes the intervals and keeps them
  with the fits, the second reads them back - and with ``--jobs N``: wall and CPU time per
  case, as ratios to the baseline, the size of ``report.html``, identical bytes across runs.

With ``--cluster`` (the fitted cohort, in a scratch database on the PostgreSQL server of
``--db``, default ``$FIELDBANK_TEST_PG_URL``): the report with ``--jobs 1`` in this process,
then - the kept intervals dropped - on a ``distributed.LocalCluster`` of one worker process
speaking TLS with the certificates ``fieldbank cluster certs`` makes, twice (intervals
computed, then kept). Per case: the worker's CPU time against ``--jobs 1`` in this process
(the target), and beside it this process's main thread (the command: selecting, reading the
payloads back, writing), the two together, and the share of the worker's CPU that the same
worker spends idle over the same wall time (Dask's heartbeats and system monitor, the TLS
event loop; measured for ``IDLE_S`` seconds before the runs) - on a loaded machine a case
takes long in wall time, and that share grows with it. The worker is warmed up as this process is -
one case computed there (imports, its database, first compilations), then the metrics alone of
every case (the compilations each kind of plan needs) - before the clock starts. The worker's
CPU is given twice: the whole process (every thread, Dask's own included) and its task
threads alone (the executor threads that run the tasks, each read from its own CPU clock); the
idle process's rate is measured for ``IDLE_S`` seconds before the runs, in the same run.

Run: python benchmarks/bench_report.py [--patients 20 100] [--jobs 2]
         [--cohort fitted|synthetic|both] [--cluster] [--db URL]
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import load_line
from fieldbank.evaluate.arms import ArmCache
from fieldbank.evaluate.compare import Conditions, compare
from fieldbank.interventions.catalogue import Botulinum
from fieldbank.interventions.course import stretch_course
from fieldbank.interventions.report import Selection, build_report, select_cases
from fieldbank.interventions.report.compute import TIMECOURSE_WEEKS, compute_case
from fieldbank.interventions.report.select import CaseSpec
from fieldbank.storage import Database
from tests.report_helpers import store_cohort, store_fitted_cohort

TARGET_MS_FIRST = 100.0
TARGET_MS_KEPT = 60.0
TARGET_WORKER_RATIO = 1.2
TARGET_KB_PER_CASE = 100.0
#: Seconds the idle worker is watched for its background CPU.
IDLE_S = 5.0
FILES = ("report.html", "metrics.csv", "metrics.json")
Check = tuple[str, float, bool, str]


def metrics_only(spec: CaseSpec) -> None:
    """What a case computes before any drawing."""
    arms = ArmCache()
    arm_b, arm_a = arms(spec.before), arms(spec.after)
    cond = Conditions.standard(arm_b)
    compare(arm_b, arm_a, cond)
    if spec.plan is not None and any(isinstance(s, Botulinum) for s in spec.plan.steps):
        stretch_course(arm_b, spec.plan, TIMECOURSE_WEEKS, arms=arms)


def timed(fn: Callable[[], object]) -> tuple[float, float]:
    """(wall, CPU) seconds of one call (CPU: this process)."""
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def baseline(cases: list[CaseSpec]) -> tuple[float, float]:
    """(wall, CPU) seconds per case of the metrics alone."""
    w = c = 0.0
    for case in cases:
        dw, dc = timed(lambda case=case: metrics_only(case))
        w, c = w + dw, c + dc
    return w / len(cases), c / len(cases)


def same_files(dirs: list[Path]) -> bool:
    return all((a / f).read_bytes() == (dirs[0] / f).read_bytes() for a in dirs for f in FILES)


def line(what: str, n: int, w: float, c: float, base_c: float, extra: str = "") -> None:
    print(f"  {what:<44} {1e3 * w / n:7.1f} ms wall {1e3 * c / n:7.1f} ms CPU per case "
          f"({c / n / base_c:5.2f}x the metrics' CPU){extra}")


def run_cohort(kind: str, n: int, jobs: int, tmp: Path) -> list[Check]:
    """One cohort in a fresh SQLite database; returns the target checks."""
    url = f"sqlite:///{tmp / f'{kind}{n}.sqlite3'}"
    out = tmp / f"{kind}{n}"
    with Database.open(url) as db:
        t = time.perf_counter()
        (store_fitted_cohort if kind == "fitted" else store_cohort)(db, n)
        print(f"\n== {kind} cohort, {n} patients (stored in {time.perf_counter() - t:.1f} s; "
              f"{load_line()})")
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
        m = len(cases)
        base = base_c / m
        line("metrics alone (compare, read-outs, weeks)", m, base_w, base_c, base)
        line("metrics, figures" + (", intervals, check" if kind == "fitted" else ""), m,
             full_w, full_c, base, f", figures {fig_bytes / m / 1e3:.1f} kB")
        runs = [("jobs1-first", 1), ("jobs1-again", 1), (f"jobs{jobs}", jobs)]
        cpus: dict[str, float] = {}
        for name, j in runs:
            w, c = timed(lambda j=j, name=name: build_report(db, Selection(), out / name,
                                                            jobs=j))
            cpus[name] = c / n
            what = {"jobs1-first": "report --jobs 1, intervals computed" if kind == "fitted"
                    else "report --jobs 1", "jobs1-again": "report --jobs 1, intervals kept"
                    if kind == "fitted" else "report --jobs 1, again"}.get(
                        name, f"report --jobs {j} (CPU: this process only)")
            size = (out / name / "report.html").stat().st_size / n / 1e3
            line(what, n, w, c, base, f", report.html {size:.1f} kB per case")
    same = same_files([out / name for name, _ in runs])
    print(f"  identical bytes from all three reports: {'yes' if same else 'NO'}")
    kb = (out / "jobs1-first" / "report.html").stat().st_size / n / 1e3
    checks: list[Check] = [
        (f"{kind} {n}: <= {TARGET_KB_PER_CASE:g} kB of report.html per case", kb,
         kb <= TARGET_KB_PER_CASE, "kB"),
        (f"{kind} {n}: identical bytes", float(same), same, "")]
    if kind == "fitted":
        first, kept = 1e3 * cpus["jobs1-first"], 1e3 * cpus["jobs1-again"]
        checks[:0] = [
            (f"fitted {n}: <= {TARGET_MS_FIRST:g} ms CPU per case, intervals computed", first,
             first <= TARGET_MS_FIRST, "ms"),
            (f"fitted {n}: <= {TARGET_MS_KEPT:g} ms CPU per case, intervals kept", kept,
             kept <= TARGET_MS_KEPT, "ms")]
    return checks


# --- on a Dask worker -------------------------------------------------------------------------
def _forget_intervals(url: str) -> None:
    """Drop the intervals the previous report kept with the fits (the next computes them)."""
    from sqlalchemy import create_engine, text

    eng = create_engine(url)
    with eng.begin() as c:
        c.execute(text("DELETE FROM fit_intervals"))
    eng.dispose()


@contextmanager
def tls_cluster(certs: Path) -> Iterator[tuple[Any, Any]]:
    """A LocalCluster of one worker process, scheduler and worker speaking only TLS with the
    cluster's certificates, and the project's scheduler setting for it."""
    from distributed import LocalCluster, Security

    from fieldbank.scheduler import SchedulerFlags, resolve_scheduler

    def c(name: str) -> str:
        return str(certs / name)

    security = Security(tls_ca_file=c("ca.pem"), tls_scheduler_cert=c("scheduler.pem"),
                        tls_scheduler_key=c("scheduler-key.pem"),
                        tls_worker_cert=c("worker.pem"), tls_worker_key=c("worker-key.pem"),
                        tls_client_cert=c("client.pem"), tls_client_key=c("client-key.pem"),
                        require_encryption=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, protocol="tls://",
                      host="127.0.0.1", security=security, dashboard_address=None,
                      silence_logs=logging.ERROR, env={"FIELDBANK_DB": ""}) as cluster:
        sched = resolve_scheduler(SchedulerFlags(cluster.scheduler_address, c("ca.pem"),
                                                 c("client.pem"), c("client-key.pem")))
        yield cluster, sched


def _warm(cases: list[CaseSpec]) -> None:
    """On a worker: what this process ran before its clock started (the metrics alone of
    every case)."""
    for case in cases:
        metrics_only(case)


def _worker_cpu(client: Any) -> float:
    """The worker processes' CPU seconds (every thread: the tasks', Dask's own)."""
    return float(sum(client.run(time.process_time).values()))


def _executor_threads_cpu(dask_worker: Any) -> float:
    """On a worker: the CPU seconds of the threads that run its tasks (its default
    executor's threads, each read from its own CPU clock)."""
    pool = dask_worker.executors["default"]
    return float(sum(time.clock_gettime(time.pthread_getcpuclockid(t.ident))
                     for t in list(getattr(pool, "_threads", ())) if t.ident is not None))


def _task_cpu(client: Any) -> float:
    """The CPU seconds of the worker threads that run tasks (what the tasks themselves cost,
    without Dask's heartbeats, system monitor and event loop)."""
    return float(sum(client.run(_executor_threads_cpu).values()))


def run_worker(n: int, server_url: str, tmp: Path) -> list[Check]:
    """The fitted cohort on PostgreSQL: ``--jobs 1`` here, then on one Dask worker."""
    from distributed import Client

    from benchmarks.bench_cluster import scratch_database
    from fieldbank.clustercerts import CertOptions, write_certs

    out = tmp / f"worker{n}"
    certs = write_certs(tmp / f"certs{n}", CertOptions()).out_dir
    with scratch_database(server_url) as url, Database.open(url, upgrade="always") as db:
        t = time.perf_counter()
        store_fitted_cohort(db, n)
        print(f"\n== fitted cohort, {n} patients, PostgreSQL (stored in "
              f"{time.perf_counter() - t:.1f} s; {load_line()})")
        cases = select_cases(db, Selection())
        compute_case(cases[0])
        base_w, base = baseline(cases)
        line("metrics alone (compare, read-outs, weeks)", 1, base_w, base, base)
        local: dict[str, float] = {}
        for name in ("first", "kept"):
            w, c = timed(lambda name=name: build_report(db, Selection(), out / f"local-{name}",
                                                       jobs=1))
            local[name] = c / n
            line(f"--jobs 1 here, intervals {'computed' if name == 'first' else 'kept'}", n,
                 w, c, base)
        _forget_intervals(url)
        remote: dict[str, float] = {}
        tasks: dict[str, float] = {}
        with tls_cluster(certs) as (cluster, sched), \
                Client(cluster, set_as_default=False) as client:
            # warmed up as this process was: one case through the command on the worker
            # (imports, its database, first compilations), then the metrics alone of every
            # case there (the compilations each kind of plan needs)
            build_report(db, Selection(plan_ids=(cases[0].plan_id,)), out / "warm",
                         scheduler=sched)
            client.submit(_warm, cases, pure=False).result()
            _forget_intervals(url)
            # what the worker process spends doing nothing (Dask's heartbeats, its system
            # monitor, the TLS event loop): CPU seconds per second of wall time
            wk0, t0, w0 = _worker_cpu(client), _task_cpu(client), time.perf_counter()
            time.sleep(IDLE_S)
            idle_w = time.perf_counter() - w0
            idle = (_worker_cpu(client) - wk0) / idle_w
            idle_tasks = (_task_cpu(client) - t0) / idle_w
            print(f"  {'one idle TLS worker, the process':<44} {1e3 * idle:7.1f} ms CPU per second"
                  f" (its task threads {1e3 * idle_tasks:.2f} ms)")
            for name in ("first", "kept"):
                wk0, tk0 = _worker_cpu(client), _task_cpu(client)
                th0, p0 = time.thread_time(), time.process_time()
                w0 = time.perf_counter()
                build_report(db, Selection(), out / f"worker-{name}", scheduler=sched)
                w = time.perf_counter() - w0
                wk, tk = _worker_cpu(client) - wk0, _task_cpu(client) - tk0
                th, pr = time.thread_time() - th0, time.process_time() - p0
                remote[name] = wk / n
                tasks[name] = tk / n
                what = "computed" if name == "first" else "kept"
                line(f"one TLS worker, intervals {what}: process", n, w, wk, base,
                     f" = {remote[name] / local[name]:.2f}x --jobs 1 here")
                line("  its task threads", n, w, tk, base,
                     f" = {tasks[name] / local[name]:.2f}x --jobs 1 here")
                print(f"  {'':<44} the idle process's rate over this run's wall time: "
                      f"{1e3 * idle * w / n:.1f} ms per case (the process less it: "
                      f"{(wk - idle * w) / n / local[name]:.2f}x --jobs 1 here)\n"
                      f"  {'':<44} the command's own main thread {1e3 * th / n:.1f} ms CPU per "
                      f"case ({(wk + th) / n / local[name]:.2f}x with the worker process's; "
                      f"this process with the scheduler {1e3 * pr / n:.1f} ms)")
    same = same_files([out / d for d in ("local-first", "local-kept", "worker-first",
                                         "worker-kept")])
    print(f"  identical bytes, here and on the worker: {'yes' if same else 'NO'}")
    checks: list[Check] = [(f"worker {n}: identical bytes", float(same), same, "")]
    for name in ("first", "kept"):
        what = "computed" if name == "first" else "kept"
        for who, cpu in (("the worker process", remote), ("its task threads", tasks)):
            r = cpu[name] / local[name]
            checks.append((f"worker {n}: {who} <= {TARGET_WORKER_RATIO:g}x --jobs 1 here, "
                           f"intervals {what}", r, r <= TARGET_WORKER_RATIO, "x"))
    return checks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, nargs="+", default=[100])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cohort", choices=("fitted", "synthetic", "both", "none"),
                    default="both")
    ap.add_argument("--cluster", action="store_true",
                    help="also the fitted cohort on PostgreSQL, here and on a Dask worker")
    ap.add_argument("--db", default=os.environ.get("FIELDBANK_TEST_PG_URL"),
                    help="PostgreSQL server URL for --cluster (a scratch database is made)")
    args = ap.parse_args()
    if args.cluster and not args.db:
        print("--cluster: give --db or set FIELDBANK_TEST_PG_URL")
        return 2
    print(f"start: {load_line()}")
    checks: list[Check] = []
    kinds = {"both": ("fitted", "synthetic"), "none": ()}.get(args.cohort, (args.cohort,))
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.patients:
            for kind in kinds:
                checks += run_cohort(kind, n, args.jobs, Path(tmp))
            if args.cluster:
                checks += run_worker(n, args.db, Path(tmp))
    print(f"\nend: {load_line()}")
    for what, value, ok, unit in checks:
        print(f"target: {what}: {value:.2f} {unit} ({'met' if ok else 'NOT met'})")
    return 0 if all(ok for what, _, ok, _ in checks if what.endswith("identical bytes")) else 1


if __name__ == "__main__":
    sys.exit(main())
