"""ORM rows of the field database (SQLAlchemy 2 typed mappings).

These classes stay inside :mod:`fieldbank.storage`; callers get frozen records and domain
objects from :class:`fieldbank.storage.Database`. Every constraint is named through
:data:`NAMING_CONVENTION` so that migrations can refer to it on every backend.

Tables::

    patients ─┬─ sessions ── maps ── source_files ── arrays ── array_chunks
              ├─ models (parent → models)
              ├─ fits ─┬─ fit_maps ── maps
              │        └─ fit_intervals  (derived: intervals of a plan over the fit's samples)
              ├─ plans (base/result → models)
              └─ haptic_sessions ─┬─ traces ── arrays
                                  ├─ haptic_trials  (A/B/X and training answers)
                                  ├─ haptic_remote_links  (a remote session's link)
                                  └─ haptic_assessments  (posterior per probe, answer beside)
    job_runs ── jobs  (batch work over workers: what ran, what failed, what is left)
    users ── api_tokens  (the workspace's accounts: role, Argon2 hash; tokens as SHA-256)
    audit_log  (append-only: UPDATE and DELETE are refused by triggers; writes and reads)

An array's bytes (a self-describing HDF5 file image, :mod:`fieldbank.arraystore`) live where
its ``arrays.location`` says: ``file`` — the array store directory next to a SQLite file;
``database`` — ``array_chunks`` rows, which every workstation of a server database reads.

Timestamps are UTC, stored without a zone. Arrays of a map are little-endian float64 blobs in
the ``maps`` row (N×2 positions, N×2 or N×4 values); JSON documents are text.
"""

from __future__ import annotations

from datetime import date, datetime

from sqlalchemy import (
    BigInteger,
    Boolean,
    CheckConstraint,
    Column,
    Date,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Table,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

SHA = String(64)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)


class PatientRow(Base):
    __tablename__ = "patients"
    __table_args__ = (
        CheckConstraint("side IN ('left', 'right')", name="side"),
        CheckConstraint("body_mass_kg > 0", name="body_mass_positive"),
        CheckConstraint("height_m > 0", name="height_positive"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    code: Mapped[str] = mapped_column(String(64), unique=True)
    body_mass_kg: Mapped[float] = mapped_column(Float)
    height_m: Mapped[float] = mapped_column(Float)
    side: Mapped[str] = mapped_column(String(8))
    notes: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(DateTime)


class SessionRow(Base):
    __tablename__ = "sessions"
    __table_args__ = (UniqueConstraint("patient_id", "label"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    patient_id: Mapped[int] = mapped_column(ForeignKey("patients.id"), index=True)
    label: Mapped[str] = mapped_column(String(128))
    session_date: Mapped[date | None] = mapped_column(Date, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    patient: Mapped[PatientRow] = relationship()


#: Where an array's bytes are: the store directory, or array_chunks in the database.
ARRAY_LOCATIONS = ("file", "database")


class ArrayRow(Base):
    """An array in the content-addressed HDF5 store (a file, or chunks in the database)."""

    __tablename__ = "arrays"
    sha256: Mapped[str] = mapped_column(SHA, primary_key=True)
    relpath: Mapped[str] = mapped_column(String(255))
    nbytes: Mapped[int] = mapped_column(BigInteger)
    shape_json: Mapped[str] = mapped_column(Text)
    dtype: Mapped[str] = mapped_column(String(32))
    unit: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime)
    # one of ARRAY_LOCATIONS, set by fieldbank.storage.arrays only
    location: Mapped[str] = mapped_column(String(16), server_default="file")


class ArrayChunkRow(Base):
    """One piece of the HDF5 file image of an array kept in the database (server databases:
    every workstation sees the same bytes). Pieces are numbered from 0 in order."""

    __tablename__ = "array_chunks"
    sha256: Mapped[str] = mapped_column(ForeignKey("arrays.sha256"), primary_key=True)
    idx: Mapped[int] = mapped_column(Integer, primary_key=True)
    data: Mapped[bytes] = mapped_column(LargeBinary)


class SourceFileRow(Base):
    """An ingested file, kept unchanged: inline bytes, or an array in the store if large."""

    __tablename__ = "source_files"
    __table_args__ = (
        CheckConstraint(
            "(content IS NULL) <> (array_sha256 IS NULL)", name="content_xor_array"
        ),
    )
    sha256: Mapped[str] = mapped_column(SHA, primary_key=True)
    file_name: Mapped[str] = mapped_column(String(255))
    file_format: Mapped[str] = mapped_column(String(16))
    nbytes: Mapped[int] = mapped_column(BigInteger)
    content: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True)
    array_sha256: Mapped[str | None] = mapped_column(
        ForeignKey("arrays.sha256"), nullable=True
    )
    ingested_at: Mapped[datetime] = mapped_column(DateTime)
    ingested_by: Mapped[str] = mapped_column(String(128))


class MapRow(Base):
    __tablename__ = "maps"
    __table_args__ = (
        UniqueConstraint("source_sha256", "index_in_file"),
        CheckConstraint("kind IN ('postural', 'stiffness')", name="kind"),
        CheckConstraint("sign IN ('arm-on-handle', 'handle-on-arm')", name="sign"),
        CheckConstraint("n_points > 0", name="n_points_positive"),
        Index("ix_maps_patient_kind", "patient_id", "kind"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    # patient_id repeats sessions.patient_id so that a patient's maps list with one index.
    patient_id: Mapped[int] = mapped_column(ForeignKey("patients.id"))
    session_id: Mapped[int] = mapped_column(ForeignKey("sessions.id"), index=True)
    source_sha256: Mapped[str] = mapped_column(ForeignKey("source_files.sha256"))
    index_in_file: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(16))
    frame: Mapped[str] = mapped_column(String(32))
    sign: Mapped[str] = mapped_column(String(16))
    velocity_x_m_per_s: Mapped[float] = mapped_column(Float)
    velocity_y_m_per_s: Mapped[float] = mapped_column(Float)
    n_points: Mapped[int] = mapped_column(Integer)
    value_unit: Mapped[str] = mapped_column(String(16))
    positions_m: Mapped[bytes] = mapped_column(LargeBinary)
    values: Mapped[bytes] = mapped_column(LargeBinary)
    sd: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True)
    source_text: Mapped[str] = mapped_column(Text)
    metadata_json: Mapped[str] = mapped_column(Text)
    ingested_at: Mapped[datetime] = mapped_column(DateTime)
    ingested_by: Mapped[str] = mapped_column(String(128))


class ModelRow(Base):
    __tablename__ = "models"
    __table_args__ = (
        CheckConstraint("origin IN ('synthetic', 'fitted', 'intervention')", name="origin"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    patient_id: Mapped[int | None] = mapped_column(
        ForeignKey("patients.id"), nullable=True, index=True
    )
    parent_id: Mapped[int | None] = mapped_column(ForeignKey("models.id"), nullable=True)
    origin: Mapped[str] = mapped_column(String(16))
    label: Mapped[str] = mapped_column(String(255))
    params_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)


fit_maps = Table(
    "fit_maps",
    Base.metadata,
    Column("fit_id", ForeignKey("fits.id"), primary_key=True),
    Column("map_id", ForeignKey("maps.id"), primary_key=True),
)


class FitRow(Base):
    __tablename__ = "fits"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    patient_id: Mapped[int] = mapped_column(ForeignKey("patients.id"), index=True)
    model_id: Mapped[int] = mapped_column(ForeignKey("models.id"))
    algorithm: Mapped[str] = mapped_column(String(64))
    seed: Mapped[int | None] = mapped_column(Integer, nullable=True)
    n_evals: Mapped[int] = mapped_column(Integer)
    time_s: Mapped[float] = mapped_column(Float)
    cost: Mapped[float] = mapped_column(Float)
    result_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)
    # SHA-256 of what the fit was made from (maps, patient, options, model version): one fit
    # per key, so a batch refit that dies and runs again stores nothing twice (None: a fit
    # stored before keys were kept)
    fit_key: Mapped[str | None] = mapped_column(SHA, nullable=True, unique=True)
    # fieldbank.fitchoices.MODEL_VERSION the fit was made under (None: not recorded)
    model_version: Mapped[int | None] = mapped_column(Integer, nullable=True)
    # the session whose maps were fitted (None: every session of the patient)
    session_id: Mapped[int | None] = mapped_column(ForeignKey("sessions.id"), nullable=True,
                                                   index=True)


class FitIntervalRow(Base):
    """A derived document kept with a fit: the prediction intervals of one plan applied to
    the fitted model's parameter samples, keyed by everything they depend on. Rebuilt, never
    edited: a different fit, model or plan is a different key."""

    __tablename__ = "fit_intervals"
    __table_args__ = (UniqueConstraint("fit_id", "key"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    fit_id: Mapped[int] = mapped_column(ForeignKey("fits.id"), index=True)
    key: Mapped[str] = mapped_column(SHA)
    model_version: Mapped[int] = mapped_column(Integer)
    document_json: Mapped[str] = mapped_column(Text)
    # float64 little-endian arrays the document names (curve bands), or None
    arrays: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class JobRunRow(Base):
    """One batch command (``fit --all``, ``report``, ``validate``) spread over workers."""

    __tablename__ = "job_runs"
    # the kinds are fieldbank.stored.records.JOB_KINDS, the states of jobs.state its JOB_STATES
    __table_args__ = (CheckConstraint("kind IN ('fit', 'report', 'validate')", name="kind"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    # a random token the workers check, so that every worker writes into this database
    token: Mapped[str] = mapped_column(String(64), unique=True)
    engine: Mapped[str] = mapped_column(String(255))
    args_json: Mapped[str] = mapped_column(Text)
    actor: Mapped[str] = mapped_column(String(128))
    started_at: Mapped[datetime] = mapped_column(DateTime)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)


class JobRow(Base):
    """One task of a run: a session to fit, a group of report cases, a patient's plans to
    check. Written by the worker that runs it; ``attempts`` counts the times one started."""

    __tablename__ = "jobs"
    __table_args__ = (
        UniqueConstraint("run_id", "key"),
        CheckConstraint("state IN ('pending', 'running', 'done', 'skipped', 'failed')",
                        name="state"),
        CheckConstraint("attempts >= 0", name="attempts_non_negative"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("job_runs.id"), index=True)
    key: Mapped[str] = mapped_column(String(255))
    patient_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    session_label: Mapped[str | None] = mapped_column(String(128), nullable=True)
    state: Mapped[str] = mapped_column(String(16))
    attempts: Mapped[int] = mapped_column(Integer)
    worker: Mapped[str | None] = mapped_column(String(255), nullable=True)
    started_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    result_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    # what the task computed for the run's own process to put together (report cases, plan
    # checks): JSON bytes, cleared once the run's output is written
    payload: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True)


class PlanRow(Base):
    __tablename__ = "plans"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    patient_id: Mapped[int | None] = mapped_column(
        ForeignKey("patients.id"), nullable=True, index=True
    )
    base_model_id: Mapped[int] = mapped_column(ForeignKey("models.id"))
    result_model_id: Mapped[int] = mapped_column(ForeignKey("models.id"))
    label: Mapped[str] = mapped_column(String(255))
    spec_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class HapticSessionRow(Base):
    __tablename__ = "haptic_sessions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    patient_id: Mapped[int | None] = mapped_column(
        ForeignKey("patients.id"), nullable=True, index=True
    )
    model_a_id: Mapped[int] = mapped_column(ForeignKey("models.id"))
    model_b_id: Mapped[int | None] = mapped_column(ForeignKey("models.id"), nullable=True)
    started_at: Mapped[datetime] = mapped_column(DateTime)
    ended_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)
    robot_url: Mapped[str] = mapped_column(String(255))
    stats_json: Mapped[str] = mapped_column(Text)
    # why the session's patient is not its models' patient (None: they match)
    patient_note: Mapped[str | None] = mapped_column(Text, nullable=True)


class HapticTrialRow(Base):
    """One trial of a session: an A/B/X trial or a training trial, with the answer given.

    ``started_s``/``answered_s`` are session times (s), the trial's window in the session's
    traces; the full record (protocol, labels, …) is ``detail_json``.
    """

    __tablename__ = "haptic_trials"
    __table_args__ = (
        UniqueConstraint("haptic_session_id", "block", "trial"),
        CheckConstraint("kind IN ('abx', 'training')", name="kind"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    haptic_session_id: Mapped[int] = mapped_column(ForeignKey("haptic_sessions.id"), index=True)
    kind: Mapped[str] = mapped_column(String(16))
    block: Mapped[int] = mapped_column(Integer)
    trial: Mapped[int] = mapped_column(Integer)
    phase: Mapped[str] = mapped_column(String(32))
    condition: Mapped[str] = mapped_column(String(64))
    answer: Mapped[str | None] = mapped_column(String(16), nullable=True)
    correct: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    started_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    answered_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    response_time_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    detail_json: Mapped[str] = mapped_column(Text)
    # the trial's window held a fault or no force: kept, left out of every accuracy
    flagged: Mapped[bool] = mapped_column(Boolean, server_default="0")


class RemoteLinkRow(Base):
    """The link of a remote session: which site, the peer, the key's fingerprint (never the
    key), the settings and what was measured (round trip, loss, passivity controller)."""

    __tablename__ = "haptic_remote_links"
    __table_args__ = (
        UniqueConstraint("haptic_session_id"),
        CheckConstraint("role IN ('clinician', 'patient')", name="role"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    haptic_session_id: Mapped[int] = mapped_column(ForeignKey("haptic_sessions.id"))
    role: Mapped[str] = mapped_column(String(16))
    peer: Mapped[str] = mapped_column(String(255))
    key_fingerprint: Mapped[str] = mapped_column(String(32))
    settings_json: Mapped[str] = mapped_column(Text)
    summary_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime)


class AssessmentRow(Base):
    """The classifier's posterior after one probe of a session, the clinician's answer beside
    it. ``started_s``/``ended_s``/``answered_s`` are session times (s)."""

    __tablename__ = "haptic_assessments"
    __table_args__ = (UniqueConstraint("haptic_session_id", "probe"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    haptic_session_id: Mapped[int] = mapped_column(ForeignKey("haptic_sessions.id"), index=True)
    probe: Mapped[int] = mapped_column(Integer)
    started_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    ended_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    prior_json: Mapped[str] = mapped_column(Text)
    posterior_json: Mapped[str] = mapped_column(Text)
    impaired_group: Mapped[str | None] = mapped_column(String(32), nullable=True)
    group_probability: Mapped[float | None] = mapped_column(Float, nullable=True)
    level: Mapped[str | None] = mapped_column(String(32), nullable=True)
    level_probability: Mapped[float | None] = mapped_column(Float, nullable=True)
    explains: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    verdict: Mapped[str] = mapped_column(Text)
    detail_json: Mapped[str] = mapped_column(Text)
    answer_group: Mapped[str | None] = mapped_column(String(32), nullable=True)
    answer_level: Mapped[str | None] = mapped_column(String(32), nullable=True)
    answer_note: Mapped[str | None] = mapped_column(Text, nullable=True)
    answered_s: Mapped[float | None] = mapped_column(Float, nullable=True)


class TraceRow(Base):
    __tablename__ = "traces"
    __table_args__ = (UniqueConstraint("haptic_session_id", "name"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    haptic_session_id: Mapped[int] = mapped_column(ForeignKey("haptic_sessions.id"), index=True)
    name: Mapped[str] = mapped_column(String(128))
    array_sha256: Mapped[str] = mapped_column(ForeignKey("arrays.sha256"))
    created_at: Mapped[datetime] = mapped_column(DateTime)


#: The roles an account may have (:mod:`fieldbank.web.accounts` says what each may do).
ROLES = ("clinician", "data-manager", "viewer")


class UserRow(Base):
    """An account of the workspace (``fieldbank serve``): a name, a role, a password hash
    (Argon2id, PHC string); disabled accounts are kept so the audit log's actors stay named."""

    __tablename__ = "users"
    __table_args__ = (
        CheckConstraint("role IN ('clinician', 'data-manager', 'viewer')", name="role"),
    )
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))
    password_hash: Mapped[str] = mapped_column(String(255))
    created_at: Mapped[datetime] = mapped_column(DateTime)
    disabled_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)


class ApiTokenRow(Base):
    """A bearer token of an account for API clients: only its SHA-256 is kept (the token is
    shown once); a revoked token stays, with when it was revoked."""

    __tablename__ = "api_tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    token_sha256: Mapped[str] = mapped_column(SHA, unique=True)
    label: Mapped[str] = mapped_column(String(128), default="")
    created_at: Mapped[datetime] = mapped_column(DateTime)
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime, nullable=True)


class AuditRow(Base):
    __tablename__ = "audit_log"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[datetime] = mapped_column(DateTime, index=True)
    actor: Mapped[str] = mapped_column(String(128), index=True)
    action: Mapped[str] = mapped_column(String(64))
    entity: Mapped[str] = mapped_column(String(64))
    entity_id: Mapped[str] = mapped_column(String(128))
    detail_json: Mapped[str] = mapped_column(Text)
