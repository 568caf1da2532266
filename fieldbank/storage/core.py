"""What every part of :class:`~fieldbank.storage.Database` shares: the engine, the array store,
the actor, transactions, the audit log and the patient and session rows.

:class:`DatabaseCore` is the base of the aggregate mixins (:mod:`~fieldbank.storage.mapstore`,
:mod:`~fieldbank.storage.lineage`, :mod:`~fieldbank.storage.traces`); :func:`read_session` and
:func:`write_session` are also what :func:`fieldbank.storage.check.check` reads through, so the
checker needs nothing private of the database.

Transactions: a read runs in one ORM session; a write runs in one session on one connection,
committed with its audit-log entry or rolled back whole. On SQLite a write starts with ``BEGIN
IMMEDIATE`` (see :mod:`fieldbank.storage.config`) so concurrent writers queue on the busy
timeout instead of failing when they upgrade a read lock. Database failures become
:class:`~fieldbank.errors.StorageError` naming the URL without its password.
"""

from __future__ import annotations

import copy
import json
import sqlite3
from collections.abc import Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager
from datetime import UTC, date, datetime
from typing import Any, Self, TypeVar

from sqlalchemy import Engine, func, select
from sqlalchemy import exc as sa_exc
from sqlalchemy.orm import Session

from fieldbank.arraystore import ArrayStore
from fieldbank.errors import ParameterError, StorageError
from fieldbank.redact import mask_url
from fieldbank.storage.arrays import ArrayAccess
from fieldbank.storage.config import db_failure, is_read_only
from fieldbank.storage.orm import AuditRow, PatientRow, SessionRow
from fieldbank.stored.words import no_patient

T = TypeVar("T")


def now() -> datetime:
    """The current time as stored: UTC without a zone."""
    return datetime.now(UTC).replace(tzinfo=None)


def to_utc(d: datetime) -> datetime:
    """A stored timestamp (UTC without a zone) as a timezone-aware UTC datetime."""
    return d.replace(tzinfo=UTC) if d.tzinfo is None else d.astimezone(UTC)


def to_utc_opt(d: datetime | None) -> datetime | None:
    return None if d is None else to_utc(d)


#: Ids per ``IN (...)`` list of a set-based read (well under SQLite's and PostgreSQL's limits
#: on the parameters of one statement).
IN_CHUNK = 1000


def chunks(ids: Sequence[T], size: int = IN_CHUNK) -> Iterator[Sequence[T]]:
    """``ids`` in runs of at most ``size`` (one ``IN`` list each)."""
    for k in range(0, len(ids), size):
        yield ids[k:k + size]


@contextmanager
def read_session(engine: Engine) -> Iterator[Session]:
    """An ORM session for reading; database failures raise StorageError."""
    try:
        with Session(engine) as s:
            yield s
    except sa_exc.DBAPIError as exc:
        raise StorageError(db_failure("Database", engine.url, exc)) from None


@contextmanager
def write_session(engine: Engine) -> Iterator[Session]:
    """An ORM session in one write transaction: committed on success, else rolled back whole.

    Raises
    ------
    StorageError
        The database refused the change (a constraint) or failed.
    """
    try:
        with engine.connect() as conn:
            if engine.dialect.name == "sqlite":
                conn.execution_options(fieldbank_begin="IMMEDIATE")
            with Session(bind=conn) as s:
                try:
                    yield s
                    s.commit()
                except BaseException:
                    s.rollback()
                    raise
    except sa_exc.IntegrityError as exc:
        raise StorageError(db_failure("The database refused the change to", engine.url,
                                      exc, verb="")) from None
    except sa_exc.DBAPIError as exc:
        if is_read_only(engine) or (isinstance(exc.orig, sqlite3.OperationalError)
                                    and "readonly" in str(exc.orig)):
            raise StorageError(f"The database {mask_url(engine.url)} is read-only (a "
                               "read-only file or file system): it can be read, but nothing "
                               "was changed.") from None
        raise StorageError(db_failure("Database", engine.url, exc)) from None


class DatabaseCore:
    """The engine, array store and actor, with the transactions and row look-ups that every
    aggregate of the database uses. Not used alone: :class:`fieldbank.storage.Database`
    combines it with the aggregates.

    Parameters
    ----------
    engine : sqlalchemy.Engine
        The database (see :func:`fieldbank.storage.config.make_engine`).
    store : ArrayStore
        The array store directory: where a SQLite database's large arrays go (a server
        database keeps them inside itself; :mod:`fieldbank.storage.arrays`).
    actor : str
        Who writes; recorded with every write in the audit log.
    """

    def __init__(self, engine: Engine, store: ArrayStore, actor: str) -> None:
        self.engine = engine
        self.store = store
        self.arrays = ArrayAccess(engine, store)
        self.actor = actor
        #: Where the writes come from, recorded with each (``acting_as``); empty: this process.
        self.context: dict[str, str] = {}

    def acting_as(self, actor: str, **context: str) -> Self:
        """This database (the same engine and store) writing as ``actor``: what a server
        holding one database for many users hands each request. ``context`` (e.g. ``via``,
        ``from``) goes into the audit detail of every write, under ``request``."""
        other = copy.copy(self)
        other.actor = actor
        other.context = dict(context)
        return other

    @property
    def url_masked(self) -> str:
        """The database URL with any password replaced by ``***``."""
        return mask_url(self.engine.url)

    # --- transactions -----------------------------------------------------------------------
    def _read(self) -> AbstractContextManager[Session]:
        return read_session(self.engine)

    def _write(self) -> AbstractContextManager[Session]:
        return write_session(self.engine)

    def _audit(self, s: Session, action: str, entity: str, entity_id: object,
               detail: Mapping[str, Any] | None = None) -> None:
        """Append to the audit log inside the write transaction ``s`` (``detail``: JSON)."""
        doc = dict(detail or {})
        if self.context:
            doc["request"] = dict(self.context)
        s.add(AuditRow(at=now(), actor=self.actor, action=action, entity=entity,
                       entity_id=str(entity_id),
                       detail_json=json.dumps(doc, sort_keys=True, default=str)))

    # --- what is missing --------------------------------------------------------------------
    def _no_row(self, s: Session, row: type[Any], what: str, key: object,
                note: str = "") -> StorageError:
        """The error for an id that is not there, naming the database looked in and what it
        holds: 'No model with id 99 in <database>: it holds 12 models, ids 1-12.'"""
        n, lo, hi = s.execute(select(func.count(), func.min(row.id), func.max(row.id))).one()
        held = (f"it holds no {what}s" if not n else
                f"it holds {n} {what}{'s' if n != 1 else ''}, "
                + (f"id {lo}" if n == 1 else f"ids {lo}-{hi}"))
        return StorageError(f"No {what} with id {key}{note} in {self.url_masked}: {held}.")

    # --- patient and session rows -----------------------------------------------------------
    def _patient_row(self, s: Session, code: str) -> PatientRow:
        row = s.scalar(select(PatientRow).where(PatientRow.code == code))
        if row is None:
            codes = list(s.scalars(select(PatientRow.code).order_by(PatientRow.code)))
            raise StorageError(no_patient(code, codes, self.url_masked))
        return row

    def _optional_patient_id(self, s: Session, code: str | None) -> int | None:
        return None if code is None else self._patient_row(s, code).id

    def _code_of(self, s: Session, patient_id: int | None) -> str | None:
        if patient_id is None:
            return None
        return s.scalar(select(PatientRow.code).where(PatientRow.id == patient_id))

    def _session_row(self, s: Session, patient: PatientRow, label: str,
                     session_date: date | None, create: bool) -> SessionRow:
        """The session ``label`` of ``patient``, dated if it was not, created if absent (and
        ``create``); a different date than the stored one is refused."""
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
            labels = list(s.scalars(select(SessionRow.label).where(
                SessionRow.patient_id == patient.id).order_by(SessionRow.session_date,
                                                              SessionRow.id)))
            held = (f"its sessions: {', '.join(repr(x) for x in labels)}" if labels
                    else "it has no sessions yet")
            raise StorageError(f"Patient {patient.code!r} has no session {label!r} in "
                               f"{self.url_masked}; {held}.")
        if not label.strip():
            raise ParameterError("A session label must not be empty.")
        row = SessionRow(patient_id=patient.id, label=label, session_date=session_date,
                         created_at=now())
        s.add(row)
        s.flush()
        self._audit(s, "add", "session", row.id, {"patient": patient.code, "label": label})
        return row
