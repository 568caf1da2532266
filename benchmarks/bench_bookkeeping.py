"""Benchmark: the engine's job bookkeeping per task against the task itself.

Every batch task (a session to fit, report cases, a patient's plans to check) is wrapped by
``fieldbank.engine._execute``: the worker's database handle (opened once per process), the
job marked running, the task, the job marked ended. The bookkeeping is all of that but the
task. Target: ≤ 2 % of a task; the baseline is the task a refit runs, a default fit of one
session (``fit_session``), timed in the same process on the same database.

For each database (PostgreSQL on the server of ``--db``, default ``$FIELDBANK_TEST_PG_URL``, in
a scratch database; and a SQLite file):

* the fit: ``--fits`` default fits of one stored session (each a new key: a new seed), through
  the same wrapper; its own time is what the wrapper reports (``Outcome.seconds``);
* the bookkeeping: ``--tasks`` tasks that do nothing, through the wrapper: wall and CPU time
  per task, the statements and transactions each sends (SQLAlchemy's events) and the
  connections opened (the pool's).

Both run beside ``--busy`` processes that keep a core busy each (default: one per core), as
the other workers' fits do on a worker machine: there every round trip to the database
server waits for the server's process to be given a core, so the bookkeeping's wall time
follows the number of round trips more than the work in them.

Printed: per database, bookkeeping per task (median wall, median CPU), statements and
transactions per task, connections opened, and the ratio to the fit's own time (wall and
CPU), with the load average at start and end. The machine is shared: wall time counts every
round trip to the database server as the scheduler grants it; CPU time does not.

Run: python benchmarks/bench_bookkeeping.py [--tasks 200] [--fits 2] [--busy N] [--db URL]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_cluster import scratch_database
from benchmarks.timing import load_line

TARGET = 0.02


def _spin(stop: Any) -> None:
    """A process that keeps one core busy until ``stop`` is set."""
    n = 0
    while not stop.is_set():
        for _ in range(100_000):
            n += 1


@contextmanager
def busy(n: int) -> Iterator[None]:
    """``n`` processes keeping a core busy each while the block runs."""
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    procs = [ctx.Process(target=_spin, args=(stop,), daemon=True) for _ in range(n)]
    for p in procs:
        p.start()
    try:
        yield
    finally:
        stop.set()
        for p in procs:
            p.join()


def nothing(db: Any, task: Any, options: Mapping[str, Any]) -> Any:
    """A task that does nothing: what is left is the bookkeeping."""
    from fieldbank.engine import Done

    return Done("done")


def _counting(db: Any) -> dict[str, int]:
    """Statements, transactions and new connections of ``db``'s engine, counted as they
    happen."""
    from sqlalchemy import event

    n = {"statements": 0, "transactions": 0, "connections": 0}

    def count(key: str) -> Callable[..., None]:
        def f(*_: Any, **__: Any) -> None:
            n[key] += 1
        return f

    event.listen(db.engine, "before_cursor_execute", count("statements"))
    event.listen(db.engine, "commit", count("transactions"))
    event.listen(db.engine, "connect", count("connections"))
    return n


def measure(url: str, store: str | None, tasks: int, fits: int) -> dict[str, float]:
    from fieldbank import engine
    from fieldbank.engine import Task, Where
    from fieldbank.fitting.batch import fit_session
    from fieldbank.storage import Database
    from tests.cohort_helpers import store_sessions

    with Database.open(url, create=True, upgrade="always", store_root=store) as db:
        ((code, label),) = store_sessions(db, 1, sessions=("pre",))
    # the fit, through the wrapper a worker runs it in (its own time: Outcome.seconds)
    fit_wall, fit_cpu = [], []
    for seed in range(fits):
        with Database.open(url, store_root=store) as db:
            run = db.start_run("fit", "bench", {}, [("f", code, label)])
        where = Where(url, store, run.id, run.token)
        c0 = time.process_time()  # every thread of this process (BLAS may use several)
        out = engine._execute(where, fit_session, {"seed": seed}, Task("f", code, label))
        fit_cpu.append(time.process_time() - c0)
        assert out.state == "done", out.detail
        fit_wall.append(out.seconds)
    # the bookkeeping: tasks that do nothing, through the same wrapper and handle
    with Database.open(url, store_root=store) as db:
        run = db.start_run("fit", "bench", {}, [(f"t{i}", code, label) for i in range(tasks)])
    where = Where(url, store, run.id, run.token)
    engine._execute(where, nothing, {}, Task("t0", code, label))  # the handle, opened once
    handle = engine._worker_db(where)
    n = _counting(handle)
    walls, cpus = [], []
    for i in range(1, tasks):
        w0, c0 = time.perf_counter(), time.process_time()
        out = engine._execute(where, nothing, {}, Task(f"t{i}", code, label))
        cpus.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
        assert out.state == "done", out.detail
    with Database.open(url, store_root=store) as db:
        assert db.get_run(run.id).counts["done"] == tasks
    engine._forget_databases()
    k = tasks - 1
    return {"fit_wall": statistics.fmean(fit_wall), "fit_cpu": statistics.fmean(fit_cpu),
            "wall": statistics.median(walls), "cpu": statistics.median(cpus),
            "statements": n["statements"] / k, "transactions": n["transactions"] / k,
            "connections": n["connections"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", type=int, default=200)
    ap.add_argument("--fits", type=int, default=2)
    ap.add_argument("--busy", type=int, default=len(os.sched_getaffinity(0)),
                    help="processes keeping a core busy each while measuring (default: one "
                         "per core)")
    ap.add_argument("--db", default=os.environ.get("FIELDBANK_TEST_PG_URL"),
                    help="PostgreSQL server URL (a scratch database is made there)")
    args = ap.parse_args()
    print(f"at start: {load_line()}")
    results: list[tuple[str, dict[str, float]]] = []
    with busy(args.busy):
        if args.db:
            with scratch_database(args.db) as url:
                results.append(("PostgreSQL", measure(url, None, args.tasks, args.fits)))
        else:
            print("no PostgreSQL (give --db or set FIELDBANK_TEST_PG_URL): SQLite only")
        with tempfile.TemporaryDirectory(prefix="fieldbank-bench-bookkeeping-") as d:
            results.append(("SQLite", measure(f"sqlite:///{d}/fb.sqlite3", f"{d}/arrays",
                                              args.tasks, args.fits)))
    print(f"{'database':<11}{'fit wall':>10}{'fit CPU':>9}{'books wall':>12}{'books CPU':>11}"
          f"{'stmts':>7}{'txns':>6}{'conns':>7}{'wall %':>8}{'CPU %':>7}")
    for name, r in results:
        print(f"{name:<11}{r['fit_wall']:>9.2f}s{r['fit_cpu']:>8.2f}s"
              f"{1e3 * r['wall']:>10.1f}ms{1e3 * r['cpu']:>9.1f}ms{r['statements']:>7.1f}"
              f"{r['transactions']:>6.1f}{r['connections']:>7.0f}"
              f"{100 * r['wall'] / r['fit_wall']:>7.2f}%{100 * r['cpu'] / r['fit_cpu']:>6.2f}%")
    print(f"bookkeeping per task (median of {args.tasks - 1}) against a default fit of one "
          f"session (mean of {args.fits}); target <= {100 * TARGET:g}% of a task; stmts, txns: "
          f"per task; conns: opened during the tasks; beside {args.busy} busy process(es)")
    print(f"at end: {load_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
