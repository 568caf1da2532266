"""The field database: one class, :class:`Database`, that every other part of fieldbank uses.

API (methods return frozen records from :mod:`fieldbank.stored.records` or domain objects such
as :class:`~fieldbank.maps.FieldMap` and :class:`~fieldbank.params.ArmParams`; ORM rows never
leave this package)::

    db = Database.open(url=None)              # --db > FIELDBANK_DB > embedded SQLite file
    db.close()   /   with Database.open(...) as db: ...
    # patients and sessions                                                   database.py
    db.add_patient(code, body_mass_kg, height_m, side, notes="") -> PatientInfo
    db.get_patient(code) / db.list_patients() / db.patient_by_id(id)
    db.ensure_session(patient_code, label, session_date=None) -> SessionInfo
    db.get_session(patient_code, label) -> SessionInfo / db.list_sessions(patient_code=None)
    db.patients_by_code(codes) -> {code: PatientInfo}   db.sessions_of(codes) -> [SessionInfo]
    # measured maps and source files (written by fieldbank.ingest)              mapstore.py
    db.ingest_files(patient_code, session_label, files, session_date=None,
                    progress: IngestProgress | None = None) -> [IngestOutcome]
    db.has_source(sha256) -> bool
    db.list_maps(patient_code=None, session_label=None, kind=None, since=None, until=None)
    db.get_map(map_id) -> FieldMap   db.get_maps(map_ids) -> [FieldMap]
    db.get_stored_map(map_id) -> StoredMap
    db.maps_of(patient_codes) -> [StoredMap]   db.maps_by_id(map_ids) -> {id: FieldMap}
    db.source_file(sha256) -> SourceFileInfo   db.source_bytes(sha256) -> bytes
    # models, fits, plans (fitting and what-if)                                 lineage.py
    db.add_model(params, origin, label, patient_code=None, parent_id=None) -> StoredModel
    db.get_model(id) / db.list_models(patient_code=None, origin=None) / db.model_lineage(id)
    db.add_fit(patient_code, model_id, algorithm, seed, n_evals, time_s, cost, result, map_ids)
    db.add_fitted_model(params, label, patient_code, algorithm, seed, n_evals, time_s, cost,
                        result, map_ids) -> (StoredModel, FitRecord)   # one transaction
    db.get_models(ids) -> {id: StoredModel}   # the set-based reads: one query per table
    db.list_fits(patient_code=None) / db.get_fit(id) / db.fit_by_key(key)
    db.fits_of(patient_codes) -> {code: [FitRecord]}
    db.add_fitted_model_once(..., fit_key=key) -> (StoredModel, FitRecord, stored: bool)
    db.add_plan(base_model_id, result_model_id, spec, label="", patient_code=None)
    db.add_plan_result(after, spec, label, patient_code=None, base_model_id=None, before=None,
                       before_label="") -> (base model id, after StoredModel, PlanRecord)
    db.list_plans(patient_code=None) / db.get_plan(id) / db.get_plans(ids)
    db.set_plan_given(plan_id, given_on) -> PlanRecord   # the day a stored plan was carried out
    # haptic sessions and traces (arrays go to the HDF5 array store)            traces.py
    db.start_haptic_session(model_a_id, robot_url, model_b_id=None, patient_code=None)
    db.end_haptic_session(id, stats) / db.get_haptic_session(id)
    db.list_haptic_sessions(patient_code=None)
    db.add_trace(haptic_session_id, name, array, unit, provenance) -> TraceRecord
    db.list_traces(haptic_session_id) / db.get_trace_array(trace_id) / db.trace_attrs(id)
    # batch runs and their jobs; documents derived from a fit                   jobs.py
    db.start_run(kind, engine, args, [(key, patient, session)]) -> JobRunRecord
    db.start_job(run_id, key, worker) -> JobRecord
    db.finish_job(run_id, key, state, result, error, payload, attempt=n) -> (JobRecord, written)
    db.give_up_job(run_id, key, error) -> JobRecord      # failed, unless it ended meanwhile
    db.get_run(id) / db.run_by_token(token) / db.list_runs(kind=None, limit=None)
    db.list_jobs(run_id, states=None) / db.job_payloads(run_id) / db.clear_payloads(run_id)
    db.finish_run(run_id)
    db.fit_document(fit_id, key) / db.put_fit_document(fit_id, key, model_version, doc, arrays)
    db.fit_documents([(fit_id, key)]) -> {(fit_id, key): (doc, arrays)}
    # accounts of the workspace (hashes made by fieldbank.web.accounts)           accounts.py
    db.add_user(name, role, password_hash) / db.get_user(name) / db.find_user(name)
    db.list_users() / db.set_user(name, role=, password_hash=, disabled=)
    db.add_token(name, sha256, label) / db.list_tokens(name=None) / db.revoke_token(id)
    db.user_for_token(sha256) -> (UserRecord, token id) | None
    db.acting_as(actor, **context) -> Database   # same engine; writes audited as actor
    # audit, integrity and clean-up              audit.py, database.py, check.py, arrays.py
    db.audit_entries(limit=None, patient=, actor=, since=, action=) -> [AuditEntry]
    db.record_read(patient_code, what, detail=None)   # a read of a patient's data
    db.check() -> CheckReport      # check.check(db): reads db.engine and db.arrays only
    db.gc() -> CollectReport       # orphans removed, safely while others write
    db.engine / db.store / db.arrays / db.actor / db.url_masked

Every write runs in one transaction together with its audit-log entry (``audit_log`` is
append-only: the database refuses UPDATE and DELETE on it). On SQLite write transactions start
with ``BEGIN IMMEDIATE`` so concurrent writers queue on the busy timeout instead of failing.

Errors (the storage part of the tree in :mod:`fieldbank.errors`)::

    FieldbankError
    ├── ParameterError(ValueError)   refused input: a patient code that is not a pseudonym, a
    │                                side, mass or height out of range, an unknown model origin,
    │                                an empty session label
    └── StorageError(RuntimeError)   the database or array store failed or refused: unknown
        │                            patient/session/map/model/fit/plan/trace, a duplicate
        │                            patient, a constraint, a schema behind head or made by a
        │                            newer fieldbank, a read-only database asked to write, a
        │                            full disk, a downgrade not confirmed, an unreachable
        │                            server (URL shown without its secrets)
        └── IntegrityError           stored bytes or an array no longer match their SHA-256,
                                     or a store file is missing or unreadable

Modules::

    __init__.py    this face: Database, the records, the configuration helpers
    database.py    Database: open/close, patients, sessions, audit, check (the mixins' design)
    core.py        DatabaseCore: engine, store, actor, transactions, audit, patient/session rows
    mapstore.py    MapStore mixin: ingest, maps, source files (IngestProgress)
    lineage.py     Lineage mixin: models, fits, plans
    traces.py      Traces mixin: haptic sessions and traces
    jobs.py        Jobs mixin: batch runs, their jobs, documents derived from a fit
    accounts.py    Accounts mixin: the workspace's users and API tokens (rows only)
    audit.py       AuditTrail mixin: the audit log read and filtered, reads recorded
    arrays.py      where large arrays live (store directory or array_chunks), write, read, gc
    check.py       check(db) -> CheckReport: every reference and checksum, orphans
    records.py     the frozen records returned by Database (those the list commands read
                   are in fieldbank.stored.records)
    orm.py         ORM rows and the schema (never leave this package)
    config.py      where the database lives (data_home, URLs), engines, SQLite set-up,
                   read-only files
    migrate.py     alembic driven from code; the migrations are the package fieldbank.migrations;
                   refuses a database made by a newer fieldbank
    backup.py      the backup before a destructive downgrade, and that downgrade

The list commands read through the light listing instead (:mod:`fieldbank.stored.listing`:
the driver alone, no SQLAlchemy; its reads are held equal to this class's by tests).

See ``docs/storage.md`` for the schema and the durability guarantees.
"""

from fieldbank.storage.config import make_engine, resolve_url
from fieldbank.storage.database import Database
from fieldbank.storage.mapstore import IngestProgress
from fieldbank.storage.records import (
    ApiTokenRecord,
    AuditEntry,
    CheckReport,
    FitRecord,
    HapticSessionRecord,
    HapticTrialRecord,
    IncomingFile,
    IngestOutcome,
    SessionInfo,
    SourceFileInfo,
    StoredModel,
    TraceRecord,
    UserRecord,
)

__all__ = [
    "ApiTokenRecord",
    "AuditEntry",
    "CheckReport",
    "Database",
    "FitRecord",
    "HapticSessionRecord",
    "HapticTrialRecord",
    "IncomingFile",
    "IngestOutcome",
    "IngestProgress",
    "SessionInfo",
    "SourceFileInfo",
    "StoredModel",
    "TraceRecord",
    "UserRecord",
    "make_engine",
    "resolve_url",
]
