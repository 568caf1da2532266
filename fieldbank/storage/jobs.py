"""Batch runs and their jobs, and the documents derived from a fit.

A **run** is one batch command spread over workers (``fieldbank fit --all``, ``report``,
``validate`` with a scheduler or a process pool); its **jobs** are created with it, all
pending, one per unit of work (a session to fit, a group of report cases, a patient's plans to
check), keyed uniquely within the run. The worker that runs a job marks it started
(:meth:`Jobs.start_job`: ``attempts`` + 1, which worker, when) and finished
(:meth:`Jobs.finish_job`: done, skipped or failed, with its result or error); a job whose
worker died stays ``running`` until the engine runs it again. ``fieldbank jobs`` reads them:
what ran, what failed, what is left. The run's random ``token`` lets a worker check that it
writes into the database the run was started on.

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
from typing import Any

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session

from fieldbank.errors import ParameterError, StorageError
from fieldbank.storage.core import DatabaseCore, now, to_utc, to_utc_opt
from fieldbank.storage.orm import FitIntervalRow, FitRow, JobRow, JobRunRow
from fieldbank.stored.records import JOB_KINDS, JOB_STATES, JobRecord, JobRunRecord
from fieldbank.stored.words import no_run

#: States a job ends in.
FINAL_STATES = ("done", "skipped", "failed")


def _job(r: JobRow) -> JobRecord:
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
        with self._write() as s:
            r = self._job_row(s, run_id, key)
            if r.state in FINAL_STATES:
                return _job(r)
            r.state, r.worker, r.started_at = "running", worker[:255], now()
            r.attempts += 1
            r.finished_at = None
            return _job(r)

    def finish_job(self, run_id: int, key: str, state: str,
                   result: Mapping[str, Any] | None = None, error: str | None = None,
                   payload: bytes | None = None) -> JobRecord:
        """Record how a job ended: 'done', 'skipped' (nothing to do: found already) or
        'failed' (``error`` says why); ``result`` a small JSON document, ``payload`` what the
        run's own process reads back (:meth:`job_payloads`)."""
        if state not in FINAL_STATES:
            raise ParameterError(f"a job ends as one of {', '.join(FINAL_STATES)}; got "
                                 f"{state!r}.")
        with self._write() as s:
            r = self._job_row(s, run_id, key)
            r.state, r.finished_at, r.error = state, now(), error
            r.result_json = None if result is None else json.dumps(dict(result), sort_keys=True)
            r.payload = payload
            if state == "failed":
                self._audit(s, "fail", "job", r.id, {"run": run_id, "key": key,
                                                     "error": (error or "")[:500]})
            return _job(r)

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
