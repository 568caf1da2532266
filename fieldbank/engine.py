"""Batch work over workers: a local process pool by default, a Dask cluster given a scheduler.

``fieldbank fit --all``, ``report`` and ``validate`` split their work into **tasks** (a session
to fit, a group of report cases, a patient's plans to check) and hand them to :func:`run_batch`,
which records a run and one job per task in the database (:mod:`fieldbank.storage.jobs`), runs
the tasks and returns one small :class:`Outcome` per task, in task order.

Where they run (:func:`fieldbank.scheduler.resolve_scheduler`): with a scheduler
(``--scheduler tls://HOST:PORT`` and the cluster's certificates, or a plain address on the
loopback) on the workers of that Dask cluster (``dask.distributed``); without one, in a local
process pool (``--jobs`` processes), or in this process for one job. The scheduler is reached
before the run is recorded: a scheduler that does not answer leaves no run behind.

What travels, and what does not (``docs/scale-out.md``):

* to a worker: the task (a patient code, a session label, ids), the options, and
  :class:`Where` - the database URL **without its password** and the run's token; a worker
  reads its maps, models and fits from the database and writes its results there itself
  (fits, job states, report cases), never through the scheduler. A worker that has
  ``FIELDBANK_DB`` set connects there instead; with the URL it received it authenticates as
  PostgreSQL clients do (``PGPASSWORD``, ``~/.pgpass``, a client certificate). Before its
  first task it checks that the database holds the run's token, so a worker pointed at
  another database fails with a message instead of writing there;
* back: an :class:`Outcome` per task - its state, a line of detail and a few ids.

Failures: a task that raises is recorded as failed with the patient and session it was working
on and the error; the other tasks go on. A worker that dies mid-task loses nothing: the
scheduler runs the task again elsewhere, and every task is idempotent (a fit is stored under a
unique key; a job's payload is rewritten; a job found finished is not run again). A task whose
workers keep dying (Dask gives up after ``distributed.scheduler.allowed-failures`` attempts),
or whose result the command can no longer get (the scheduler went away), is recorded as failed
with that reason - unless it has ended in the database meanwhile, and then the command reports
what the database holds. A worker ends only its own live attempt of a job
(:meth:`~fieldbank.storage.Database.finish_job` with ``attempt``): once the command has given
a job up, a worker that finishes it later does not overwrite what the command reported (its
fit, if it made one, is stored under its key, and the next run finds it).
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sqlalchemy.engine import make_url

from fieldbank.errors import FieldbankError, ParameterError
from fieldbank.scheduler import Scheduler, resolve_scheduler
from fieldbank.storage import Database
from fieldbank.stored.records import JobRecord, JobRunRecord

if TYPE_CHECKING:  # typing only: Dask loads when a batch runs on a cluster
    from distributed import Client

#: Seconds to wait for the scheduler to answer before giving up.
CONNECT_TIMEOUT_S = 10.0


def default_jobs() -> int:
    """Worker processes of a local batch: the cores this process may run on."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
               else (os.cpu_count() or 1))


@dataclass(frozen=True)
class Task:
    """One unit of batch work: a key unique in its run, whom it concerns, and its inputs
    (plain JSON values: ids, labels, options)."""

    key: str
    patient: str | None = None
    session: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)

    def who(self) -> str:
        """The patient and session, for messages."""
        if self.patient is None:
            return f"task {self.key}"
        return f"patient {self.patient}" + (f", session {self.session}" if self.session
                                             else "")


@dataclass(frozen=True)
class Done:
    """What a task function returns: 'done' (work stored) or 'skipped' (found done already),
    a line of detail, a small JSON result, and optionally a payload for the run's own process
    (:meth:`fieldbank.storage.Database.job_payloads`)."""

    state: str
    detail: str = ""
    result: Mapping[str, Any] = field(default_factory=dict)
    payload: bytes | None = None


#: A task function: runs one task against the worker's database. Module-level, so that it
#: travels to workers by name.
TaskFn = Callable[[Database, Task, Mapping[str, Any]], Done]


@dataclass(frozen=True)
class Outcome:
    """How one task ended: 'done', 'skipped' or 'failed' (``detail`` says why)."""

    key: str
    patient: str | None
    session: str | None
    state: str
    detail: str
    result: Mapping[str, Any] = field(default_factory=dict)
    attempts: int = 1
    worker: str = ""
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "patient": self.patient, "session": self.session,
                "state": self.state, "detail": self.detail, "result": dict(self.result),
                "attempts": self.attempts, "worker": self.worker, "seconds": self.seconds}


@dataclass(frozen=True)
class Where:
    """How a worker reaches the run's database: URL (no password when it travels to other
    machines), the array store directory of a SQLite database, the run's id and token."""

    url: str
    store_root: str | None
    run_id: int
    token: str


@dataclass(frozen=True)
class BatchResult:
    """A run and the outcome of each task, in task order."""

    run: JobRunRecord
    outcomes: tuple[Outcome, ...]
    engine: str

    @property
    def failed(self) -> tuple[Outcome, ...]:
        return tuple(o for o in self.outcomes if o.state == "failed")

    def count(self, state: str) -> int:
        return sum(1 for o in self.outcomes if o.state == state)

    def to_dict(self) -> dict[str, Any]:
        """The run, its counts and every task's outcome (``--json`` of the batch commands)."""
        return {"run_id": self.run.id, "kind": self.run.kind, "engine": self.engine,
                "counts": dict(self.run.counts), "left": self.run.left,
                "tasks": [o.to_dict() for o in self.outcomes]}


Progress = Callable[[Iterable[Outcome], int], Iterable[Outcome]]


def progress_bar(desc: str) -> Progress:
    """A progress bar on stderr (tqdm) over outcomes as they arrive, failures counted."""
    from tqdm import tqdm

    def wrap(it: Iterable[Outcome], total: int) -> Iterator[Outcome]:
        failed = 0
        with tqdm(total=total, unit="task", desc=desc, leave=False, disable=None) as bar:
            for o in it:
                if o.state == "failed":
                    failed += 1
                    bar.set_postfix(failed=failed)
                bar.update(1)
                yield o
    return wrap


def run_batch(db: Database, kind: str, tasks: Sequence[Task], fn: TaskFn,
              options: Mapping[str, Any] | None = None, *,
              scheduler: Scheduler | str | None = None, jobs: int = 1,
              progress: Progress | None = None, args: Mapping[str, Any] | None = None,
              say: Callable[[str], None] | None = None) -> BatchResult:
    """Record a run of ``tasks`` and run each through ``fn`` where ``scheduler`` says.

    ``scheduler``: as :func:`~fieldbank.scheduler.resolve_scheduler` accepted it, or an
    address it is to check (with the certificate settings in force). ``fn`` must be a
    module-level function (it travels by name); ``options`` are plain JSON values every task
    gets; ``args`` are recorded with the run (what the command was asked). Returns when every
    task has ended; the outcomes are in task order.

    Raises
    ------
    ClusterError
        The scheduler is refused or does not answer; nothing is recorded.
    """
    opts = dict(options or {})
    sched = scheduler if isinstance(scheduler, Scheduler) else resolve_scheduler(scheduler or "")
    engine = (f"dask {sched.address}" if sched else
              "this process" if jobs <= 1 or len(tasks) <= 1 else f"{jobs} local processes")
    client = _connect(sched, say) if sched else None  # before anything is recorded
    try:
        run = db.start_run(kind, engine, dict(args or {}),
                           [(t.key, t.patient, t.session) for t in tasks])
    except BaseException:
        if client is not None:
            _close(client)
        raise
    where = Where(db.engine.url.render_as_string(hide_password=False),
                  str(db.store.root), run.id, run.token)
    try:
        if client is not None:
            it: Iterable[Outcome] = _on_dask(db, client, kind, where, tasks, fn, opts, say)
        elif engine == "this process":
            it = (_execute_with(db, where, fn, opts, t) for t in tasks)
        else:
            it = _on_pool(db, jobs, where, tasks, fn, opts)
        if progress is not None:
            it = progress(it, len(tasks))
        by_key = {o.key: o for o in it}
    finally:
        if client is not None:
            _close(client)
        final = db.finish_run(run.id)
    return BatchResult(final, tuple(by_key[t.key] for t in tasks), engine)


# --- where tasks run ------------------------------------------------------------------------
def _on_pool(db: Database, jobs: int, where: Where, tasks: Sequence[Task], fn: TaskFn,
             options: Mapping[str, Any]) -> Iterator[Outcome]:
    """Tasks over a local process pool, outcomes as they end. A pool whose worker process
    died (BrokenProcessPool) fails its unfinished tasks; those run again on the next run."""
    with ProcessPoolExecutor(max_workers=max(1, min(jobs, len(tasks)))) as pool:
        pending: dict[Future[Outcome], Task] = {
            pool.submit(_execute, where, fn, options, t): t for t in tasks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                task = pending.pop(fut)
                try:
                    yield fut.result()
                except Exception as exc:  # the process running it died
                    yield _lost(db, where, task, f"its worker process died ({exc})")


def _connect(sched: Scheduler, say: Callable[[str], None] | None) -> Client:
    """A client of ``sched`` (:meth:`Scheduler.connect`); its risk said first when it is an
    insecure one."""
    if sched.warning is not None and say is not None:
        say(sched.warning)
    return sched.connect(CONNECT_TIMEOUT_S)


def _close(client: Client) -> None:
    """Close a client. One whose scheduler went away logs the reconnection its closing cancels
    as an error with a traceback; the command says what happened to each task instead."""
    log = logging.getLogger("distributed.client")
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        client.close()
    finally:
        log.setLevel(level)


def _on_dask(db: Database, client: Client, kind: str, where: Where, tasks: Sequence[Task],
             fn: TaskFn, options: Mapping[str, Any],
             say: Callable[[str], None] | None) -> Iterator[Outcome]:
    """Tasks on a Dask cluster, outcomes as they end. The task keys name the kind, so the
    dashboard's progress groups them (``fieldbank-fit``, ``fieldbank-report``, ...)."""
    from distributed import as_completed

    travelling = Where(_without_password(where.url), where.store_root, where.run_id,
                       where.token)
    if say is not None:
        info = client.scheduler_info(n_workers=-1)
        board = (client.dashboard_link if "dashboard" in info.get("services", {}) else
                 "none (the scheduler runs without one)")
        say(f"{kind}: {len(tasks)} task(s) on {client.scheduler.address} "
            f"({len(info.get('workers', {}))} worker(s)); dashboard: {board}")
    keys = [(f"fieldbank-{kind}", where.run_id, i) for i in range(len(tasks))]
    futures = client.map(_execute, [travelling] * len(tasks), [fn] * len(tasks),
                         [options] * len(tasks), list(tasks), key=keys, pure=False)
    task_of = {f.key: t for f, t in zip(futures, tasks, strict=True)}
    for fut in as_completed(futures, loop=client.loop):
        task = task_of[fut.key]
        try:
            out = fut.result()
        except Exception as exc:  # KilledWorker: its workers kept dying; or the scheduler lost
            out = _lost(db, where, task, " ".join(f"{type(exc).__name__}: {exc}".split()))
        fut.release()
        yield out


def _lost(db: Database, where: Where, task: Task, why: str) -> Outcome:
    """A task the engine lost (its workers died, the scheduler went away): recorded failed,
    naming whom it concerned - unless the job ended in the database meanwhile; the outcome
    is what the database holds."""
    rec = db.give_up_job(where.run_id, task.key, f"{task.who()}: not finished: {why}")
    return Outcome(task.key, task.patient, task.session, rec.state,
                   rec.error or "finished by its worker", rec.result or {}, rec.attempts,
                   rec.worker or "")


def _without_password(url: str) -> str:
    u = make_url(url)
    return u.set(password=None).render_as_string(hide_password=False) if u.password else url


# --- what runs on a worker ------------------------------------------------------------------
#: The databases this process opened for tasks, by URL and store; a forked child starts empty.
_DATABASES: dict[tuple[str, str | None], Database] = {}
#: Runs whose token this process found in its database.
_VERIFIED: set[tuple[str, str | None, str]] = set()


def _forget_databases() -> None:
    """A forked child must not use its parent's connections: it opens its own."""
    _DATABASES.clear()
    _VERIFIED.clear()


os.register_at_fork(after_in_child=_forget_databases)


def _worker_db(where: Where) -> Database:
    """This process's database for ``where``: ``FIELDBANK_DB`` when set here, else the URL
    the task brought; opened once per process, checked to hold the run."""
    url = os.environ.get("FIELDBANK_DB") or where.url
    store = None if os.environ.get("FIELDBANK_DB") else where.store_root
    db = _DATABASES.get((url, store))
    if db is None:
        db = _DATABASES[(url, store)] = Database.open(url, store_root=store)
    if (url, store, where.token) not in _VERIFIED:
        if db.run_by_token(where.token) is None:
            raise FieldbankError(
                f"the worker on {socket.gethostname()} reaches the database {db.url_masked}, "
                f"which does not hold run {where.run_id}: every worker must use the database "
                "the run was started on (set FIELDBANK_DB on the worker, or leave it unset to "
                "use the URL the task brings).")
        _VERIFIED.add((url, store, where.token))
    return db


def _execute(where: Where, fn: TaskFn, options: Mapping[str, Any], task: Task) -> Outcome:
    """Run one task in a worker: open (once) and check the database, then
    :func:`_execute_with`."""
    try:
        db = _worker_db(where)
    except FieldbankError as exc:
        return Outcome(task.key, task.patient, task.session, "failed", f"{task.who()}: {exc}",
                       worker=_worker_name())
    return _execute_with(db, where, fn, options, task)


def _execute_with(db: Database, where: Where, fn: TaskFn, options: Mapping[str, Any],
                  task: Task) -> Outcome:
    """Mark the job started, run it, record how it ended; a job found finished already (its
    first worker died after recording it) is not run again."""
    worker = _worker_name()
    rec = db.start_job(where.run_id, task.key, worker)
    if rec.state in ("done", "skipped", "failed"):
        return Outcome(task.key, task.patient, task.session, rec.state, rec.error or
                       "finished by an earlier attempt", rec.result or {}, rec.attempts,
                       rec.worker or worker)
    t0 = time.perf_counter()
    try:
        done = fn(db, task, options)
    except FieldbankError as exc:
        return _failed(db, where, task, f"{task.who()}: {exc}", rec.attempts, worker, t0)
    except Exception as exc:  # a bug: recorded with where it happened, the rest go on
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return _failed(db, where, task, f"{task.who()}: {type(exc).__name__}: {exc} "
                       f"(at {os.path.basename(last.filename)}:{last.lineno})", rec.attempts,
                       worker, t0)
    if done.state not in ("done", "skipped"):
        raise ParameterError(f"a task ends 'done' or 'skipped'; got {done.state!r}.")
    end = db.finish_job(where.run_id, task.key, done.state, dict(done.result), None,
                        done.payload, attempt=rec.attempts)
    return _ended(task, end, done.detail, worker, t0)


def _failed(db: Database, where: Where, task: Task, detail: str, attempts: int, worker: str,
            t0: float) -> Outcome:
    end = db.finish_job(where.run_id, task.key, "failed", error=detail, attempt=attempts)
    return _ended(task, end, detail, worker, t0)


def _ended(task: Task, end: tuple[JobRecord, bool], detail: str, worker: str,
           t0: float) -> Outcome:
    """The outcome of an attempt as the database holds it (``end``: the job and whether this
    attempt wrote it): when another ended it first (the run's process gave up on it, another
    attempt), what that one recorded."""
    job, written = end
    if not written:
        detail = job.error or f"ended by another attempt ({job.state})"
    return Outcome(task.key, task.patient, task.session, job.state, detail, job.result or {},
                   job.attempts, worker if written else (job.worker or worker),
                   time.perf_counter() - t0)


def _worker_name() -> str:
    """The Dask worker's address, else this host and process."""
    dist = sys.modules.get("distributed")  # loaded in a Dask worker; never loaded for it here
    if dist is not None:
        try:
            return f"{dist.get_worker().address} ({socket.gethostname()})"
        except ValueError:  # not inside a Dask worker
            pass
    return f"{socket.gethostname()} pid {os.getpid()}"
