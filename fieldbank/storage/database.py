"""The :class:`Database` facade: opening and closing, patients, sessions and check.

:class:`Database` is the one class the rest of fieldbank uses (its API is listed in
:mod:`fieldbank.storage`). It is assembled from one mixin per aggregate, all on the shared
:class:`~fieldbank.storage.core.DatabaseCore` (engine, array store, actor, transactions, audit,
patient and session rows)::

    Database(MapStore, Lineage, Traces, Jobs, RemoteLinks, Accounts, AuditTrail)
    │                                          this module: open/close, patients, sessions
    ├── MapStore(DatabaseCore)                 mapstore.py: ingest, maps, source files
    ├── Lineage(DatabaseCore)                  lineage.py: models, fits, plans
    ├── Traces(DatabaseCore)                   traces.py: haptic sessions, traces
    ├── Jobs(DatabaseCore)                     jobs.py: batch runs and jobs, fit documents
    ├── RemoteLinks(DatabaseCore)              remote.py: remote links, assessments
    ├── Accounts(DatabaseCore)                 accounts.py: the workspace's users and tokens
    └── AuditTrail(DatabaseCore)               audit.py: the audit log read, reads recorded

Why mixins rather than objects the facade holds: the aggregates share one engine, one store and
one actor, and several writes span two of them in ONE transaction (an ingest creates the
session it stores into; a fitted model and its fit; a plan, its result model and its base). With
mixins each aggregate's ``_add_*(session, ...)`` helpers compose inside a single
``with self._write() as s`` block, and ``Database``'s public methods stay where callers find
them, without a layer of forwarding methods. Each mixin reads and writes only its own tables
plus the patient and session rows that :class:`DatabaseCore` provides.
"""

from __future__ import annotations

import getpass
import re
from collections.abc import Sequence
from datetime import date
from pathlib import Path

from sqlalchemy import exc as sa_exc
from sqlalchemy import func, select, text
from sqlalchemy.engine import URL

from fieldbank.arraystore import ArrayStore
from fieldbank.errors import DatabaseMissing, ParameterError, StorageError
from fieldbank.params import ArmParams
from fieldbank.redact import mask_url
from fieldbank.storage import migrate
from fieldbank.storage.accounts import Accounts
from fieldbank.storage.arrays import CollectReport
from fieldbank.storage.audit import AuditTrail
from fieldbank.storage.check import check
from fieldbank.storage.config import (
    db_failure,
    default_store_root,
    is_read_only,
    is_sqlite,
    make_engine,
    resolve_url,
    sqlite_path,
)
from fieldbank.storage.core import chunks, now, to_utc
from fieldbank.storage.jobs import Jobs
from fieldbank.storage.lineage import Lineage
from fieldbank.storage.mapstore import MapStore
from fieldbank.storage.orm import MapRow, PatientRow, SessionRow
from fieldbank.storage.records import CheckReport, SessionInfo
from fieldbank.storage.remote import RemoteLinks
from fieldbank.storage.traces import Traces
from fieldbank.stored.location import missing_message, url_source
from fieldbank.stored.records import PatientInfo

SIDES = ("left", "right")
#: Patient codes are pseudonyms: letters, digits and ``-_.``, no spaces (so no full names).
#: Matched whole (``fullmatch``): a trailing newline or any control character is refused.
CODE_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}", re.ASCII)


def default_actor() -> str:
    """Who writes, for the audit log: the login name, else 'unknown'."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no login name (containers without a passwd entry)
        return "unknown"


def _patient_info(r: PatientRow) -> PatientInfo:
    return PatientInfo(r.id, r.code, r.body_mass_kg, r.height_m, r.side, r.notes,
                       to_utc(r.created_at))


class Database(MapStore, Lineage, Traces, Jobs, RemoteLinks, Accounts, AuditTrail):
    """The field database and its array store. Create with :meth:`open`."""

    # --- opening ----------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        url: str | URL | None = None,
        *,
        upgrade: str = "auto",
        store_root: str | Path | None = None,
        actor: str | None = None,
        create: bool = True,
    ) -> Database:
        """Open the database at ``url`` (resolved as in :mod:`fieldbank.storage.config`).

        ``upgrade``: 'auto' brings a SQLite database to head on first use (the embedded default
        and any private SQLite file) and requires a server database to be at head already
        (``fieldbank db upgrade``); 'always' upgrades any backend; 'never' does not look.
        A read-only SQLite file is never migrated: it must be at head to be used. A database
        made by a newer fieldbank is refused (``created by a newer fieldbank``).

        ``create=False``: a SQLite file that does not exist is refused
        (:class:`~fieldbank.errors.DatabaseMissing`, naming the path, where it came from and
        how to create it) instead of being created - what every command does except the two
        that start a database (``patient add``, ``db upgrade``).
        """
        u = url if isinstance(url, URL) else resolve_url(url)
        path = sqlite_path(u)
        if not create and path is not None and not path.exists():
            raise DatabaseMissing(missing_message(path, url_source(
                url if isinstance(url, str) else None)))
        engine = make_engine(u)
        root = Path(store_root) if store_root is not None else default_store_root(u)
        db = cls(engine, ArrayStore(root), actor or default_actor())
        if upgrade == "never":
            return db
        try:
            current = migrate.current_revision(engine)
            migrate.refuse_newer(engine, current)
            migrating = upgrade == "always" or (upgrade == "auto" and is_sqlite(u))
            if current != migrate.head_revision():
                if is_read_only(engine):
                    raise StorageError(
                        f"The database {mask_url(u)} is read-only and at schema revision "
                        f"{current or '(empty)'}, not {migrate.head_revision()}: it cannot "
                        "be migrated here; open it with the fieldbank that wrote it, or "
                        "upgrade a writable copy.")
                if not migrating:
                    raise StorageError(
                        f"The database {mask_url(u)} is at schema revision "
                        f"{current or '(empty)'}, behind {migrate.head_revision()}; run "
                        "'fieldbank db upgrade'.")
                migrate.ensure_head(engine, root)
        except sa_exc.OperationalError as exc:
            engine.dispose()
            raise StorageError(db_failure("Cannot open database", u, exc, verb="")) from None
        except StorageError:
            engine.dispose()
            raise
        return db

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- patients ---------------------------------------------------------------------------
    def add_patient(self, code: str, body_mass_kg: float, height_m: float, side: str,
                    notes: str = "") -> PatientInfo:
        """Register a patient under a pseudonymous code (no names or birth dates).

        Parameters
        ----------
        code : str
            1-64 letters, digits or ``-_.``, starting with a letter or digit.
        body_mass_kg : float
            Body mass, kg.
        height_m : float
            Height, m.
        side : {'left', 'right'}
            The arm that is measured.
        """
        if not CODE_RE.fullmatch(code):
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
                             created_at=now())
            s.add(row)
            s.flush()
            self._audit(s, "add", "patient", row.id, {"code": code})
            return _patient_info(row)

    def get_patient(self, code: str) -> PatientInfo:
        with self._read() as s:
            return _patient_info(self._patient_row(s, code))

    def patients_by_code(self, codes: Sequence[str]) -> dict[str, PatientInfo]:
        """The registered patients among ``codes``, by code (a code not registered is left
        out), in one query per thousand codes."""
        out: dict[str, PatientInfo] = {}
        with self._read() as s:
            for part in chunks(sorted(set(codes))):
                out.update((r.code, _patient_info(r)) for r in s.scalars(
                    select(PatientRow).where(PatientRow.code.in_(part))))
        return out

    def patient_by_id(self, patient_id: int) -> PatientInfo:
        with self._read() as s:
            row = s.get(PatientRow, patient_id)
            if row is None:
                raise self._no_row(s, PatientRow, "patient", patient_id)
            return _patient_info(row)

    def list_patients(self) -> list[PatientInfo]:
        with self._read() as s:
            return [_patient_info(r) for r in s.scalars(
                select(PatientRow).order_by(PatientRow.code))]

    # --- sessions ---------------------------------------------------------------------------
    def ensure_session(self, patient_code: str, label: str,
                       session_date: date | None = None) -> SessionInfo:
        """The session ``label`` of a patient, created if absent."""
        with self._write() as s:
            p = self._patient_row(s, patient_code)
            r = self._session_row(s, p, label, session_date, create=True)
            return SessionInfo(r.id, p.code, r.label, r.session_date, to_utc(r.created_at))

    def get_session(self, patient_code: str, label: str) -> SessionInfo:
        """Session ``label`` of a patient; an error naming the database and the patient's
        sessions when there is none."""
        with self._read() as s:
            p = self._patient_row(s, patient_code)
            r = self._session_row(s, p, label, None, create=False)
            return SessionInfo(r.id, p.code, r.label, r.session_date, to_utc(r.created_at))

    def list_sessions(self, patient_code: str | None = None) -> list[SessionInfo]:
        """Sessions with their number of maps, by patient, date and id."""
        return self._sessions(None if patient_code is None else [patient_code])

    def sessions_of(self, patient_codes: Sequence[str]) -> list[SessionInfo]:
        """:meth:`list_sessions` of every patient of ``patient_codes``, in that order (by
        patient, date and id), in one query per thousand patients."""
        return [x for part in chunks(sorted(set(patient_codes)))
                for x in self._sessions(part)]

    def _sessions(self, codes: Sequence[str] | None) -> list[SessionInfo]:
        with self._read() as s:
            n = (select(MapRow.session_id, func.count().label("n"))
                 .group_by(MapRow.session_id).subquery())
            q = (select(SessionRow, PatientRow.code, func.coalesce(n.c.n, 0))
                 .join(PatientRow, SessionRow.patient_id == PatientRow.id)
                 .outerjoin(n, n.c.session_id == SessionRow.id)
                 .order_by(PatientRow.code, SessionRow.session_date, SessionRow.id))
            if codes is not None:
                q = q.where(PatientRow.code.in_(codes))
            return [SessionInfo(r.id, code, r.label, r.session_date, to_utc(r.created_at),
                                int(k))
                    for r, code, k in s.execute(q)]

    # --- integrity -------------------------------------------------------------------------
    def check(self) -> CheckReport:
        """Verify every reference and checksum; see :func:`fieldbank.storage.check.check`."""
        return check(self)

    def gc(self) -> CollectReport:
        """Remove what nothing refers to: ``arrays`` rows no source file or trace uses, then
        store files no row names and temporary files of interrupted writes; on a server
        database, move arrays this workstation still holds as files into the database.

        Safe while other processes write (:mod:`fieldbank.storage.arrays` explains why); each
        step is one audited transaction.
        """
        with self._write() as s:
            rows = self.arrays.collect_rows(s)
            self._audit(s, "gc", "arrays", "-", {"rows": len(rows.rows),
                                                 "moved": len(rows.moved)})
        with self._write() as s:
            files = self.arrays.collect_files(s)
            self._audit(s, "gc", "array_store", "-",
                        {"files": len(files.files), "temporaries": len(files.temporaries)})
        return rows.merged(files)

    def raw_sql(self, sql: str) -> None:
        """Run one SQL statement in a write transaction, NOT audited: for tests and
        maintenance only (application code uses the audited methods above)."""
        with self._write() as s:
            s.execute(text(sql))
