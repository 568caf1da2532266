"""Fit many sessions at once: every session of a cohort, or every fit an older model made.

``fieldbank fit --all [--patient CODE …] [--older-than VERSION]`` turns into one task per
(patient, session) (:func:`fit_tasks`), run by :func:`fieldbank.engine.run_batch` on a local
process pool or a Dask cluster. Each task (:func:`fit_session`, on a worker) reads the
session's maps from the database, and

* finds a fit with the same key (:func:`fieldbank.fitting.records.fit_key`: same maps, patient,
  options and :data:`fieldbank.fitchoices.MODEL_VERSION`) - then nothing is repeated ('skipped');
* else fits and stores the fit and its model in one transaction under that key. The key is
  unique in the database, so a task that runs twice (its first worker died after committing)
  stores nothing twice: the second finds the first's fit. Its job's result keeps the fit's
  own wall and CPU time (``fit_s``, ``fit_cpu_s``: the CPU of the thread that ran it), so a
  run's bookkeeping is the task's time less these.

Which sessions: without ``older_than``, every session with maps of the patients (all patients
when none is named). With ``older_than`` N, the fits stored under a model version below N (or
with none recorded: fits stored before versions were kept), each refitted with its own session
scope (one session, or all of the patient's). The options (algorithm, seed, parameter kinds,
prior, uncertainty) are the command's for every task.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from fieldbank.engine import BatchResult, Done, Progress, Task, run_batch
from fieldbank.errors import FitError, ParameterError
from fieldbank.fitchoices import MODEL_VERSION
from fieldbank.fitting.dbstore import DatabaseFitStore
from fieldbank.fitting.fitter import ArmFitter
from fieldbank.fitting.records import fit_key, fit_patient
from fieldbank.scheduler import Scheduler
from fieldbank.storage import Database


def fit_tasks(db: Database, patients: Sequence[str] = (),
              older_than: int | None = None) -> list[Task]:
    """The (patient, session) pairs to fit, ordered by patient code, then session date.

    Raises
    ------
    ParameterError
        ``older_than`` is not a model version this fieldbank can refit to (1 …
        :data:`~fieldbank.fitchoices.MODEL_VERSION`).
    StorageError
        A named patient is not in the database.
    FitError
        Nothing to fit (no sessions with maps; no fit older than the version).
    """
    if older_than is not None and not 1 <= older_than <= MODEL_VERSION:
        raise ParameterError(
            f"--older-than {older_than}: this fieldbank fits under model version "
            f"{MODEL_VERSION}, so it can refit what versions below 1 … {MODEL_VERSION} made; "
            f"give a version from 1 to {MODEL_VERSION}.")
    codes = list(dict.fromkeys(patients)) or [p.code for p in db.list_patients()]
    for code in codes:
        db.get_patient(code)  # an unknown patient: the storage layer's clear error
    tasks: list[Task] = []
    for code in codes:
        if older_than is None:
            scopes: list[str | None] = [s.label for s in db.list_sessions(code) if s.n_maps]
        else:
            scopes = list(dict.fromkeys(
                f.session_label for f in db.list_fits(code)
                if f.model_version is None or f.model_version < older_than))
        tasks += [Task(code if s is None else f"{code}/{s}", code, s) for s in scopes]
    if not tasks:
        who = ("patients " + ", ".join(codes)) if patients else "the database"
        raise FitError(f"nothing to fit: {who} has no sessions with maps" if older_than is None
                       else f"nothing to refit: {who} has no fit made under a model version "
                       f"below {older_than} (this fieldbank's is {MODEL_VERSION}).")
    return tasks


def fit_session(db: Database, task: Task, options: Mapping[str, Any]) -> Done:
    """One task of :func:`fit_all` (on a worker): find the same fit, or fit and store it."""
    if task.patient is None:
        raise FitError(f"task {task.key} names no patient.")
    store = DatabaseFitStore(db)
    fitter = ArmFitter(**dict(options))
    base = store.patient_params(task.patient)
    ids = store.map_ids(task.patient, task.session)
    if not ids:
        raise FitError("no maps to fit.")
    found = store.fit_with_key(fit_key(task.patient, task.session, ids, base, fitter.options()))
    if found is not None:
        return Done("skipped", f"fit {found.fit_id} (model {found.model_id}) holds these maps "
                    f"under model version {MODEL_VERSION} already",
                    {"fit_id": found.fit_id, "model_id": found.model_id, "found": True})
    out = fit_patient(store, task.patient, task.session, fitter)
    fid, mid = out.saved.fit_id, out.saved.model_id
    if not out.saved.created:
        return Done("skipped", f"fit {fid} (model {mid}) was stored meanwhile by another "
                    "attempt", {"fit_id": fid, "model_id": mid, "found": True})
    return Done("done", f"fit {fid} -> model {mid}: {out.fitter.status_}, "
                f"{len(ids)} maps, {out.fitter.time_s_:.1f} s",
                {"fit_id": fid, "model_id": mid, "status": out.fitter.status_,
                 "fit_s": round(out.fitter.time_s_, 4), "fit_cpu_s": round(out.fitter.cpu_s_, 4)})


def fit_all(db: Database, options: Mapping[str, Any], *, patients: Sequence[str] = (),
            older_than: int | None = None, scheduler: Scheduler | str | None = None,
            jobs: int = 1,
            progress: Progress | None = None,
            say: Callable[[str], None] | None = None) -> BatchResult:
    """Fit every chosen session (:func:`fit_tasks`) with ``options`` (ArmFitter keyword
    arguments as plain values), on the scheduler's cluster or ``jobs`` local processes."""
    ArmFitter(**dict(options)).check_options()  # bad options fail here, not on every worker
    tasks = fit_tasks(db, patients, older_than)
    return run_batch(db, "fit", tasks, fit_session, options, scheduler=scheduler, jobs=jobs,
                     progress=progress, say=say,
                     args={"patients": list(patients), "older_than": older_than,
                           "options": dict(options), "model_version": MODEL_VERSION})
