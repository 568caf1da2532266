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
  connections opened (the pool's);
* the two marks alone, as they are written now (``start_job``, ``finish_job``: each one
  UPDATE ... RETURNING) and as they were written before (:func:`former_marks`: each a write
  transaction that reads the job row, changes it and commits), in blocks interleaved with the
  wrapper's so that all three meet the same load.

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


def former_marks(db: Any, run_id: int, key: str, worker: str) -> None:
    """The job marks as they were written before: each a transaction that reads the row (the
    ORM), changes it, and commits (BEGIN, SELECT, UPDATE, COMMIT); the end read back."""
    from sqlalchemy import select

    from fieldbank.storage.core import now
    from fieldbank.storage.orm import JobRow

    with db._write() as s:
        r = s.scalar(select(JobRow).where(JobRow.run_id == run_id, JobRow.key == key))
        r.state, r.worker, r.started_at, r.finished_at = "running", worker, now(), None
        r.attempts += 1
    with db._write() as s:
        r = s.scalar(select(JobRow).where(JobRow.run_id == run_id, JobRow.key == key))
        r.state, r.finished_at, r.error, r.result_json, r.payload = "done", now(), None, "{}", None
        s.flush()
        s.refresh(r)


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
    # the bookkeeping: tasks that do nothing, through the same wrapper and handle; the former
    # marks in blocks between them, on the same handle
    with Database.open(url, store_root=store) as db:
        run = db.start_run("fit", "bench", {}, [(f"t{i}", code, label) for i in range(tasks)])
        old = db.start_run("fit", "bench", {}, [(f"o{i}", code, label) for i in range(tasks)])
    where = Where(url, store, run.id, run.token)
    engine._execute(where, nothing, {}, Task("t0", code, label))  # the handle, opened once
    handle = engine._worker_db(where)
    former_marks(handle, old.id, "o0", "bench")
    n = _counting(handle)
    counted = {"statements": 0, "transactions": 0, "connections": 0}
    with Database.open(url, store_root=store) as db:
        new = db.start_run("fit", "bench", {}, [(f"n{i}", code, label) for i in range(tasks)]).id
    walls, cpus, old_walls, old_cpus, new_walls, new_cpus = [], [], [], [], [], []
    for block in range(1, tasks, 10):
        for i in range(block, min(tasks, block + 10)):
            w0, c0 = time.perf_counter(), time.process_time()
            out = engine._execute(where, nothing, {}, Task(f"t{i}", code, label))
            cpus.append(time.process_time() - c0)
            walls.append(time.perf_counter() - w0)
            assert out.state == "done", out.detail
        counted = dict(n)  # the wrapper's only
        for i in range(block, min(tasks, block + 10)):
            w0, c0 = time.perf_counter(), time.process_time()
            former_marks(handle, old.id, f"o{i}", "bench")
            old_cpus.append(time.process_time() - c0)
            old_walls.append(time.perf_counter() - w0)
            w0, c0 = time.perf_counter(), time.process_time()
            rec = handle.start_job(new, f"n{i}", "bench")
            handle.finish_job(new, f"n{i}", "done", {}, attempt=rec.attempts)
            new_cpus.append(time.process_time() - c0)
            new_walls.append(time.perf_counter() - w0)
        for k, v in counted.items():
            n[k] = v
    with Database.open(url, store_root=store) as db:
        assert db.get_run(run.id).counts["done"] == tasks
    engine._forget_databases()
    k = tasks - 1
    return {"fit_wall": statistics.fmean(fit_wall), "fit_cpu": statistics.fmean(fit_cpu),
            "wall": statistics.median(walls), "cpu": statistics.median(cpus),
            "old_wall": statistics.median(old_walls), "old_cpu": statistics.median(old_cpus),
            "new_wall": statistics.median(new_walls), "new_cpu": statistics.median(new_cpus),
            "statements": counted["statements"] / k,
            "transactions": counted["transactions"] / k,
            "connections": counted["connections"]}


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
          f"{'stmts':>7}{'txns':>6}{'conns':>7}{'wall %':>8}{'CPU %':>7}"
          f"{'marks wall':>12}{'former':>9}{'marks CPU':>11}{'former':>9}{'  marks/former':>14}")
    for name, r in results:
        print(f"{name:<11}{r['fit_wall']:>9.2f}s{r['fit_cpu']:>8.2f}s"
              f"{1e3 * r['wall']:>10.1f}ms{1e3 * r['cpu']:>9.1f}ms{r['statements']:>7.1f}"
              f"{r['transactions']:>6.1f}{r['connections']:>7.0f}"
              f"{100 * r['wall'] / r['fit_wall']:>7.2f}%{100 * r['cpu'] / r['fit_cpu']:>6.2f}%"
              f"{1e3 * r['new_wall']:>10.1f}ms{1e3 * r['old_wall']:>7.1f}ms"
              f"{1e3 * r['new_cpu']:>9.1f}ms{1e3 * r['old_cpu']:>7.1f}ms"
              f"  {r['new_wall'] / r['old_wall']:.2f} wall, {r['new_cpu'] / r['old_cpu']:.2f} CPU")
    print(f"books: the wrapper around a task that does nothing (median of {args.tasks - 1}), "
          f"against a default fit of one session (mean of {args.fits}); target <= "
          f"{100 * TARGET:g}% of a task; stmts, txns: per task; conns: opened during the "
          "tasks; marks: start_job + finish_job alone; former: the same two marks as "
          f"read-modify-write transactions, interleaved; beside {args.busy} busy process(es)")
    print(f"at end: {load_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
