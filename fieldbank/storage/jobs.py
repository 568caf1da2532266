"""Batch runs and their jobs, and the documents derived from a fit.

A **run** is one batch command spread over workers (``fieldbank fit --all``, ``report``,
``validate`` with a scheduler or a process pool); its **jobs** are created with it, all
pending, one per unit of work (a session to fit, a group of report cases, a patient's plans to
check), keyed uniquely within the run. The worker that runs a job marks it started
(:meth:`Jobs.start_job`: ``attempts`` + 1, which worker, when) and finished
(:meth:`Jobs.finish_job`: done, skipped or failed, with its result or error) - only while
that attempt is the job's live one; a job whose worker died stays ``running`` until the engine
runs it again, or gives it up (:meth:`Jobs.give_up_job`: failed, unless it ended
meanwhile). ``fieldbank jobs`` reads them: what ran, what failed, what is left. The run's
random ``token`` lets a worker check that it writes into the database the run was started on.

Derived documents of a fit (``fit_intervals``): the prediction intervals of one plan over the
fit's parameter samples, stored under a key of everything they depend on
(:meth:`Jobs.fit_document`, :meth:`Jobs.put_fit_document`); a newer model version replaces
the fit's older documents. They are caches: written once, never edited, rebuilt on demand.

Audit: a run's start and end and every failed job are audited; the progress marks of each job
and the derived documents are bookkeeping and caches, not user data, and are not (the fits a
run stores are audited as every fit is).
"""

from __future__ import annotations

import json
import secrets
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

from sqlalchemy import CursorResult, delete, func, select, update
from sqlalchemy import exc as sa_exc
from sqlalchemy.orm import Session

from fieldbank.errors import ParameterError, StorageError
from fieldbank.storage.config import db_failure
from fieldbank.storage.core import DatabaseCore, chunks, now, to_utc, to_utc_opt
from fieldbank.storage.orm import FitIntervalRow, FitRow, JobRow, JobRunRow
from fieldbank.stored.records import JOB_KINDS, JOB_STATES, JobRecord, JobRunRecord
from fieldbank.stored.words import no_run

#: States a job ends in.
FINAL_STATES = ("done", "skipped", "failed")


#: A job row's columns, as an UPDATE ... RETURNING gives them back.
_COLUMNS = tuple(JobRow.__table__.c)


def _ended(state: str, error: str | None, result: Mapping[str, Any] | None,
           payload: bytes | None) -> dict[str, Any]:
    """The columns a job's end sets."""
    return {"state": state, "finished_at": now(), "error": error, "payload": payload,
            "result_json": None if result is None else json.dumps(dict(result), sort_keys=True)}


def _job(r: Any) -> JobRecord:
    """A job row (ORM or a returned row: the same column names) as its record."""
    return JobRecord(r.id, r.run_id, r.key, r.patient_code, r.session_label, r.state,
                     r.attempts, r.worker, to_utc_opt(r.started_at), to_utc_opt(r.finished_at),
                     r.error, None if r.result_json is None else json.loads(r.result_json))


class Jobs(DatabaseCore):
    """Runs, jobs and fit documents of :class:`~fieldbank.storage.Database`."""

    # --- runs -------------------------------------------------------------------------------
    def start_run(self, kind: str, engine: str, args: Mapping[str, Any],
                  jobs: Sequence[tuple[str, str | None, str | None]]) -> JobRunRecord:
        """Record a run and its jobs, all pending, in one transaction.

        ``jobs``: (key, patient code, session label) per job; keys unique within the run.
        """
        if kind not in JOB_KINDS:
            raise ParameterError(f"job kind must be one of {', '.join(JOB_KINDS)}; got "
                                 f"{kind!r}.")
        keys = [k for k, _, _ in jobs]
        if len(set(keys)) != len(keys):
            raise ParameterError("the jobs of a run need distinct keys.")
        with self._write() as s:
            run = JobRunRow(kind=kind, token=secrets.token_hex(16), engine=engine[:255],
                            args_json=json.dumps(dict(args), sort_keys=True, default=str),
                            actor=self.actor, started_at=now())
            s.add(run)
            s.flush()
            s.add_all(JobRow(run_id=run.id, key=k, patient_code=p, session_label=sess,
                             state="pending", attempts=0) for k, p, sess in jobs)
            self._audit(s, "start", "job_run", run.id,
                        {"kind": kind, "engine": engine, "jobs": len(jobs)})
            s.flush()
            return self._run(s, run)

    def finish_run(self, run_id: int) -> JobRunRecord:
        """Mark a run ended (its jobs keep their states: some may be left)."""
        with self._write() as s:
            run = self._run_row(s, run_id)
            run.finished_at = now()
            rec = self._run(s, run)
            self._audit(s, "finish", "job_run", run_id, rec.counts)
            return rec

    def get_run(self, run_id: int) -> JobRunRecord:
        with self._read() as s:
            return self._run(s, self._run_row(s, run_id))

    def run_by_token(self, token: str) -> JobRunRecord | None:
        """The run with this token, or None (a worker reaching another database)."""
        with self._read() as s:
            r = s.scalar(select(JobRunRow).where(JobRunRow.token == token))
            return None if r is None else self._run(s, r)

    def list_runs(self, kind: str | None = None, limit: int | None = None) -> list[JobRunRecord]:
        """Runs, newest first."""
        q = select(JobRunRow).order_by(JobRunRow.id.desc())
        if kind is not None:
            q = q.where(JobRunRow.kind == kind)
        if limit is not None:
            q = q.limit(limit)
        with self._read() as s:
            return [self._run(s, r) for r in s.scalars(q)]

    def _run_row(self, s: Session, run_id: int) -> JobRunRow:
        r = s.get(JobRunRow, run_id)
        if r is None:
            raise StorageError(no_run(run_id))
        return r

    def _run(self, s: Session, r: JobRunRow) -> JobRunRecord:
        counts = dict.fromkeys(JOB_STATES, 0)
        for state, n in s.execute(select(JobRow.state, func.count()).where(JobRow.run_id == r.id)
                                  .group_by(JobRow.state)):
            counts[str(state)] = int(n)
        return JobRunRecord(r.id, r.kind, r.token, r.engine, json.loads(r.args_json), r.actor,
                            to_utc(r.started_at), to_utc_opt(r.finished_at), counts)

    # --- jobs -------------------------------------------------------------------------------
    def list_jobs(self, run_id: int, states: Iterable[str] | None = None) -> list[JobRecord]:
        """A run's jobs in the order they were created."""
        q = select(JobRow).where(JobRow.run_id == run_id).order_by(JobRow.id)
        if states is not None:
            q = q.where(JobRow.state.in_(list(states)))
        with self._read() as s:
            self._run_row(s, run_id)
            return [_job(r) for r in s.scalars(q)]

    def start_job(self, run_id: int, key: str, worker: str) -> JobRecord:
        """Mark a job started by ``worker`` (one more attempt); returns it as it was before
        when it had already finished (a task run twice finds its own result)."""
        row = self._mark(update(JobRow).where(
            JobRow.run_id == run_id, JobRow.key == key, JobRow.state.not_in(FINAL_STATES)
        ).values(state="running", worker=worker[:255], started_at=now(), finished_at=None,
                 attempts=JobRow.attempts + 1).returning(*_COLUMNS))
        if row is not None:
            return _job(row)
        with self._read() as s:  # ended already (or no such job: the storage error)
            return _job(self._job_row(s, run_id, key))

    def finish_job(self, run_id: int, key: str, state: str,
                   result: Mapping[str, Any] | None = None, error: str | None = None,
                   payload: bytes | None = None, *, attempt: int) -> tuple[JobRecord, bool]:
        """Record how attempt ``attempt`` of a job ended: 'done', 'skipped' (nothing to do:
        found already) or 'failed' (``error`` says why); ``result`` a small JSON document,
        ``payload`` what the run's own process reads back (:meth:`job_payloads`).

        Only a live attempt ends its job: the job is written only while it is running under
        that attempt. A job that another attempt ended, or that the run's process gave up on
        (:meth:`give_up_job`), keeps what it holds. Returns the job as the database holds it
        and whether this call wrote it."""
        if state not in FINAL_STATES:
            raise ParameterError(f"a job ends as one of {', '.join(FINAL_STATES)}; got "
                                 f"{state!r}.")
        live = [JobRow.state == "running", JobRow.attempts == attempt]
        if state == "failed":  # audited with it: a transaction of its own
            return self._end_job(run_id, key, live, state, error, result, payload)
        row = self._mark(update(JobRow).where(JobRow.run_id == run_id, JobRow.key == key, *live)
                         .values(_ended(state, error, result, payload)).returning(*_COLUMNS))
        if row is not None:
            return _job(row), True
        with self._read() as s:
            return _job(self._job_row(s, run_id, key)), False

    def give_up_job(self, run_id: int, key: str, error: str) -> JobRecord:
        """Record as failed a job the run's process lost (its workers kept dying, the
        scheduler went away) unless it has ended already; returns the job as the database
        holds it, so that what the command reports is what is stored. A worker still running
        it can no longer end it (:meth:`finish_job`)."""
        return self._end_job(run_id, key, [JobRow.state.not_in(FINAL_STATES)], "failed",
                             error)[0]

    def _end_job(self, run_id: int, key: str, only_if: list[Any], state: str,
                 error: str | None, result: Mapping[str, Any] | None = None,
                 payload: bytes | None = None) -> tuple[JobRecord, bool]:
        """One conditional UPDATE (the database decides between racing writers: a worker
        ending its attempt and the run's process giving up), then the job as it is."""
        with self._write() as s:
            r = self._job_row(s, run_id, key)
            written = cast(CursorResult[Any], s.execute(
                update(JobRow).where(JobRow.id == r.id, *only_if).values(
                    _ended(state, error, result, payload)),
                execution_options={"synchronize_session": False})).rowcount > 0
            if written and state == "failed":
                self._audit(s, "fail", "job", r.id, {"run": run_id, "key": key,
                                                     "error": (error or "")[:500]})
            s.flush()
            s.refresh(r)
            return _job(r), written

    def _mark(self, stmt: Any) -> Any:
        """Run one statement that marks a job (an UPDATE ... RETURNING, atomic by itself) and
        return its row, or None. A worker sends two per task, so they cost one round trip
        each on a server: in autocommit, with no BEGIN and no COMMIT around them (on a busy
        worker machine each round trip waits for the server's process to get a core). SQLite
        runs in this process: its write transaction, one sync either way."""
        if self.engine.dialect.name == "sqlite":
            with self._write() as s:
                return s.execute(stmt).one_or_none()
        try:
            with self.engine.connect().execution_options(isolation_level="AUTOCOMMIT") as c:
                return c.execute(stmt).one_or_none()
        except sa_exc.DBAPIError as exc:
            raise StorageError(db_failure("Marking a job in", self.engine.url, exc)) from None

    def job_payloads(self, run_id: int) -> dict[str, bytes]:
        """Each finished job's payload by job key (jobs without one are left out)."""
        with self._read() as s:
            return {str(k): bytes(p or b"") for k, p in s.execute(
                select(JobRow.key, JobRow.payload).where(JobRow.run_id == run_id,
                                                         JobRow.payload.is_not(None)))}

    def clear_payloads(self, run_id: int) -> None:
        """Drop a run's payloads once its output is written (they can be large)."""
        with self._write() as s:
            s.execute(update(JobRow).where(JobRow.run_id == run_id).values(payload=None))

    def _job_row(self, s: Session, run_id: int, key: str) -> JobRow:
        r = s.scalar(select(JobRow).where(JobRow.run_id == run_id, JobRow.key == key))
        if r is None:
            raise StorageError(f"Run {run_id} has no job {key!r}.")
        return r

    # --- documents derived from a fit -------------------------------------------------------
    def fit_document(self, fit_id: int, key: str) -> tuple[dict[str, Any], bytes | None] | None:
        """The document kept with fit ``fit_id`` under ``key`` and its arrays, or None."""
        with self._read() as s:
            r = s.scalar(select(FitIntervalRow).where(FitIntervalRow.fit_id == fit_id,
                                                      FitIntervalRow.key == key))
            if r is None:
                return None
            return json.loads(r.document_json), None if r.arrays is None else bytes(r.arrays)

    def fit_documents(self, wanted: Sequence[tuple[int, str]]
                      ) -> dict[tuple[int, str], tuple[dict[str, Any], bytes | None]]:
        """:meth:`fit_document` of each (fit id, key) of ``wanted`` that is kept, by that
        pair, in one query per thousand fits."""
        keys = set(wanted)
        out: dict[tuple[int, str], tuple[dict[str, Any], bytes | None]] = {}
        with self._read() as s:
            for part in chunks(sorted({f for f, _ in keys})):
                for r in s.scalars(select(FitIntervalRow)
                                   .where(FitIntervalRow.fit_id.in_(part))):
                    if (r.fit_id, r.key) in keys:
                        out[(r.fit_id, r.key)] = (json.loads(r.document_json),
                                                  None if r.arrays is None else bytes(r.arrays))
        return out

    def put_fit_document(self, fit_id: int, key: str, model_version: int,
                         document: Mapping[str, Any], arrays: bytes | None = None) -> bool:
        """Keep a derived document with a fit, unless one is kept under ``key`` already (two
        workers computing the same one store it once). Documents of the fit made under another
        model version are dropped: they describe a model this fieldbank no longer computes.
        Returns whether this call stored it."""
        try:
            with self._write() as s:
                if s.get(FitRow, fit_id) is None:
                    raise StorageError(f"No fit with id {fit_id}.")
                s.execute(delete(FitIntervalRow).where(
                    FitIntervalRow.fit_id == fit_id,
                    FitIntervalRow.model_version != model_version))
                if s.scalar(select(FitIntervalRow.id).where(
                        FitIntervalRow.fit_id == fit_id, FitIntervalRow.key == key)) is not None:
                    return False
                s.add(FitIntervalRow(fit_id=fit_id, key=key, model_version=model_version,
                                     document_json=json.dumps(dict(document), sort_keys=True),
                                     arrays=arrays, created_at=now()))
                return True
        except StorageError:
            if self.fit_document(fit_id, key) is not None:
                return False  # another writer stored the same document first
            raise
