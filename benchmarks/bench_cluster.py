"""Benchmark: a cohort refit and its report on a Dask LocalCluster of 1 and of 2 workers.

Target (BRIEF §17): a refit of 10,000 sessions in ≤ 1 hour on 16 cores; the engine's overhead
per task ≤ 5% of the task's own time; scaling efficiency ≥ 0.85 at 2 workers on an idle 2-core
machine.

For each number of workers W (1, then 2), in a fresh PostgreSQL database on the server of
``--db`` (default ``$FIELDBANK_TEST_PG_URL``; ``scripts/pg-test-server`` starts one):

* a cohort of ``--patients`` synthetic patients with two sessions of maps each
  (``tests/cohort_helpers.py``), refitted with ``fieldbank fit --all``'s defaults on a
  ``LocalCluster(n_workers=W, threads_per_worker=1)`` (workers started and warmed up before
  the clock starts): sessions per second;
* a report over one plan per fitted model on the same cluster: cases per second.

Then: scaling efficiency = throughput(2) / (2 × throughput(1)); the engine's overhead per task,
from Dask's task stream - the time a worker spends between tasks (scheduling, transfer) and
the bookkeeping around the fit (job rows, database handle) - against the fit's own time; and
from those, the time of a 10,000-session refit on 16 and 64 cores. The load average is printed
at the start and the end: the machine is shared, and a loaded one understates the scaling.

Run: python benchmarks/bench_cluster.py [--patients 8] [--db URL]
"""

from __future__ import annotations

import argparse
import itertools
import logging
import os
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TARGET_EFFICIENCY = 0.85
TARGET_OVERHEAD = 0.05
TARGET_HOURS_16 = 1.0
SESSIONS = 10_000


class Figures(NamedTuple):
    workers: int
    sessions: int
    fit_wall_s: float
    fit_task_s: list[float]
    #: per task: Dask's compute time on the worker minus the fit's own time (job rows, the
    #: database handle; the first task of a worker also opens the database)
    bookkeeping_s: list[float]
    gaps_s: float
    cases: int
    report_wall_s: float

    @property
    def fits_per_s(self) -> float:
        return self.sessions / self.fit_wall_s

    @property
    def cases_per_s(self) -> float:
        return self.cases / self.report_wall_s


@contextmanager
def scratch_database(server_url: str) -> Iterator[str]:
    """A fresh database on the server, dropped afterwards."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    name = f"fbbench_{uuid.uuid4().hex[:10]}"
    admin = create_engine(server_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield make_url(server_url).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


def _warm() -> int:
    """Run on each worker before the clock starts: what a first task would import."""
    import fieldbank.fitting.batch
    import fieldbank.interventions.report.remote  # noqa: F401

    return os.getpid()


def measure(workers: int, server_url: str, patients: int) -> Figures:
    from distributed import Client, LocalCluster, get_task_stream

    from fieldbank import modelsource
    from fieldbank.fitting.batch import fit_all
    from fieldbank.interventions import Plan
    from fieldbank.interventions.report import Selection, build_report
    from fieldbank.interventions.whatif import save_plan
    from fieldbank.storage import Database
    from tests.cohort_helpers import store_sessions
    from tests.report_helpers import COHORT_PLANS

    with scratch_database(server_url) as url, \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
            Client(cluster, set_as_default=False) as client:
        client.run(_warm)
        with Database.open(url, upgrade="always") as db:
            pairs = store_sessions(db, patients)
            with get_task_stream(client) as stream:
                t = time.perf_counter()
                res = fit_all(db, {"seed": 0}, scheduler=cluster.scheduler_address)
                fit_wall = time.perf_counter() - t
            assert not res.failed, res.failed
            compute, gaps = _stream_times(stream.data)
            seconds = [o.seconds for o in res.outcomes]
            bookkeeping = [compute[i] - seconds[i] for i in sorted(compute)]
            for code in dict.fromkeys(c for c, _ in pairs):
                for k, m in enumerate(db.list_models(code, origin="fitted")):
                    label, step = COHORT_PLANS[k % len(COHORT_PLANS)]
                    save_plan(db, modelsource.stored(db, int(m.id)), Plan.of(step(), label=label),
                              accept_poor_fit=True)
            out = Path(tempfile.mkdtemp(prefix="fieldbank-bench-cluster-")) / "report"
            t = time.perf_counter()
            rep = build_report(db, Selection(), out, scheduler=cluster.scheduler_address,
                               accept_poor_fit=True)
            report_wall = time.perf_counter() - t
    return Figures(workers, len(pairs), fit_wall, seconds, bookkeeping, gaps, rep.n_cases,
                   report_wall)


def _stream_times(data: list[dict[str, Any]]) -> tuple[dict[int, float], float]:
    """Each task's compute time on its worker, by task number, and the summed idle gaps
    between consecutive tasks of one worker (scheduling and transfer; the start of the first
    is not counted)."""
    by_worker: dict[str, list[tuple[float, float]]] = {}
    compute: dict[int, float] = {}
    for d in data:
        for ss in d.get("startstops", ()):
            if ss["action"] == "compute":
                by_worker.setdefault(d["worker"], []).append((ss["start"], ss["stop"]))
                compute[int(d["key"][-1])] = ss["stop"] - ss["start"]
    gaps = 0.0
    for spans in by_worker.values():
        spans.sort()
        gaps += sum(max(0.0, b[0] - a[1]) for a, b in itertools.pairwise(spans))
    return compute, gaps


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", type=int, default=8, help="two sessions each")
    ap.add_argument("--db", default=os.environ.get("FIELDBANK_TEST_PG_URL"),
                    help="PostgreSQL server URL (a scratch database is made there)")
    args = ap.parse_args()
    if not args.db:
        print("give --db or set FIELDBANK_TEST_PG_URL (scripts/pg-test-server starts a server)")
        return 2
    print(f"load average at start: {', '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} cores)")
    figs = [measure(w, args.db, args.patients) for w in (1, 2)]
    for f in figs:
        fit_mean = statistics.fmean(f.fit_task_s)
        print(f"{f.workers} worker(s): refit {f.sessions} sessions in {f.fit_wall_s:6.2f} s = "
              f"{f.fits_per_s:5.2f} sessions/s (a fit alone {fit_mean:.2f} s on average); "
              f"report {f.cases} cases in {f.report_wall_s:5.2f} s = {f.cases_per_s:5.2f} "
              "cases/s")
    one, two = figs
    eff_fit = two.fits_per_s / (2 * one.fits_per_s)
    eff_rep = two.cases_per_s / (2 * one.cases_per_s)
    print(f"scaling efficiency at 2 workers: refit {eff_fit:.2f}, report {eff_rep:.2f} "
          f"(target >= {TARGET_EFFICIENCY:g} on an idle 2-core machine)")
    task = statistics.fmean(two.fit_task_s)
    bookkeeping = statistics.median(two.bookkeeping_s)
    gap = two.gaps_s / max(1, two.sessions - two.workers)
    overhead = (bookkeeping + gap) / task
    print(f"engine overhead per task (2 workers): {1e3 * gap:.1f} ms between tasks (Dask) + "
          f"{1e3 * bookkeeping:.1f} ms bookkeeping (job rows; median, the first task of a "
          f"worker also opens the database: largest {1e3 * max(two.bookkeeping_s):.0f} ms) = "
          f"{100 * overhead:.1f}% of a fit's own {task:.2f} s (target <= "
          f"{100 * TARGET_OVERHEAD:g}%)")
    per_session = 1.0 / one.fits_per_s  # one worker's wall time per session, overhead included
    eff = min(1.0, eff_fit)
    for cores in (16, 64):
        hours = SESSIONS * per_session / (cores * eff) / 3600
        print(f"estimate: {SESSIONS} sessions on {cores} cores = {SESSIONS} x "
              f"{per_session:.2f} s / ({cores} x {eff:.2f}) = {hours:.2f} h"
              + (f" (target <= {TARGET_HOURS_16:g} h)" if cores == 16 else ""))
    print(f"load average at end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
