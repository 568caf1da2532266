"""The field database: one class, :class:`Database`, that every other part of fieldbank uses.

API (all methods return frozen records from :mod:`fieldbank.storage.records` or domain objects
such as :class:`~fieldbank.maps.FieldMap` and :class:`~fieldbank.params.ArmParams`; ORM rows
never leave this package)::

    db = Database.open(url=None)              # --db > FIELDBANK_DB > embedded SQLite file
    # patients and sessions
    db.add_patient(code, body_mass_kg, height_m, side, notes="") -> PatientInfo
    db.get_patient(code) / db.list_patients() / db.patient_by_id(id)
    db.ensure_session(patient_code, label, session_date=None) -> SessionInfo
    db.list_sessions(patient_code=None)
    # measured maps (written by fieldbank.ingest)
    db.ingest_files(patient_code, session_label, files, session_date=None) -> [IngestOutcome]
    db.list_maps(patient_code=None, session_label=None, kind=None, since=None, until=None)
    db.get_map(map_id) -> FieldMap        db.get_stored_map(map_id) -> StoredMap
    db.source_file(sha256) -> SourceFileInfo   db.source_bytes(sha256) -> bytes
    # models, fits, plans (fitting and what-if)
    db.add_model(params, origin, label, patient_code=None, parent_id=None) -> StoredModel
    db.get_model(id) / db.list_models(patient_code=None, origin=None) / db.model_lineage(id)
    db.add_fit(patient_code, model_id, algorithm, seed, n_evals, time_s, cost, result, map_ids)
    db.add_fitted_model(params, label, patient_code, algorithm, seed, n_evals, time_s, cost,
                        result, map_ids) -> (StoredModel, FitRecord)   # one transaction
    db.list_fits(patient_code=None) / db.get_fit(id)
    db.add_plan(base_model_id, result_model_id, spec, label="", patient_code=None)
    db.add_plan_result(after, spec, label, patient_code=None, base_model_id=None, before=None)
        -> (base model id, after StoredModel, PlanRecord)              # one transaction
    db.list_plans(patient_code=None) / db.get_plan(id)
    # haptic sessions and traces (arrays go to the HDF5 array store)
    db.start_haptic_session(model_a_id, robot_url, model_b_id=None, patient_code=None)
    db.end_haptic_session(id, stats) / db.list_haptic_sessions(patient_code=None)
    db.add_trace(haptic_session_id, name, array, unit, provenance) -> TraceRecord
    db.list_traces(haptic_session_id) / db.get_trace_array(trace_id)
    # integrity and audit
    db.audit_entries(limit=None) -> [AuditEntry]       db.check() -> CheckReport

Every write runs in one transaction together with its audit-log entry (``audit_log`` is
append-only: the database refuses UPDATE and DELETE on it). On SQLite write transactions start
with ``BEGIN IMMEDIATE`` so concurrent writers queue on the busy timeout instead of failing.
"""

from __future__ import annotations

import getpass
import hashlib
import json
import os
import re
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sqlalchemy import Engine, func, select, text
from sqlalchemy import exc as sa_exc
from sqlalchemy.engine import URL
from sqlalchemy.orm import Session

from fieldbank.arraystore import ArrayRef, ArrayStore
from fieldbank.errors import ParameterError, StorageError
from fieldbank.maps import VALUE_UNITS, FieldMap
from fieldbank.params import ArmParams
from fieldbank.storage import migrate
from fieldbank.storage.config import data_home, is_sqlite, make_engine, mask_url, resolve_url
from fieldbank.storage.orm import (
    ArrayRow,
    AuditRow,
    FitRow,
    HapticSessionRow,
    MapRow,
    ModelRow,
    PatientRow,
    PlanRow,
    SessionRow,
    SourceFileRow,
    TraceRow,
    fit_maps,
)
from fieldbank.storage.records import (
    AuditEntry,
    FitRecord,
    HapticSessionRecord,
    IncomingFile,
    IngestOutcome,
    PatientInfo,
    PlanRecord,
    SessionInfo,
    SourceFileInfo,
    StoredMap,
    StoredModel,
    TraceRecord,
)

ENV_ARRAYS = "FIELDBANK_ARRAYS"
#: Source files up to this size are kept inside the database; larger ones in the array store.
INLINE_MAX_BYTES = 1 << 20
ORIGINS = ("synthetic", "fitted", "intervention")
SIDES = ("left", "right")
#: Patient codes are pseudonyms: letters, digits and ``-_.``, no spaces (so no full names).
CODE_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
#: Test hook: seconds to sleep after writing each file of an ingest batch, inside the
#: transaction (lets tests kill an ingest in the middle of a batch). Unset in normal use.
ENV_TEST_INGEST_SLEEP = "FIELDBANK_TEST_INGEST_SLEEP_S"
#: Arbitrary constant key of the PostgreSQL advisory lock held by an ingest transaction.
PG_INGEST_LOCK_KEY = 0x696E676573  # "inges"
#: Test hook: a file to which a line is appended after each file is written, inside the
#: transaction (tests wait for it to know the batch is half written). Unset in normal use.
ENV_TEST_INGEST_MARK = "FIELDBANK_TEST_INGEST_MARK"


def _now() -> datetime:
    return datetime.now(UTC).replace(tzinfo=None)


def _utc(d: datetime) -> datetime:
    return d.replace(tzinfo=UTC) if d.tzinfo is None else d.astimezone(UTC)


def _utc_opt(d: datetime | None) -> datetime | None:
    return None if d is None else _utc(d)


def default_actor() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no login name (containers without a passwd entry)
        return "unknown"


def _blob(a: ArrayLike) -> bytes:
    return np.ascontiguousarray(np.asarray(a, dtype="<f8")).tobytes()


def _unblob(b: bytes, shape: tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(b, dtype="<f8").reshape(shape).copy()


def default_store_root(url: URL) -> Path:
    """The array store of a database: next to a SQLite file, else under the data home."""
    env = os.environ.get(ENV_ARRAYS)
    if env:
        return Path(env).expanduser()
    if is_sqlite(url) and url.database not in (None, "", ":memory:"):
        return Path(str(url.database) + ".arrays")
    return data_home() / "arrays"


class Database:
    """The field database and its array store. Create with :meth:`open`."""

    def __init__(self, engine: Engine, store: ArrayStore, actor: str) -> None:
        self.engine = engine
        self.store = store
        self.actor = actor

    # --- opening ----------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        url: str | URL | None = None,
        *,
        upgrade: str = "auto",
        store_root: str | Path | None = None,
        actor: str | None = None,
    ) -> Database:
        """Open the database at ``url`` (resolved as in :mod:`fieldbank.storage.config`).

        ``upgrade``: 'auto' brings a SQLite database to head on first use (the embedded default
        and any private SQLite file) and requires a server database to be at head already
        (``fieldbank db upgrade``); 'always' upgrades any backend; 'never' does not look.
        """
        u = url if isinstance(url, URL) else resolve_url(url)
        engine = make_engine(u)
        db = cls(engine, ArrayStore(store_root or default_store_root(u)),
                 actor or default_actor())
        if upgrade == "never":
            return db
        try:
            if upgrade == "always" or (upgrade == "auto" and is_sqlite(u)):
                migrate.ensure_head(engine)
            elif migrate.current_revision(engine) != migrate.head_revision():
                raise StorageError(
                    f"The database {mask_url(u)} is not at the current schema revision; "
                    "run 'fieldbank db upgrade'."
                )
        except sa_exc.OperationalError as exc:
            engine.dispose()
            raise StorageError(f"Cannot open database {mask_url(u)}: {exc.orig}") from None
        return db

    @property
    def url_masked(self) -> str:
        return mask_url(self.engine.url)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- transactions -----------------------------------------------------------------------
    @contextmanager
    def _read(self) -> Iterator[Session]:
        try:
            with Session(self.engine) as s:
                yield s
        except sa_exc.DBAPIError as exc:
            raise StorageError(f"Database {self.url_masked} failed: {exc.orig}") from None

    @contextmanager
    def _write(self) -> Iterator[Session]:
        try:
            with self.engine.connect() as conn:
                if self.engine.dialect.name == "sqlite":
                    conn.execution_options(fieldbank_begin="IMMEDIATE")
                with Session(bind=conn) as s:
                    try:
                        yield s
                        s.commit()
                    except BaseException:
                        s.rollback()
                        raise
        except sa_exc.IntegrityError as exc:
            raise StorageError(f"The database refused the change: {exc.orig}") from None
        except sa_exc.DBAPIError as exc:
            raise StorageError(f"Database {self.url_masked} failed: {exc.orig}") from None

    def _audit(self, s: Session, action: str, entity: str, entity_id: object,
               detail: Mapping[str, Any] | None = None) -> None:
        s.add(AuditRow(at=_now(), actor=self.actor, action=action, entity=entity,
                       entity_id=str(entity_id),
                       detail_json=json.dumps(dict(detail or {}), sort_keys=True, default=str)))

    # --- patients and sessions ----------------------------------------------------------------
    @staticmethod
    def _patient_info(r: PatientRow) -> PatientInfo:
        return PatientInfo(r.id, r.code, r.body_mass_kg, r.height_m, r.side, r.notes,
                           _utc(r.created_at))

    def add_patient(self, code: str, body_mass_kg: float, height_m: float, side: str,
                    notes: str = "") -> PatientInfo:
        """Register a patient under a pseudonymous code (no names or birth dates)."""
        if not CODE_RE.match(code):
            raise ParameterError(
                f"Patient code {code!r} must be a pseudonym of 1-64 letters, digits or '-_.' "
                "starting with a letter or digit (no spaces, so no names)."
            )
        if side not in SIDES:
            raise ParameterError(f"side must be 'left' or 'right'; got {side!r}.")
        # Validates mass and height the same way the arm model does.
        ArmParams.from_anthropometry(body_mass_kg, height_m, side)
        with self._write() as s:
            if s.scalar(select(PatientRow.id).where(PatientRow.code == code)) is not None:
                raise StorageError(f"A patient with code {code!r} already exists.")
            row = PatientRow(code=code, body_mass_kg=float(body_mass_kg),
                             height_m=float(height_m), side=side, notes=notes,
                             created_at=_now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "patient", row.id, {"code": code})
            return self._patient_info(row)

    def _patient_row(self, s: Session, code: str) -> PatientRow:
        row = s.scalar(select(PatientRow).where(PatientRow.code == code))
        if row is None:
            raise StorageError(f"No patient with code {code!r} in the database; add it with "
                               "'fieldbank patient add'.")
        return row

    def get_patient(self, code: str) -> PatientInfo:
        with self._read() as s:
            return self._patient_info(self._patient_row(s, code))

    def patient_by_id(self, patient_id: int) -> PatientInfo:
        with self._read() as s:
            row = s.get(PatientRow, patient_id)
            if row is None:
                raise StorageError(f"No patient with id {patient_id}.")
            return self._patient_info(row)

    def list_patients(self) -> list[PatientInfo]:
        with self._read() as s:
            return [self._patient_info(r) for r in s.scalars(
                select(PatientRow).order_by(PatientRow.code))]

    def _session_row(self, s: Session, patient: PatientRow, label: str,
                     session_date: date | None, create: bool) -> SessionRow:
        row = s.scalar(select(SessionRow).where(SessionRow.patient_id == patient.id,
                                                SessionRow.label == label))
        if row is not None:
            if session_date is not None and row.session_date not in (None, session_date):
                raise StorageError(
                    f"Session {label!r} of patient {patient.code!r} is dated "
                    f"{row.session_date}; got {session_date}."
                )
            if session_date is not None and row.session_date is None:
                row.session_date = session_date
                self._audit(s, "date", "session", row.id, {"date": session_date.isoformat()})
            return row
        if not create:
            raise StorageError(f"Patient {patient.code!r} has no session {label!r}.")
        if not label.strip():
            raise ParameterError("A session label must not be empty.")
        row = SessionRow(patient_id=patient.id, label=label, session_date=session_date,
                         created_at=_now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "session", row.id, {"patient": patient.code, "label": label})
        return row

    def ensure_session(self, patient_code: str, label: str,
                       session_date: date | None = None) -> SessionInfo:
        """The session ``label`` of a patient, created if absent."""
        with self._write() as s:
            p = self._patient_row(s, patient_code)
            r = self._session_row(s, p, label, session_date, create=True)
            return SessionInfo(r.id, p.code, r.label, r.session_date, _utc(r.created_at))

    def list_sessions(self, patient_code: str | None = None) -> list[SessionInfo]:
        with self._read() as s:
            n = (select(MapRow.session_id, func.count().label("n"))
                 .group_by(MapRow.session_id).subquery())
            q = (select(SessionRow, PatientRow.code, func.coalesce(n.c.n, 0))
                 .join(PatientRow, SessionRow.patient_id == PatientRow.id)
                 .outerjoin(n, n.c.session_id == SessionRow.id)
                 .order_by(PatientRow.code, SessionRow.session_date, SessionRow.id))
            if patient_code is not None:
                q = q.where(PatientRow.code == patient_code)
            return [SessionInfo(r.id, code, r.label, r.session_date, _utc(r.created_at), int(k))
                    for r, code, k in s.execute(q)]

    # --- maps -----------------------------------------------------------------------------------
    def has_source(self, sha256: str) -> bool:
        with self._read() as s:
            return s.get(SourceFileRow, sha256) is not None

    def ingest_files(self, patient_code: str, session_label: str,
                     files: Sequence[IncomingFile], session_date: date | None = None,
                     progress: Any = None) -> list[IngestOutcome]:
        """Store validated files and their maps in ONE transaction: all or nothing.

        Large source files are written to the array store first (write-once; if the
        transaction then fails they stay as harmless orphans that ``db check`` reports). A file
        whose SHA-256 is already stored is reported as 'duplicate' and not stored again.
        ``progress`` (optional) is called with each file name after it is written.
        """
        sleep_s = float(os.environ.get(ENV_TEST_INGEST_SLEEP, "0") or 0)
        mark = os.environ.get(ENV_TEST_INGEST_MARK)
        refs: dict[str, ArrayRef] = {}
        for f in files:
            if len(f.content) > INLINE_MAX_BYTES and f.sha256 not in refs:
                refs[f.sha256] = self.store.put(
                    np.frombuffer(f.content, dtype=np.uint8), "bytes",
                    {"file_name": f.file_name, "file_sha256": f.sha256,
                     "format": f.file_format, "stored_by": self.actor})
        outcomes: list[IngestOutcome] = []
        with self._write() as s:
            if self.engine.dialect.name == "postgresql":
                # Serialise ingests as BEGIN IMMEDIATE does on SQLite, so that two processes
                # storing the same file see each other's commit instead of colliding.
                s.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": PG_INGEST_LOCK_KEY})
            p = self._patient_row(s, patient_code)
            shas = [f.sha256 for f in files]
            existing = set(s.scalars(select(SourceFileRow.sha256)
                                     .where(SourceFileRow.sha256.in_(shas))))
            if set(shas) <= existing:  # nothing new: do not create an empty session
                return [IngestOutcome(f.file_name, f.sha256, "duplicate", (), len(f.maps))
                        for f in files]
            sess = self._session_row(s, p, session_label, session_date, create=True)
            now = _now()
            for f in files:
                if f.sha256 in existing:
                    outcomes.append(IngestOutcome(f.file_name, f.sha256, "duplicate", (),
                                                  len(f.maps)))
                    continue
                existing.add(f.sha256)
                ref = refs.get(f.sha256)
                if ref is not None and s.get(ArrayRow, ref.sha256) is None:
                    s.add(self._array_row(ref))
                    s.flush()
                s.add(SourceFileRow(
                    sha256=f.sha256, file_name=f.file_name, file_format=f.file_format,
                    nbytes=len(f.content), content=None if ref else f.content,
                    array_sha256=ref.sha256 if ref else None, ingested_at=now,
                    ingested_by=self.actor))
                s.flush()  # rows refer to each other by foreign key only, not relationships
                rows = [self._map_row(m, p.id, sess.id, f.sha256, i, now)
                        for i, m in enumerate(f.maps)]
                s.add_all(rows)
                s.flush()
                ids = tuple(r.id for r in rows)
                self._audit(s, "ingest", "source_file", f.sha256,
                            {"file": f.file_name, "patient": p.code, "session": sess.label,
                             "maps": list(ids)})
                outcomes.append(IngestOutcome(f.file_name, f.sha256, "stored", ids,
                                              len(f.maps)))
                if progress is not None:
                    progress(f.file_name)
                if mark:
                    with open(mark, "a", encoding="utf-8") as fh:
                        fh.write(f.sha256 + "\n")
                if sleep_s > 0:
                    time.sleep(sleep_s)
        return outcomes

    def _map_row(self, m: FieldMap, patient_id: int, session_id: int, sha: str, index: int,
                 now: datetime) -> MapRow:
        return MapRow(
            patient_id=patient_id, session_id=session_id, source_sha256=sha,
            index_in_file=index, kind=m.kind, frame=m.frame, sign=m.sign,
            velocity_x_m_per_s=m.velocity_m_per_s[0], velocity_y_m_per_s=m.velocity_m_per_s[1],
            n_points=m.n, value_unit=VALUE_UNITS[m.kind], positions_m=_blob(m.positions_m),
            values=_blob(m.values), sd=None if m.sd is None else _blob(m.sd),
            source_text=m.source, metadata_json=json.dumps(dict(m.metadata), sort_keys=True),
            ingested_at=now, ingested_by=self.actor)

    _MAP_COLUMNS = (MapRow.id, PatientRow.code, SessionRow.label, SessionRow.session_date,
                    MapRow.kind, MapRow.frame, MapRow.sign, MapRow.velocity_x_m_per_s,
                    MapRow.velocity_y_m_per_s, MapRow.n_points, MapRow.value_unit,
                    MapRow.source_text, SourceFileRow.file_name, MapRow.source_sha256,
                    MapRow.index_in_file, MapRow.ingested_at, MapRow.ingested_by)

    @staticmethod
    def _stored_map(r: Any) -> StoredMap:
        return StoredMap(r[0], r[1], r[2], r[3], r[4], r[5], r[6], (r[7], r[8]), r[9], r[10],
                         r[11], r[12], r[13], r[14], r[15].replace(tzinfo=UTC), r[16])

    def _map_query(self) -> Any:
        return (select(*self._MAP_COLUMNS)
                .join(PatientRow, MapRow.patient_id == PatientRow.id)
                .join(SessionRow, MapRow.session_id == SessionRow.id)
                .join(SourceFileRow, MapRow.source_sha256 == SourceFileRow.sha256))

    def list_maps(self, patient_code: str | None = None, session_label: str | None = None,
                  kind: str | None = None, since: date | None = None,
                  until: date | None = None) -> list[StoredMap]:
        """Maps matching every given filter, by patient, session date and id."""
        q = self._map_query()
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        if session_label is not None:
            q = q.where(SessionRow.label == session_label)
        if kind is not None:
            q = q.where(MapRow.kind == kind)
        if since is not None:
            q = q.where(SessionRow.session_date >= since)
        if until is not None:
            q = q.where(SessionRow.session_date <= until)
        q = q.order_by(PatientRow.code, SessionRow.session_date, MapRow.id)
        # Core, not the ORM session: listing is on the interactive path (target ≤ 5 ms).
        try:
            with self.engine.connect() as conn:
                rows = conn.execute(q).all()
        except sa_exc.DBAPIError as exc:
            raise StorageError(f"Database {self.url_masked} failed: {exc.orig}") from None
        return [self._stored_map(r) for r in rows]

    def get_stored_map(self, map_id: int) -> StoredMap:
        with self._read() as s:
            r = s.execute(self._map_query().where(MapRow.id == map_id)).first()
            if r is None:
                raise StorageError(f"No map with id {map_id}.")
            return self._stored_map(r)

    @staticmethod
    def _field_map(r: MapRow) -> FieldMap:
        n = r.n_points
        vshape = (n, 2) if r.kind == "postural" else (n, 2, 2)
        return FieldMap(
            kind=r.kind, positions_m=_unblob(r.positions_m, (n, 2)),
            values=_unblob(r.values, vshape),
            sd=None if r.sd is None else _unblob(r.sd, vshape), frame=r.frame, sign=r.sign,
            velocity_m_per_s=(r.velocity_x_m_per_s, r.velocity_y_m_per_s),
            source=r.source_text, metadata=json.loads(r.metadata_json))

    def get_map(self, map_id: int) -> FieldMap:
        """The map's arrays and metadata as a :class:`FieldMap` (SI, as ingested)."""
        with self._read() as s:
            r = s.get(MapRow, map_id)
            if r is None:
                raise StorageError(f"No map with id {map_id}.")
            return self._field_map(r)

    def get_maps(self, map_ids: Sequence[int]) -> list[FieldMap]:
        with self._read() as s:
            rows = {r.id: r for r in s.scalars(select(MapRow).where(MapRow.id.in_(map_ids)))}
        missing = [i for i in map_ids if i not in rows]
        if missing:
            raise StorageError(f"No map with id {', '.join(map(str, missing))}.")
        return [self._field_map(rows[i]) for i in map_ids]

    def source_file(self, sha256: str) -> SourceFileInfo:
        with self._read() as s:
            r = s.get(SourceFileRow, sha256)
            if r is None:
                raise StorageError(f"No source file with SHA-256 {sha256}.")
            return SourceFileInfo(r.sha256, r.file_name, r.file_format, r.nbytes,
                                  _utc(r.ingested_at), r.ingested_by, r.array_sha256 is not None)

    def source_bytes(self, sha256: str) -> bytes:
        """The raw file exactly as ingested (verified against its SHA-256)."""
        with self._read() as s:
            r = s.get(SourceFileRow, sha256)
            if r is None:
                raise StorageError(f"No source file with SHA-256 {sha256}.")
            content, key = r.content, r.array_sha256
        data = content if content is not None else self.store.get(str(key)).tobytes()
        if hashlib.sha256(data).hexdigest() != sha256:
            from fieldbank.errors import IntegrityError

            raise IntegrityError(f"Source file {sha256} does not match its SHA-256.")
        return data

    # --- models, fits, plans ------------------------------------------------------------------
    @staticmethod
    def _model(r: ModelRow, code: str | None) -> StoredModel:
        return StoredModel(r.id, code, r.parent_id, r.origin, r.label,
                           ArmParams.from_json(r.params_json, where=f"model {r.id}"),
                           _utc(r.created_at))

    def _code_of(self, s: Session, patient_id: int | None) -> str | None:
        if patient_id is None:
            return None
        return s.scalar(select(PatientRow.code).where(PatientRow.id == patient_id))

    def _optional_patient_id(self, s: Session, code: str | None) -> int | None:
        return None if code is None else self._patient_row(s, code).id

    def add_model(self, params: ArmParams, origin: str, label: str,
                  patient_code: str | None = None, parent_id: int | None = None) -> StoredModel:
        """Store arm parameters; ``origin`` is 'synthetic', 'fitted' or 'intervention'."""
        with self._write() as s:
            return self._add_model(s, params, origin, label, patient_code, parent_id)

    def _add_model(self, s: Session, params: ArmParams, origin: str, label: str,
                   patient_code: str | None, parent_id: int | None) -> StoredModel:
        if origin not in ORIGINS:
            raise ParameterError(f"origin must be one of {', '.join(ORIGINS)}; got {origin!r}.")
        pid = self._optional_patient_id(s, patient_code)
        if parent_id is not None and s.get(ModelRow, parent_id) is None:
            raise StorageError(f"No model with id {parent_id} (the parent).")
        row = ModelRow(patient_id=pid, parent_id=parent_id, origin=origin, label=label,
                       params_json=params.to_json(), created_at=_now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "model", row.id,
                    {"origin": origin, "label": label, "parent": parent_id})
        return self._model(row, patient_code)

    def get_model(self, model_id: int) -> StoredModel:
        with self._read() as s:
            r = s.get(ModelRow, model_id)
            if r is None:
                raise StorageError(f"No model with id {model_id}.")
            return self._model(r, self._code_of(s, r.patient_id))

    def list_models(self, patient_code: str | None = None,
                    origin: str | None = None) -> list[StoredModel]:
        q = (select(ModelRow, PatientRow.code)
             .outerjoin(PatientRow, ModelRow.patient_id == PatientRow.id).order_by(ModelRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        if origin is not None:
            q = q.where(ModelRow.origin == origin)
        with self._read() as s:
            return [self._model(r, code) for r, code in s.execute(q)]

    def model_lineage(self, model_id: int) -> list[StoredModel]:
        """The model and its ancestors, newest first."""
        out: list[StoredModel] = []
        seen: set[int] = set()
        current: int | None = model_id
        while current is not None and current not in seen:
            seen.add(current)
            m = self.get_model(current)
            out.append(m)
            current = m.parent_id
        return out

    def add_fit(self, patient_code: str, model_id: int, algorithm: str, seed: int | None,
                n_evals: int, time_s: float, cost: float, result: Mapping[str, Any],
                map_ids: Sequence[int]) -> FitRecord:
        """Record a fit: the fitted model (stored before, origin 'fitted') and the maps used."""
        with self._write() as s:
            return self._add_fit(s, patient_code, model_id, algorithm, seed, n_evals, time_s,
                                 cost, result, map_ids)

    def add_fitted_model(self, params: ArmParams, label: str, patient_code: str,
                         algorithm: str, seed: int | None, n_evals: int, time_s: float,
                         cost: float, result: Mapping[str, Any],
                         map_ids: Sequence[int]) -> tuple[StoredModel, FitRecord]:
        """Store a fitted model and its fit record in one transaction: both or neither."""
        with self._write() as s:
            model = self._add_model(s, params, "fitted", label, patient_code, None)
            fit = self._add_fit(s, patient_code, model.id, algorithm, seed, n_evals, time_s,
                                cost, result, map_ids)
            return model, fit

    def _add_fit(self, s: Session, patient_code: str, model_id: int, algorithm: str,
                 seed: int | None, n_evals: int, time_s: float, cost: float,
                 result: Mapping[str, Any], map_ids: Sequence[int]) -> FitRecord:
        p = self._patient_row(s, patient_code)
        if s.get(ModelRow, model_id) is None:
            raise StorageError(f"No model with id {model_id}.")
        found = set(s.scalars(select(MapRow.id).where(MapRow.id.in_(list(map_ids)),
                                                      MapRow.patient_id == p.id)))
        missing = [m for m in map_ids if m not in found]
        if missing:
            raise StorageError(f"Maps {missing} are not maps of patient {patient_code!r}.")
        row = FitRow(patient_id=p.id, model_id=model_id, algorithm=algorithm, seed=seed,
                     n_evals=int(n_evals), time_s=float(time_s), cost=float(cost),
                     result_json=json.dumps(dict(result), sort_keys=True),
                     created_at=_now())
        s.add(row)
        s.flush()
        ids = tuple(dict.fromkeys(int(m) for m in map_ids))
        if ids:
            s.execute(fit_maps.insert(), [{"fit_id": row.id, "map_id": m} for m in ids])
        self._audit(s, "add", "fit", row.id, {"model": model_id, "maps": list(ids)})
        return FitRecord(row.id, p.code, model_id, algorithm, seed, row.n_evals,
                         row.time_s, row.cost, json.loads(row.result_json), ids,
                         _utc(row.created_at))

    def _fit(self, s: Session, r: FitRow) -> FitRecord:
        ids = tuple(s.scalars(select(fit_maps.c.map_id).where(fit_maps.c.fit_id == r.id)
                              .order_by(fit_maps.c.map_id)))
        return FitRecord(r.id, str(self._code_of(s, r.patient_id)), r.model_id, r.algorithm,
                         r.seed, r.n_evals, r.time_s, r.cost, json.loads(r.result_json), ids,
                         _utc(r.created_at))

    def get_fit(self, fit_id: int) -> FitRecord:
        with self._read() as s:
            r = s.get(FitRow, fit_id)
            if r is None:
                raise StorageError(f"No fit with id {fit_id}.")
            return self._fit(s, r)

    def list_fits(self, patient_code: str | None = None) -> list[FitRecord]:
        q = select(FitRow).join(PatientRow, FitRow.patient_id == PatientRow.id).order_by(FitRow.id)
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [self._fit(s, r) for r in s.scalars(q)]

    def add_plan(self, base_model_id: int, result_model_id: int, spec: Mapping[str, Any],
                 label: str = "", patient_code: str | None = None) -> PlanRecord:
        with self._write() as s:
            return self._add_plan(s, base_model_id, result_model_id, spec, label, patient_code)

    def add_plan_result(self, after: ArmParams, spec: Mapping[str, Any], label: str,
                        patient_code: str | None = None, base_model_id: int | None = None,
                        before: ArmParams | None = None,
                        before_label: str = "") -> tuple[int, StoredModel, PlanRecord]:
        """Store a plan with its result model in one transaction: all or nothing.

        The base is a stored model (``base_model_id``) or, when it is not stored yet, the
        ``before`` parameters, stored first as a synthetic model. Returns (base model id,
        the after model (origin 'intervention', parent = base), the plan record).
        """
        if (base_model_id is None) == (before is None):
            raise ParameterError("Give exactly one of base_model_id and before.")
        with self._write() as s:
            if base_model_id is None:
                assert before is not None
                base_model_id = self._add_model(s, before, "synthetic", before_label,
                                                patient_code, None).id
            child = self._add_model(s, after, "intervention", label, patient_code,
                                    base_model_id)
            plan = self._add_plan(s, base_model_id, child.id, spec, label, patient_code)
            return base_model_id, child, plan

    def _add_plan(self, s: Session, base_model_id: int, result_model_id: int,
                  spec: Mapping[str, Any], label: str, patient_code: str | None) -> PlanRecord:
        pid = self._optional_patient_id(s, patient_code)
        for mid in (base_model_id, result_model_id):
            if s.get(ModelRow, mid) is None:
                raise StorageError(f"No model with id {mid}.")
        row = PlanRow(patient_id=pid, base_model_id=base_model_id,
                      result_model_id=result_model_id, label=label,
                      spec_json=json.dumps(dict(spec), sort_keys=True), created_at=_now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "plan", row.id,
                    {"base": base_model_id, "result": result_model_id})
        return PlanRecord(row.id, patient_code, base_model_id, result_model_id, label,
                          json.loads(row.spec_json), _utc(row.created_at))

    def _plan(self, s: Session, r: PlanRow) -> PlanRecord:
        return PlanRecord(r.id, self._code_of(s, r.patient_id), r.base_model_id,
                          r.result_model_id, r.label, json.loads(r.spec_json),
                          _utc(r.created_at))

    def get_plan(self, plan_id: int) -> PlanRecord:
        with self._read() as s:
            r = s.get(PlanRow, plan_id)
            if r is None:
                raise StorageError(f"No plan with id {plan_id}.")
            return self._plan(s, r)

    def list_plans(self, patient_code: str | None = None) -> list[PlanRecord]:
        q = (select(PlanRow).outerjoin(PatientRow, PlanRow.patient_id == PatientRow.id)
             .order_by(PlanRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [self._plan(s, r) for r in s.scalars(q)]

    # --- haptic sessions and traces -----------------------------------------------------------
    def _haptic(self, s: Session, r: HapticSessionRow) -> HapticSessionRecord:
        return HapticSessionRecord(r.id, self._code_of(s, r.patient_id), r.model_a_id,
                                   r.model_b_id, _utc(r.started_at), _utc_opt(r.ended_at),
                                   r.robot_url, json.loads(r.stats_json))

    def start_haptic_session(self, model_a_id: int, robot_url: str,
                             model_b_id: int | None = None,
                             patient_code: str | None = None) -> HapticSessionRecord:
        """Open a haptic session record; the robot URL is stored with any password removed."""
        safe_url = _strip_password(robot_url)
        with self._write() as s:
            pid = self._optional_patient_id(s, patient_code)
            for mid in (model_a_id, model_b_id):
                if mid is not None and s.get(ModelRow, mid) is None:
                    raise StorageError(f"No model with id {mid}.")
            row = HapticSessionRow(patient_id=pid, model_a_id=model_a_id, model_b_id=model_b_id,
                                   started_at=_now(), ended_at=None, robot_url=safe_url,
                                   stats_json="{}")
            s.add(row)
            s.flush()
            self._audit(s, "start", "haptic_session", row.id, {"robot": safe_url})
            return self._haptic(s, row)

    def end_haptic_session(self, haptic_session_id: int,
                           stats: Mapping[str, Any]) -> HapticSessionRecord:
        with self._write() as s:
            row = s.get(HapticSessionRow, haptic_session_id)
            if row is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            if row.ended_at is not None:
                raise StorageError(f"Haptic session {haptic_session_id} has already ended.")
            row.ended_at = _now()
            row.stats_json = json.dumps(dict(stats), sort_keys=True)
            self._audit(s, "end", "haptic_session", row.id, {})
            return self._haptic(s, row)

    def get_haptic_session(self, haptic_session_id: int) -> HapticSessionRecord:
        with self._read() as s:
            r = s.get(HapticSessionRow, haptic_session_id)
            if r is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            return self._haptic(s, r)

    def list_haptic_sessions(self, patient_code: str | None = None) -> list[HapticSessionRecord]:
        q = (select(HapticSessionRow)
             .outerjoin(PatientRow, HapticSessionRow.patient_id == PatientRow.id)
             .order_by(HapticSessionRow.id))
        if patient_code is not None:
            q = q.where(PatientRow.code == patient_code)
        with self._read() as s:
            return [self._haptic(s, r) for r in s.scalars(q)]

    @staticmethod
    def _array_row(ref: ArrayRef) -> ArrayRow:
        return ArrayRow(sha256=ref.sha256, relpath=ref.relpath, nbytes=ref.nbytes,
                        shape_json=json.dumps(list(ref.shape)), dtype=ref.dtype, unit=ref.unit,
                        created_at=_now())

    @staticmethod
    def _array_ref(r: ArrayRow) -> ArrayRef:
        return ArrayRef(r.sha256, r.relpath, r.nbytes, tuple(json.loads(r.shape_json)), r.dtype,
                        r.unit)

    def add_trace(self, haptic_session_id: int, name: str, array: ArrayLike, unit: str,
                  provenance: Mapping[str, Any] | None = None) -> TraceRecord:
        """Write an array to the HDF5 store, then record it as a trace of the session."""
        ref = self.store.put(array, unit, {"haptic_session": haptic_session_id, "trace": name,
                                           "stored_by": self.actor, **dict(provenance or {})})
        with self._write() as s:
            if s.get(HapticSessionRow, haptic_session_id) is None:
                raise StorageError(f"No haptic session with id {haptic_session_id}.")
            if s.get(ArrayRow, ref.sha256) is None:
                s.add(self._array_row(ref))
                s.flush()
            row = TraceRow(haptic_session_id=haptic_session_id, name=name,
                           array_sha256=ref.sha256, created_at=_now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "trace", row.id, {"array": ref.sha256, "unit": unit})
            return TraceRecord(row.id, haptic_session_id, name, ref, _utc(row.created_at))

    def list_traces(self, haptic_session_id: int) -> list[TraceRecord]:
        q = (select(TraceRow, ArrayRow).join(ArrayRow, TraceRow.array_sha256 == ArrayRow.sha256)
             .where(TraceRow.haptic_session_id == haptic_session_id).order_by(TraceRow.id))
        with self._read() as s:
            return [TraceRecord(t.id, t.haptic_session_id, t.name, self._array_ref(a),
                                _utc(t.created_at)) for t, a in s.execute(q)]

    def get_trace_array(self, trace_id: int) -> np.ndarray:
        """The trace's array, verified against its SHA-256."""
        with self._read() as s:
            t = s.get(TraceRow, trace_id)
            if t is None:
                raise StorageError(f"No trace with id {trace_id}.")
            key = t.array_sha256
        return self.store.get(key)

    # --- audit and integrity -------------------------------------------------------------------
    def audit_entries(self, limit: int | None = None) -> list[AuditEntry]:
        q = select(AuditRow).order_by(AuditRow.id.desc())
        if limit is not None:
            q = q.limit(limit)
        with self._read() as s:
            return [AuditEntry(r.id, _utc(r.at), r.actor, r.action, r.entity, r.entity_id,
                               json.loads(r.detail_json)) for r in s.scalars(q)]

    def check(self) -> Any:
        """Verify every reference and checksum; see :func:`fieldbank.storage.check.check`."""
        from fieldbank.storage.check import check

        return check(self)

    def raw_sql(self, sql: str) -> None:
        """Run one SQL statement in a write transaction, NOT audited: for tests and
        maintenance only (application code uses the audited methods above)."""
        with self._write() as s:
            s.execute(text(sql))


def _strip_password(url: str) -> str:
    """A URL with any ``user:password@`` password removed (robot URLs are not DB URLs)."""
    return re.sub(r"(//[^/@:]*):[^/@]*@", r"\1@", url)
